//! A small drone's indoor flight (issue 54): a downward camera flying low (1–3 m) over a flat
//! floor mat with weak texture and sparse markers ([`crate::MatConfig`]), taking off from the
//! floor (about 0.1 m), hovering, flying straight legs at changing heights, turning on the spot
//! (yaw only) and landing; a 640x360 camera with a real small drone's radial distortion,
//! vignetting, JPEG compression, sensor noise and motion blur ([`IndoorFlightConfig`]; rendered by
//! [`crate::write_indoor::write_indoor_flight`]).
//!
//! Time: the camera runs at `rate_hz` (30 Hz) and every `frame_step`-th frame (3) is kept, so a
//! sequence is at 10 Hz with the steps of a 30 Hz camera taken three at a time; the motion blur
//! is that of one 30 Hz exposure. Poses are `world_from_cam` with the world = x right, y down,
//! z forward (the first camera's heading), metres, the first camera at the origin, the floor the
//! plane `y = takeoff_height_m`. Image up is the direction of flight.

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use visnav_core::{CalibratedCamera, Distortion, PinholeCamera, Pose};

use crate::{MatConfig, SceneConfig, SynthError};

/// The camera of an indoor flight: a pinhole with radial distortion (Kalibr `radtan`
/// `k1 k2 0 0`), the principal point at the image centre.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IndoorCamera {
    /// Image width, pixels. Default 640.
    pub width: u32,
    /// Image height, pixels. Default 360.
    pub height: u32,
    /// Focal length (`fx = fy`) at this width, pixels. Default 560 (about 60° across; with the
    /// default distortion a focal length below about 510 px puts the corners outside the region
    /// where the lens model can be inverted, and the reader refuses the camera).
    pub focal_px: f64,
    /// Radial distortion coefficient of r² (normalised coordinates). Default 0.19.
    pub k1: f64,
    /// Radial distortion coefficient of r⁴. Default −0.56.
    pub k2: f64,
}

impl Default for IndoorCamera {
    fn default() -> Self {
        Self {
            width: 640,
            height: 360,
            focal_px: 560.0,
            k1: 0.19,
            k2: -0.56,
        }
    }
}

impl IndoorCamera {
    /// The same lens on a `width` x `height` sensor (the focal length scaled by the width).
    #[must_use]
    pub fn resized(&self, width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            focal_px: self.focal_px * f64::from(width) / f64::from(self.width.max(1)),
            ..self.clone()
        }
    }

    /// The calibrated camera (raw, distorted images).
    ///
    /// # Errors
    /// [`SynthError::InvalidConfig`] for a size or focal length out of range.
    pub fn calibrated(&self) -> Result<CalibratedCamera, SynthError> {
        let bad = |message: String| SynthError::InvalidConfig {
            field: "camera".into(),
            message,
        };
        if !(16..=8192).contains(&self.width) || !(16..=8192).contains(&self.height) {
            return Err(bad(format!(
                "the image must be 16..=8192 pixels a side, got {}x{}",
                self.width, self.height
            )));
        }
        if !(self.k1.is_finite() && self.k2.is_finite()) {
            return Err(bad("the distortion coefficients must be finite".into()));
        }
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let pinhole = PinholeCamera::new(
            self.focal_px,
            self.focal_px,
            0.5 * w - 0.5,
            0.5 * h - 0.5,
            self.width,
            self.height,
        )
        .map_err(|e| bad(format!("focal_px {}: {e}", self.focal_px)))?;
        let camera = CalibratedCamera {
            pinhole,
            distortion: Distortion::RadialTangential {
                k1: self.k1,
                k2: self.k2,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
        };
        // the reader undistorts on load: a lens it cannot invert would render an unreadable
        // sequence
        visnav_core::rectify::undistorted_pinhole(&camera).map_err(|e| {
            bad(format!(
                "focal_px {} with k1 {} and k2 {}: {e}",
                self.focal_px, self.k1, self.k2
            ))
        })?;
        Ok(camera)
    }
}

