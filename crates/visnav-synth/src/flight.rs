//! Generated UAV flights (the monocular paper's aerial experiment, issue 26): a camera flying at
//! a given height above the ground and speed, looking forward (pitched down a little) or straight
//! down, with climbs and descents and gentle turns.
//!
//! Poses are `world_from_cam` with the world = x right, y down, z forward (the first camera's
//! heading), metres, as in [`crate::drive_trajectory`]; the first camera is at the origin. The
//! scene to render a flight in is [`FlightConfig::scene`]: the city of [`crate::Scene`] with its
//! ground `height_m` below the lowest point of the flight.

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use visnav_core::Pose;

use crate::{SceneConfig, SynthError};

/// Where the camera looks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlightView {
    /// Forward along the flight, pitched down by [`FlightConfig::forward_pitch_deg`].
    Forward,
    /// Straight down (nadir), image up = the direction of flight.
    Down,
}

/// Parameters of [`flight_trajectory`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlightConfig {
    /// Where the camera looks. Default forward.
    pub view: FlightView,
    /// Height of the lowest point of the flight above the ground, metres. Default 30.
    pub height_m: f64,
    /// Ground speed, m/s. Default 15.
    pub speed_mps: f64,
    /// Frame rate, Hz. Default 10.
    pub rate_hz: f64,
    /// Peak-to-peak height change of the climbs and descents, metres. Default 20.
    pub climb_m: f64,
    /// Period of a climb and descent, seconds. Default 20.
    pub climb_period_s: f64,
    /// Largest heading change of the gentle S-turns, degrees. Default 30.
    pub turn_deg: f64,
    /// Period of an S-turn, seconds. Default 30.
    pub turn_period_s: f64,
    /// Downward pitch of the forward-looking camera, degrees. Default 20.
    pub forward_pitch_deg: f64,
    /// What the flight passes over. Default `city`.
    pub terrain: Terrain,
    /// Every wavelength of the ground's texture multiplied by this
    /// ([`SceneConfig::ground_texture_scale`]): about the height over 30 m for a flight
    /// kilometres up, whose pixels are metres across. Default 1.
    pub texture_scale: f64,
}

/// The ground under a flight ([`FlightConfig::terrain`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Terrain {
    /// The synthetic city: a street with buildings, boxes and poles on both sides.
    #[default]
    City,
    /// Open, flat ground (the street's textures; the buildings set back out of view): the
    /// planar scene where the eight-point algorithm is degenerate.
    Open,
    /// A forest track: tree crowns 8–25 m high on both sides, 150 m deep (the paper's UAV
    /// flight is over a forest).
    Forest,
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            view: FlightView::Forward,
            height_m: 30.0,
            speed_mps: 15.0,
            rate_hz: 10.0,
            climb_m: 20.0,
            climb_period_s: 20.0,
            turn_deg: 30.0,
            turn_period_s: 30.0,
            forward_pitch_deg: 20.0,
            terrain: Terrain::City,
            texture_scale: 1.0,
        }
    }
}