/// Parameters of an indoor flight (module docs). Every field has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IndoorFlightConfig {
    /// The camera's frame rate, Hz. Default 30.
    pub rate_hz: f64,
    /// Every `frame_step`-th camera frame is kept (the sequence's rate is `rate_hz /
    /// frame_step`). Default 3 (10 Hz).
    pub frame_step: u32,
    /// Height of the camera above the floor before the takeoff and after the landing, metres.
    /// Default 0.1.
    pub takeoff_height_m: f64,
    /// Mean height of the legs, metres. Default 2.
    pub cruise_height_m: f64,
    /// The legs alternate between `cruise_height_m ± height_change_m / 2`, changing height as
    /// they fly. Default 1 (1.5 and 2.5 m).
    pub height_change_m: f64,
    /// Mean vertical speed of the takeoff and the landing, m/s. Default 0.4.
    pub climb_speed_mps: f64,
    /// Length of a straight leg, metres. Default 3.
    pub leg_m: f64,
    /// Mean ground speed of a leg, m/s (the speed eases in and out, peaking at π/2 of it).
    /// Default 0.5.
    pub speed_mps: f64,
    /// The yaw-only turn after each leg, degrees (positive: to the right). Default 90.
    pub turn_deg: f64,
    /// Mean yaw rate of a turn, degrees a second. Default 45.
    pub yaw_rate_dps: f64,
    /// Hover after the takeoff and after each leg and turn, seconds. Default 2.
    pub hover_s: f64,
    /// Land at the end of the sequence. Default true.
    pub land: bool,
    /// The camera and its lens.
    pub camera: IndoorCamera,
    /// Exposure time, seconds: the motion blur integrates the motion over it. Default 0.012.
    pub exposure_s: f64,
    /// Renders averaged over the exposure (1: no motion blur). Default 5.
    pub blur_samples: u32,
    /// Standard deviation of the sensor noise, grey levels. Default 1.5.
    pub noise_sd: f64,
    /// Vignetting: the brightness at the image's corners relative to its centre, falling off
    /// with the square of the distance from the centre (a small drone's lens). Default 0.8.
    pub corner_brightness: f64,
    /// JPEG quality of the written images, 1..=100. Default 85.
    pub jpeg_quality: u8,
    /// The floor.
    pub mat: MatConfig,
}

impl Default for IndoorFlightConfig {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            frame_step: 3,
            takeoff_height_m: 0.1,
            cruise_height_m: 2.0,
            height_change_m: 1.0,
            climb_speed_mps: 0.4,
            leg_m: 3.0,
            speed_mps: 0.5,
            turn_deg: 90.0,
            yaw_rate_dps: 45.0,
            hover_s: 2.0,
            land: true,
            camera: IndoorCamera::default(),
            exposure_s: 0.012,
            blur_samples: 5,
            noise_sd: 1.5,
            corner_brightness: 0.8,
            jpeg_quality: 85,
            mat: MatConfig::default(),
        }
    }
}

/// One piece of the flight plan: from its start state, over `duration_s`, eased in and out.
#[derive(Debug, Clone, Copy)]
enum Manoeuvre {
    /// Keep the state.
    Hover,
    /// Change the height to `to_m` on the spot.
    Climb { to_m: f64 },
    /// Fly `length_m` along the heading, the height changing to `to_m`.
    Leg { length_m: f64, to_m: f64 },
    /// Turn on the spot by `by_rad` (yaw only).
    Turn { by_rad: f64 },
}

/// The drone's state: horizontal position `(x, z)`, height above the floor, heading (radians,
/// 0 = +z, positive towards +x).
#[derive(Debug, Clone, Copy, PartialEq)]
struct State {
    x: f64,
    z: f64,
    height_m: f64,
    heading: f64,
}

/// The planned flight: manoeuvres with their start times and states.
#[derive(Debug, Clone)]
pub struct IndoorFlight {
    config: IndoorFlightConfig,
    plan: Vec<(f64, f64, Manoeuvre, State)>,
    duration_s: f64,
}

/// `(1 − cos πτ) / 2`: 0 at τ = 0, 1 at τ = 1, zero speed at both ends.
fn ease(tau: f64) -> f64 {
    0.5 * (1.0 - (std::f64::consts::PI * tau.clamp(0.0, 1.0)).cos())
}

impl IndoorFlightConfig {
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
        let positive = |v: f64| v.is_finite() && v > 0.0;
        check(
            positive(self.rate_hz) && self.rate_hz <= 1e4,
            "rate_hz",
            "must be within 0..=10000 Hz",
        )?;
        check(
            (1..=1000).contains(&self.frame_step),
            "frame_step",
            "must be within 1..=1000",
        )?;
        check(
            positive(self.takeoff_height_m) && self.takeoff_height_m <= 100.0,
            "takeoff_height_m",
            "must be within 0..=100 m",
        )?;
        check(
            self.height_change_m.is_finite()
                && self.height_change_m >= 0.0
                && self.cruise_height_m.is_finite()
                && self.cruise_height_m - 0.5 * self.height_change_m > 0.0
                && self.cruise_height_m + 0.5 * self.height_change_m <= 100.0,
            "cruise_height_m",
            "the legs' heights (cruise_height_m ± height_change_m / 2) must be within 0..=100 m",
        )?;
        for (field, v) in [
            ("climb_speed_mps", self.climb_speed_mps),
            ("speed_mps", self.speed_mps),
            ("yaw_rate_dps", self.yaw_rate_dps),
        ] {
            check(positive(v) && v <= 1e3, field, "must be within 0..=1000")?;
        }
        check(
            self.leg_m.is_finite() && (0.0..=1e3).contains(&self.leg_m),
            "leg_m",
            "must be within 0..=1000 m",
        )?;
        check(
            self.turn_deg.is_finite() && self.turn_deg.abs() <= 360.0,
            "turn_deg",
            "must be within -360..=360 degrees",
        )?;
        check(
            self.hover_s.is_finite() && (0.0..=1e3).contains(&self.hover_s),
            "hover_s",
            "must be within 0..=1000 s",
        )?;
        check(
            self.exposure_s.is_finite()
                && self.exposure_s >= 0.0
                && self.exposure_s * self.rate_hz <= 1.0,
            "exposure_s",
            "must be within 0..=1 / rate_hz",
        )?;
        check(
            (1..=64).contains(&self.blur_samples),
            "blur_samples",
            "must be within 1..=64",
        )?;
        check(
            self.noise_sd.is_finite() && (0.0..=50.0).contains(&self.noise_sd),
            "noise_sd",
            "must be within 0..=50 grey levels",
        )?;
        check(
            self.corner_brightness.is_finite() && (0.0..=1.0).contains(&self.corner_brightness),
            "corner_brightness",
            "must be within 0..=1",
        )?;
        check(
            (1..=100).contains(&self.jpeg_quality),
            "jpeg_quality",
            "must be within 1..=100",
        )?;
        self.camera.calibrated()?;
        self.mat.validate()
    }

    /// Time between two kept frames, seconds.
    #[must_use]
    pub fn frame_interval_s(&self) -> f64 {
        f64::from(self.frame_step) / self.rate_hz
    }

    /// The scene: the floor mat `takeoff_height_m` below the first camera, nothing standing in
    /// view (the city's buildings set back 900 m), rendered without supersampling (the mat is
    /// filtered analytically).
    #[must_use]
    pub fn scene(&self) -> SceneConfig {
        SceneConfig {
            ground_depth_m: self.takeoff_height_m,
            setback_min_m: 900.0,
            setback_max_m: 950.0,
            supersampling: 1,
            mat: Some(self.mat.clone()),
            ..SceneConfig::default()
        }
    }

    /// The flight plan for a sequence of `duration_s` seconds: takeoff, hover, then legs each
    /// followed by a hover, a turn and a hover, until the landing (its climb and a hover before
    /// it) fits only just; the landing at the end. A sequence too short for the takeoff and the
    /// landing, or `land = false`, skips the landing and flies cycles to the end (the last one
    /// cut).
    ///
    /// # Errors
    /// An invalid config.
    pub fn plan(&self, duration_s: f64) -> Result<IndoorFlight, SynthError> {
        self.validate()?;
        let climb_s = |from: f64, to: f64| (to - from).abs() / self.climb_speed_mps;
        let (low, high) = (
            self.cruise_height_m - 0.5 * self.height_change_m,
            self.cruise_height_m + 0.5 * self.height_change_m,
        );
        let takeoff_s = climb_s(self.takeoff_height_m, self.cruise_height_m);
        let mut plan = Vec::new();
        let mut state = State {
            x: 0.0,
            z: 0.0,
            height_m: self.takeoff_height_m,
            heading: 0.0,
        };
        let mut t = 0.0;
        let push = |plan: &mut Vec<_>, t: &mut f64, state: &mut State, dur: f64, m| {
            if dur > 0.0 {
                plan.push((*t, dur, m, *state));
                *t += dur;
                *state = apply(*state, m, 1.0);
            }
        };
        push(
            &mut plan,
            &mut t,
            &mut state,
            takeoff_s,
            Manoeuvre::Climb {
                to_m: self.cruise_height_m,
            },
        );
        push(
            &mut plan,
            &mut t,
            &mut state,
            self.hover_s,
            Manoeuvre::Hover,
        );
        let landing_s = |h: f64| climb_s(h, self.takeoff_height_m) + self.hover_s;
        let land = self.land && duration_s >= takeoff_s + landing_s(self.cruise_height_m);
        let leg_s = self.leg_m / self.speed_mps;
        let turn_s = self.turn_deg.abs() / self.yaw_rate_dps;
        let cycle_s = leg_s + turn_s + 2.0 * self.hover_s;
        for k in 0usize.. {
            let to_m = if k % 2 == 0 { low } else { high };
            // with a landing, whole cycles that leave room for it; without, cycles until the
            // end of the sequence (the last one cut)
            let full = if land {
                duration_s - t - landing_s(to_m) >= cycle_s
            } else {
                t < duration_s
            };
            if cycle_s <= 0.0 || !full {
                break;
            }
            let leg = Manoeuvre::Leg {
                length_m: self.leg_m,
                to_m,
            };
            push(&mut plan, &mut t, &mut state, leg_s, leg);
            push(
                &mut plan,
                &mut t,
                &mut state,
                self.hover_s,
                Manoeuvre::Hover,
            );
            let turn = Manoeuvre::Turn {
                by_rad: self.turn_deg.to_radians(),
            };
            push(&mut plan, &mut t, &mut state, turn_s, turn);
            push(
                &mut plan,
                &mut t,
                &mut state,
                self.hover_s,
                Manoeuvre::Hover,
            );
        }
        if land {
            let descent_s = climb_s(state.height_m, self.takeoff_height_m);
            let wait_s = (duration_s - t - descent_s).max(0.0);
            push(&mut plan, &mut t, &mut state, wait_s, Manoeuvre::Hover);
            let to_m = self.takeoff_height_m;
            push(
                &mut plan,
                &mut t,
                &mut state,
                descent_s,
                Manoeuvre::Climb { to_m },
            );
        }
        Ok(IndoorFlight {
            config: self.clone(),
            plan,
            duration_s,
        })
    }
}