impl FlightConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`SynthError::InvalidConfig`] naming the offending field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let check = |ok: bool, field: &str, message: &str| {
            if ok {
                Ok(())
            } else {
                Err(SynthError::InvalidConfig {
                    field: field.into(),
                    message: message.into(),
                })
            }
        };
        check(
            self.height_m.is_finite() && self.height_m >= 1.0 && self.height_m <= 10_000.0,
            "height_m",
            "must be within 1..=10000 m",
        )?;
        check(
            self.speed_mps.is_finite() && (0.0..=300.0).contains(&self.speed_mps),
            "speed_mps",
            "must be within 0..=300 m/s",
        )?;
        check(
            self.rate_hz.is_finite() && self.rate_hz > 0.0,
            "rate_hz",
            "must be finite and positive",
        )?;
        check(
            self.climb_m.is_finite() && self.climb_m >= 0.0,
            "climb_m",
            "must be finite and >= 0",
        )?;
        check(
            self.climb_period_s.is_finite() && self.climb_period_s > 0.0,
            "climb_period_s",
            "must be finite and positive",
        )?;
        check(
            self.turn_deg.is_finite() && self.turn_deg.abs() <= 90.0,
            "turn_deg",
            "must be within -90..=90 degrees",
        )?;
        check(
            self.turn_period_s.is_finite() && self.turn_period_s > 0.0,
            "turn_period_s",
            "must be finite and positive",
        )?;
        check(
            self.forward_pitch_deg.is_finite() && (0.0..=80.0).contains(&self.forward_pitch_deg),
            "forward_pitch_deg",
            "must be within 0..=80 degrees",
        )?;
        check(
            crate::scene_config::GROUND_TEXTURE_SCALE.contains(&self.texture_scale),
            "texture_scale",
            "must be within 0.001..=10000",
        )
    }

    /// The named flights: `forward` (the defaults) and `down` (the same flight looking straight
    /// down); `None` for another name.
    #[must_use]
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "forward" => Some(Self::default()),
            "down" => Some(Self {
                view: FlightView::Down,
                ..Self::default()
            }),
            _ => None,
        }
    }

    /// The scene to render the flight in: the defaults of [`SceneConfig`] with the ground
    /// `height_m` below the lowest camera and the sky beyond the far edge of the view.
    #[must_use]
    pub fn scene(&self) -> SceneConfig {
        let defaults = SceneConfig::default();
        let (setback_min_m, setback_max_m, forest_depth_m) = match self.terrain {
            Terrain::City => (defaults.setback_min_m, defaults.setback_max_m, 0.0),
            Terrain::Open => (900.0, 950.0, 0.0),
            Terrain::Forest => (defaults.setback_min_m, defaults.setback_max_m, 150.0),
        };
        SceneConfig {
            ground_depth_m: self.height_m,
            max_distance_m: defaults
                .max_distance_m
                .max(20.0 * (self.height_m + self.climb_m)),
            setback_min_m,
            setback_max_m,
            forest_depth_m,
            ground_texture_scale: self.texture_scale,
            ..defaults
        }
    }
}