/// The state `fraction` (0..1, eased) of the way through manoeuvre `m` from `start`.
fn apply(start: State, m: Manoeuvre, fraction: f64) -> State {
    let e = ease(fraction);
    match m {
        Manoeuvre::Hover => start,
        Manoeuvre::Climb { to_m } => State {
            height_m: start.height_m + e * (to_m - start.height_m),
            ..start
        },
        Manoeuvre::Leg { length_m, to_m } => State {
            x: start.x + e * length_m * start.heading.sin(),
            z: start.z + e * length_m * start.heading.cos(),
            height_m: start.height_m + e * (to_m - start.height_m),
            heading: start.heading,
        },
        Manoeuvre::Turn { by_rad } => State {
            heading: start.heading + e * by_rad,
            ..start
        },
    }
}

impl IndoorFlight {
    /// The config the flight was planned with.
    #[must_use]
    pub fn config(&self) -> &IndoorFlightConfig {
        &self.config
    }

    /// The planned duration, seconds.
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The drone's state at time `t_s` (before the first manoeuvre: its start; after the last:
    /// its end).
    fn state_at(&self, t_s: f64) -> State {
        let mut last = State {
            x: 0.0,
            z: 0.0,
            height_m: self.config.takeoff_height_m,
            heading: 0.0,
        };
        for &(start_s, dur_s, m, state) in &self.plan {
            if t_s < start_s {
                return last;
            }
            if t_s <= start_s + dur_s {
                return apply(state, m, (t_s - start_s) / dur_s);
            }
            last = apply(state, m, 1.0);
        }
        last
    }

    /// The camera's pose (`world_from_cam`) at time `t_s`: looking straight down, image up
    /// along the heading.
    #[must_use]
    pub fn pose_at(&self, t_s: f64) -> Pose {
        let s = self.state_at(t_s);
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), s.heading);
        let down =
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -std::f64::consts::FRAC_PI_2);
        let position = Vector3::new(s.x, self.config.takeoff_height_m - s.height_m, s.z);
        Pose::from_parts(Translation3::from(position), yaw * down)
    }

    /// The camera's height above the floor at time `t_s`, metres.
    #[must_use]
    pub fn height_at(&self, t_s: f64) -> f64 {
        self.state_at(t_s).height_m
    }

    /// The poses of `frames` kept frames (frame `k` at `k · frame_interval_s`).
    #[must_use]
    pub fn frame_poses(&self, frames: usize) -> Vec<Pose> {
        let dt = self.config.frame_interval_s();
        (0..frames).map(|k| self.pose_at(k as f64 * dt)).collect()
    }
}

/// The indoor flight of `frames` kept frames: its plan over `frames` frame intervals.
///
/// # Errors
/// An invalid config.
pub fn indoor_flight(
    frames: usize,
    config: &IndoorFlightConfig,
) -> Result<IndoorFlight, SynthError> {
    let duration_s = frames.saturating_sub(1) as f64 * config.frame_interval_s();
    config.plan(duration_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default 600-frame flight takes off from 0.1 m, flies its legs between 1.5 and
    /// 2.5 m, hovers (poses repeated exactly), turns on the spot and lands at the end.
    #[test]
    fn the_default_flight_takes_off_hovers_turns_and_lands() {
        let cfg = IndoorFlightConfig::default();
        let flight = indoor_flight(600, &cfg).unwrap();
        let poses = flight.frame_poses(600);
        let dt = cfg.frame_interval_s();
        assert!((dt - 0.1).abs() < 1e-12);
        let heights: Vec<f64> = (0..600).map(|k| flight.height_at(k as f64 * dt)).collect();
        assert!((heights[0] - 0.1).abs() < 1e-12 && (heights[599] - 0.1).abs() < 1e-9);
        let top = heights.iter().copied().fold(f64::MIN, f64::max);
        assert!((top - 2.5).abs() < 1e-9, "{top}");
        // looking down: the optical axis is +y (the floor), image up the heading (+z)
        let axis = poses[0].rotation * Vector3::z();
        assert!((axis - Vector3::y()).norm() < 1e-12, "{axis}");
        let image_up = poses[0].rotation * -Vector3::y();
        assert!((image_up - Vector3::z()).norm() < 1e-12, "{image_up}");
        let steps: Vec<(f64, f64)> = poses
            .windows(2)
            .map(|w| {
                let d = w[0].inverse() * w[1];
                (d.translation.vector.norm(), d.rotation.angle())
            })
            .collect();
        let hovers = steps.iter().filter(|s| s.0 == 0.0 && s.1 == 0.0).count();
        let turns = steps.iter().filter(|s| s.0 < 1e-12 && s.1 > 1e-3).count();
        assert!(
            hovers > 60 && turns > 20,
            "{hovers} hovers, {turns} turning steps"
        );
        let longest = steps.iter().map(|s| s.0).fold(0.0, f64::max);
        assert!(longest < 0.1, "{longest} m");
    }

    #[test]
    fn invalid_indoor_flights_are_errors() {
        for cfg in [
            IndoorFlightConfig {
                takeoff_height_m: 0.0,
                ..IndoorFlightConfig::default()
            },
            IndoorFlightConfig {
                cruise_height_m: 0.4,
                ..IndoorFlightConfig::default()
            },
            IndoorFlightConfig {
                jpeg_quality: 0,
                ..IndoorFlightConfig::default()
            },
            IndoorFlightConfig {
                exposure_s: 0.5,
                ..IndoorFlightConfig::default()
            },
            IndoorFlightConfig {
                camera: IndoorCamera {
                    focal_px: 480.0,
                    ..IndoorCamera::default()
                },
                ..IndoorFlightConfig::default()
            },
            IndoorFlightConfig {
                camera: IndoorCamera {
                    focal_px: -1.0,
                    ..IndoorCamera::default()
                },
                ..IndoorFlightConfig::default()
            },
        ] {
            assert!(matches!(
                indoor_flight(10, &cfg),
                Err(SynthError::InvalidConfig { .. })
            ));
        }
    }
}