/// A generated flight of `frames` poses (see the module docs): constant ground speed, the
/// height a sine of `climb_m` peak to peak, the heading a sine of `turn_deg`.
///
/// # Errors
/// An invalid config ([`FlightConfig::validate`]).
pub fn flight_trajectory(frames: usize, config: &FlightConfig) -> Result<Vec<Pose>, SynthError> {
    config.validate()?;
    let dt = 1.0 / config.rate_hz;
    let heading = |t: f64| {
        config.turn_deg.to_radians() * (std::f64::consts::TAU * t / config.turn_period_s).sin()
    };
    // y down: a climb lowers y; the first camera is at the top of nothing in particular, y = 0
    let up_m = |t: f64| {
        0.5 * config.climb_m * (1.0 - (std::f64::consts::TAU * t / config.climb_period_s).cos())
    };
    let camera_tilt = match config.view {
        // pitch down: rotate about the camera x axis so that z leans towards +y (down)
        FlightView::Forward => -config.forward_pitch_deg.to_radians(),
        FlightView::Down => -std::f64::consts::FRAC_PI_2,
    };
    let mut position = Vector3::zeros();
    let mut poses = Vec::with_capacity(frames);
    for k in 0..frames {
        let t = k as f64 * dt;
        let psi = heading(t);
        if k > 0 {
            // integrate the horizontal motion at the mid-point heading
            let mid = heading(t - 0.5 * dt);
            position.x += config.speed_mps * dt * mid.sin();
            position.z += config.speed_mps * dt * mid.cos();
        }
        position.y = -up_m(t);
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), psi);
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), camera_tilt);
        poses.push(Pose::from_parts(Translation3::from(position), yaw * tilt));
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_downward_flight_looks_down_and_flies_at_its_speed() {
        let cfg = FlightConfig {
            view: FlightView::Down,
            turn_deg: 0.0,
            climb_m: 0.0,
            ..FlightConfig::default()
        };
        let poses = flight_trajectory(11, &cfg).unwrap();
        let optical_axis = poses[0].rotation * Vector3::z();
        assert!(
            (optical_axis - Vector3::y()).norm() < 1e-12,
            "{optical_axis}"
        );
        // image up (-y of the camera) is the direction of flight (+z)
        let image_up = poses[0].rotation * -Vector3::y();
        assert!((image_up - Vector3::z()).norm() < 1e-12, "{image_up}");
        let travelled = (poses[10].translation.vector - poses[0].translation.vector).norm();
        assert!((travelled - cfg.speed_mps).abs() < 1e-9, "{travelled}");
    }

    #[test]
    fn a_forward_flight_climbs_and_descends_by_its_amplitude() {
        let cfg = FlightConfig::default();
        let frames = (cfg.climb_period_s * cfg.rate_hz) as usize + 1;
        let poses = flight_trajectory(frames, &cfg).unwrap();
        let top = poses
            .iter()
            .map(|p| -p.translation.y)
            .fold(f64::MIN, f64::max);
        assert!((top - cfg.climb_m).abs() < 1e-6, "{top}");
        assert!(poses.last().unwrap().translation.y.abs() < 1e-6);
        // the forward camera looks ahead and down
        let axis = poses[0].rotation * Vector3::z();
        assert!(axis.z > 0.9 && axis.y > 0.3, "{axis}");
        assert_eq!(cfg.scene().ground_depth_m, cfg.height_m);
    }

    #[test]
    fn invalid_flights_are_errors() {
        for cfg in [
            FlightConfig {
                height_m: f64::NAN,
                ..FlightConfig::default()
            },
            FlightConfig {
                rate_hz: 0.0,
                ..FlightConfig::default()
            },
            FlightConfig {
                speed_mps: -1.0,
                ..FlightConfig::default()
            },
        ] {
            assert!(matches!(
                flight_trajectory(3, &cfg),
                Err(SynthError::InvalidConfig { .. })
            ));
        }
    }

    /// The terrains: open ground has nothing standing within its view, the forest many more
    /// objects than the city (its crowns), and a forest depth out of range is an error.
    #[test]
    fn terrains_lay_out_their_scenes() {
        let scene = |terrain| {
            let cfg = FlightConfig {
                terrain,
                ..FlightConfig::default()
            };
            let poses = flight_trajectory(50, &cfg).unwrap();
            crate::Scene::along_with(&poses, 1, cfg.scene()).unwrap()
        };
        let city = scene(Terrain::City).object_count();
        let forest = scene(Terrain::Forest).object_count();
        assert!(forest > 5 * city, "forest {forest}, city {city}");
        let open = FlightConfig {
            terrain: Terrain::Open,
            ..FlightConfig::default()
        }
        .scene();
        assert!(open.setback_min_m > 20.0 * open.ground_depth_m);
        let bad = crate::SceneConfig {
            forest_depth_m: -1.0,
            ..crate::SceneConfig::default()
        };
        assert!(bad.validate().is_err());
        let parsed: FlightConfig = serde_json::from_str(r#"{"terrain": "forest"}"#).unwrap();
        assert_eq!(parsed.terrain, Terrain::Forest);
    }

    /// A flight kilometres up sees texture only with its ground's wavelengths scaled: at 3 km
    /// the street's textures average to one grey (the pipeline refuses such frames), scaled by
    /// 100 they are a field's; a scale out of range is an error.
    #[test]
    fn the_texture_scale_gives_a_high_flight_its_texture() {
        let contrast = |texture_scale: f64| {
            let cfg = FlightConfig {
                view: FlightView::Down,
                height_m: 3000.0,
                texture_scale,
                ..FlightConfig::default()
            };
            let poses = flight_trajectory(1, &cfg).unwrap();
            let scene = crate::Scene::along_with(&poses, 1, cfg.scene())
                .unwrap()
                .with_supersampling(1);
            let cam = crate::kitti_like_camera(160, 48);
            let image = crate::render_view(&scene, &cam, &poses[0]).image;
            let data = image.data();
            let mean = data.iter().sum::<f32>() / data.len() as f32;
            (data.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / data.len() as f32).sqrt()
        };
        let (street, field) = (contrast(1.0), contrast(100.0));
        assert!(street < 2.0 && field > 4.0, "sd {street} against {field}");
        let bad = FlightConfig {
            texture_scale: 0.0,
            ..FlightConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
