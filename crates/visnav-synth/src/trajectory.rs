//! Generated drives: a smooth camera trajectory at a fixed frame rate with straight cruising,
//! left and right turns, a stop (standstill for several frames) and a pure rotation on the spot.
//!
//! Poses are `world_from_cam` with the world = the first camera frame (x right, y down,
//! z forward, metres), as in KITTI ground truth. The ground is the plane `y = +ground_depth`.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use visnav_core::Pose;

use crate::SynthError;

/// Parameters of [`drive_trajectory_with`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveConfig {
    /// Frame rate, Hz (KITTI: 10).
    pub rate_hz: f64,
    /// Lowest cruise speed, m/s (drawn per seed between min and max).
    pub min_speed_mps: f64,
    /// Highest cruise speed, m/s.
    pub max_speed_mps: f64,
    /// Largest heading change of a turn, degrees (drives shorter than 20 s turn less).
    pub max_turn_deg: f64,
    /// Amplitude of the pitch oscillation (suspension), degrees.
    pub pitch_amplitude_deg: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10.0,
            min_speed_mps: 8.0,
            max_speed_mps: 12.0,
            max_turn_deg: 60.0,
            pitch_amplitude_deg: 0.4,
        }
    }
}

impl DriveConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`SynthError::InvalidConfig`] naming the offending field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |field: &str, message: &str| {
            Err(SynthError::InvalidConfig {
                field: field.into(),
                message: message.into(),
            })
        };
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return bad("rate_hz", "must be finite and positive");
        }
        if !(self.min_speed_mps >= 0.0 && self.max_speed_mps >= self.min_speed_mps) {
            return bad("min_speed_mps", "need 0 <= min_speed_mps <= max_speed_mps");
        }
        if !(self.max_speed_mps.is_finite() && self.max_speed_mps < 100.0) {
            return bad("max_speed_mps", "must be finite and below 100 m/s");
        }
        if !(self.max_turn_deg.is_finite() && (0.0..=180.0).contains(&self.max_turn_deg)) {
            return bad("max_turn_deg", "must be within 0..=180");
        }
        if !(self.pitch_amplitude_deg.is_finite() && self.pitch_amplitude_deg.abs() < 10.0) {
            return bad("pitch_amplitude_deg", "must be finite and below 10 degrees");
        }
        Ok(())
    }
}

/// A generated drive of `frames` poses (`world_from_cam`, 10 Hz, 8–12 m/s) with the defaults of
/// [`DriveConfig`]: cruise, a turn, a stop, a rotation on the spot, a turn the other way.
#[must_use]
pub fn drive_trajectory(frames: usize, seed: u64) -> Vec<Pose> {
    drive_trajectory_with(frames, seed, &DriveConfig::default())
}

/// Phases of the drive as fractions of its duration: (fraction, speed factor, heading change
/// factor). Stop and rotation are consecutive so the rotation starts from standstill.
const PHASES: [(f64, f64, f64); 8] = [
    (0.14, 1.0, 0.0),  // cruise
    (0.16, 1.0, 1.0),  // turn A
    (0.10, 1.0, 0.0),  // cruise
    (0.20, 0.0, 0.0),  // stop and stand still
    (0.10, 0.0, 0.5),  // rotate on the spot (half a turn angle)
    (0.10, 1.0, 0.0),  // cruise
    (0.12, 1.0, -1.0), // turn B, the other way
    (0.08, 1.0, 0.0),  // cruise
];

/// A generated drive with explicit parameters (see [`drive_trajectory`]). An invalid config
/// falls back to the defaults.
#[must_use]
pub fn drive_trajectory_with(frames: usize, seed: u64, config: &DriveConfig) -> Vec<Pose> {
    let default_config = DriveConfig::default();
    let config = if config.validate().is_ok() {
        config
    } else {
        &default_config
    };
    if frames == 0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_d71e);
    let speed = rng.random_range(config.min_speed_mps..=config.max_speed_mps);
    let turn_sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let duration_s = frames as f64 / config.rate_hz;
    let turn_rad = config.max_turn_deg.to_radians()
        * rng.random_range(0.6..=1.0)
        * (duration_s / 20.0).clamp(0.3, 1.0);
    let pitch_period_s = rng.random_range(2.5..4.5);
    let roll_period_s = rng.random_range(3.0..6.0);

    // targets on a fine time grid, then smoothed by two box filters (a C1 profile)
    let substeps = 10usize;
    let dt = 1.0 / (config.rate_hz * substeps as f64);
    let n = frames * substeps + 1;
    let mut speed_target = vec![0.0f64; n];
    let mut yaw_rate_target = vec![0.0f64; n];
    let mut start = 0.0f64;
    for (k, &(fraction, speed_factor, turn_factor)) in PHASES.iter().enumerate() {
        let len_s = fraction * duration_s;
        let i0 = ((start / dt).round() as usize).min(n);
        let i1 = if k + 1 == PHASES.len() {
            n
        } else {
            (((start + len_s) / dt).round() as usize).min(n)
        };
        for i in i0..i1 {
            speed_target[i] = speed * speed_factor;
            yaw_rate_target[i] = turn_sign * turn_factor * turn_rad / len_s.max(dt);
        }
        start += len_s;
    }
    let window = ((0.06 * duration_s).clamp(0.1, 2.0) / dt).round().max(1.0) as usize;
    let speed_mps = box_smooth(&box_smooth(&speed_target, window), window);
    let yaw_rate = box_smooth(&box_smooth(&yaw_rate_target, window), window);

    let mut yaw = 0.0f64;
    let mut pos = Vector3::zeros();
    let mut poses = Vec::with_capacity(frames);
    for i in 0..n {
        if i % substeps == 0 && poses.len() < frames {
            let t = i as f64 * dt;
            let motion = (speed_mps[i] / speed.max(1e-9)).clamp(0.0, 1.0);
            let pitch = config.pitch_amplitude_deg.to_radians()
                * motion
                * (std::f64::consts::TAU * t / pitch_period_s).sin();
            let roll = 0.5
                * config.pitch_amplitude_deg.to_radians()
                * motion
                * (std::f64::consts::TAU * t / roll_period_s).sin();
            let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), pitch)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll);
            poses.push(Isometry3::from_parts(Translation3::from(pos), rot));
        }
        // midpoint integration of the heading, then the position
        let yaw_mid = yaw + 0.5 * yaw_rate[i] * dt;
        pos += speed_mps[i] * dt * Vector3::new(yaw_mid.sin(), 0.0, yaw_mid.cos());
        yaw += yaw_rate[i] * dt;
    }
    // express everything in the first camera frame (the first pose is the identity)
    let first_inv = poses[0].inverse();
    poses.iter().map(|p| first_inv * p).collect()
}

/// A closed drive around a block: a rectangle of `length_m` x `width_m` (centre-line sides)
/// with quarter-circle corners of radius `corner_radius_m`, driven clockwise seen from above
/// (right turns) at `step_m` metres per frame, starting in the middle of a long side heading
/// `+z`. After one lap (`length_m`, `width_m` and the corners add up to the perimeter) the drive
/// goes on over its own start for the remaining frames, so the last frames revisit the first
/// ones: the loop-closure test drive. Level, no pitch; `world_from_cam`, the first pose is the
/// identity. Empty for `frames = 0` or a non-positive size.
#[must_use]
pub fn loop_trajectory(
    frames: usize,
    length_m: f64,
    width_m: f64,
    corner_radius_m: f64,
    step_m: f64,
) -> Vec<Pose> {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if frames == 0
        || !(ok(length_m) && ok(width_m) && ok(corner_radius_m) && ok(step_m))
        || 2.0 * corner_radius_m > length_m.min(width_m)
    {
        return Vec::new();
    }
    let straight_long = length_m - 2.0 * corner_radius_m;
    let straight_short = width_m - 2.0 * corner_radius_m;
    let arc = std::f64::consts::FRAC_PI_2 * corner_radius_m;
    // the lap from the middle of a long side: (length, curvature) pieces
    let pieces = [
        (0.5 * straight_long, 0.0),
        (arc, 1.0 / corner_radius_m),
        (straight_short, 0.0),
        (arc, 1.0 / corner_radius_m),
        (straight_long, 0.0),
        (arc, 1.0 / corner_radius_m),
        (straight_short, 0.0),
        (arc, 1.0 / corner_radius_m),
        (0.5 * straight_long, 0.0),
    ];
    let perimeter: f64 = pieces.iter().map(|p| p.0).sum();
    // heading and position at arc length s (exact: straight pieces and circular arcs)
    let pose_at = |s: f64| {
        let mut s = s.rem_euclid(perimeter);
        let (mut x, mut z, mut yaw) = (0.0f64, 0.0f64, 0.0f64);
        for &(len, curvature) in &pieces {
            let d = s.min(len);
            if curvature == 0.0 {
                x += d * yaw.sin();
                z += d * yaw.cos();
            } else {
                // a right turn: the heading grows, the centre lies to the right (+x side)
                let r = 1.0 / curvature;
                let dyaw = d * curvature;
                x += r * (yaw.cos() - (yaw + dyaw).cos());
                z += r * ((yaw + dyaw).sin() - yaw.sin());
                yaw += dyaw;
            }
            s -= d;
            if s <= 0.0 {
                break;
            }
        }
        Isometry3::from_parts(
            Translation3::new(x, 0.0, z),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw),
        )
    };
    (0..frames).map(|k| pose_at(k as f64 * step_m)).collect()
}

/// The loop-closure test drive of the tests and `visnav demo`: [`loop_trajectory`] around a
/// 50 m x 30 m block with 10 m corner radii (perimeter 142.83 m) at 1.6 m a frame (16 m/s at
/// 10 Hz), so one lap takes 89 frames and the frames after revisit the start.
#[must_use]
pub fn block_loop_trajectory(frames: usize) -> Vec<Pose> {
    loop_trajectory(frames, 50.0, 30.0, 10.0, 1.6)
}

/// Centred moving average with a window of `w` samples (edges use the available samples).
fn box_smooth(x: &[f64], w: usize) -> Vec<f64> {
    let half = w / 2;
    let mut prefix = Vec::with_capacity(x.len() + 1);
    prefix.push(0.0);
    for v in x {
        prefix.push(prefix[prefix.len() - 1] + v);
    }
    (0..x.len())
        .map(|i| {
            let a = i.saturating_sub(half);
            let b = (i + half + 1).min(x.len());
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::se3::rotation_angle;

    #[test]
    fn drive_has_speed_turns_stop_and_rotation() {
        let poses = drive_trajectory(300, 3);
        assert_eq!(poses.len(), 300);
        assert!((poses[0].to_homogeneous() - nalgebra::Matrix4::identity()).norm() < 1e-12);
        let steps: Vec<(f64, f64)> = poses
            .windows(2)
            .map(|w| {
                let rel = w[0].inverse() * w[1];
                (rel.translation.vector.norm(), rotation_angle(&rel))
            })
            .collect();
        let max_speed = steps.iter().map(|s| s.0).fold(0.0, f64::max) * 10.0;
        assert!((8.0..=12.5).contains(&max_speed), "max speed {max_speed}");
        let standstill = steps.iter().filter(|s| s.0 < 1e-9 && s.1 < 1e-9).count();
        assert!(standstill >= 5, "standstill frames {standstill}");
        let pure_rotation = steps.iter().filter(|s| s.0 < 1e-9 && s.1 > 1e-3).count();
        assert!(pure_rotation >= 5, "pure rotation frames {pure_rotation}");
        let total_turn: f64 = steps.iter().map(|s| s.1).sum();
        assert!(total_turn > 0.5, "total turning {total_turn} rad");
        // smooth: speed changes by less than 0.6 m/s between frames (6 m/s^2)
        for w in steps.windows(2) {
            assert!((w[1].0 - w[0].0).abs() * 10.0 < 0.6, "{w:?}");
        }
        // deterministic for a seed, different for another
        assert_eq!(drive_trajectory(300, 3), poses);
        assert_ne!(drive_trajectory(300, 4), poses);
    }

    #[test]
    fn short_drive_still_has_all_phases() {
        let poses = drive_trajectory(50, 0);
        assert_eq!(poses.len(), 50);
        let still = poses
            .windows(2)
            .filter(|w| (w[0].translation.vector - w[1].translation.vector).norm() < 1e-9)
            .count();
        assert!(still >= 5, "{still}");
        assert!(drive_trajectory(0, 0).is_empty());
        assert!(DriveConfig::default().validate().is_ok());
        let bad = DriveConfig {
            rate_hz: -1.0,
            ..DriveConfig::default()
        };
        assert!(bad.validate().is_err());
    }
    #[test]
    fn loop_drive_closes_on_itself() {
        // 60 x 40 m block, 8 m corners: perimeter 2 (60 + 40) - 8 * 8 + 2 pi 8 = 186.27 m
        let perimeter = 200.0 - 64.0 + std::f64::consts::TAU * 8.0;
        let step = perimeter / 100.0;
        let poses = loop_trajectory(120, 60.0, 40.0, 8.0, step);
        assert_eq!(poses.len(), 120);
        assert!((poses[0].to_homogeneous() - nalgebra::Matrix4::identity()).norm() < 1e-12);
        // frame 100 is back at the start, with the start's heading; frame 110 revisits frame 10
        assert!((poses[100].to_homogeneous() - poses[0].to_homogeneous()).norm() < 1e-9);
        assert!((poses[110].to_homogeneous() - poses[10].to_homogeneous()).norm() < 1e-9);
        // constant speed, level, turns right (x grows first)
        for w in poses.windows(2) {
            let d = (w[1].translation.vector - w[0].translation.vector).norm();
            assert!((d - step).abs() < 0.02 * step, "{d}");
            assert!(w[1].translation.y.abs() < 1e-12);
        }
        let far = poses.iter().map(|p| p.translation.x).fold(0.0, f64::max);
        assert!((far - 40.0).abs() < 1e-9, "{far}");
        assert!(loop_trajectory(10, 10.0, 10.0, 6.0, 1.0).is_empty());
        assert!(loop_trajectory(0, 60.0, 40.0, 8.0, 1.0).is_empty());
    }
}

/// A highway drive of `frames` poses (`world_from_cam`, 10 Hz): a constant cruise speed drawn
/// per seed in 25–30 m/s (2.5–3 m a frame), gentle S-curves (yaw rate a sum of two sinusoids,
/// curve radius above ≈ 1.5 km), a slight pitch and roll (suspension, 0.3° / 0.15°), no stops.
/// The first pose is the identity. Lay the scene out with [`crate::SceneConfig::highway`] for
/// the repetitive roadside of a motorway.
#[must_use]
pub fn highway_trajectory(frames: usize, seed: u64) -> Vec<Pose> {
    if frames == 0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4194_3a7e);
    let rate_hz = 10.0;
    let speed = rng.random_range(25.0..=30.0);
    // yaw rate (rad/s) = speed / radius: amplitudes for radii of ≈ 1.5 km and more
    let yaw_amp = [
        speed / rng.random_range(1500.0..3000.0),
        speed / rng.random_range(3000.0..6000.0),
    ];
    let yaw_period_s = [rng.random_range(20.0..35.0), rng.random_range(8.0..14.0)];
    let phase = [
        rng.random_range(0.0..std::f64::consts::TAU),
        rng.random_range(0.0..std::f64::consts::TAU),
    ];
    let pitch_period_s = rng.random_range(2.5..4.5);
    let roll_period_s = rng.random_range(3.0..6.0);
    let substeps = 10usize;
    let dt = 1.0 / (rate_hz * substeps as f64);
    let yaw_rate = |t: f64| {
        (0..2)
            .map(|i| yaw_amp[i] * (std::f64::consts::TAU * t / yaw_period_s[i] + phase[i]).sin())
            .sum::<f64>()
    };
    let (mut yaw, mut pos) = (0.0f64, Vector3::zeros());
    let mut poses = Vec::with_capacity(frames);
    for i in 0..frames * substeps {
        let t = i as f64 * dt;
        if i % substeps == 0 {
            let pitch = 0.3f64.to_radians() * (std::f64::consts::TAU * t / pitch_period_s).sin();
            let roll = 0.15f64.to_radians() * (std::f64::consts::TAU * t / roll_period_s).sin();
            let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), pitch)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll);
            poses.push(Isometry3::from_parts(Translation3::from(pos), rot));
        }
        let yaw_mid = yaw + 0.5 * yaw_rate(t) * dt;
        pos += speed * dt * Vector3::new(yaw_mid.sin(), 0.0, yaw_mid.cos());
        yaw += yaw_rate(t + 0.5 * dt) * dt;
    }
    let first_inv = poses[0].inverse();
    poses.iter().map(|p| first_inv * p).collect()
}

#[cfg(test)]
mod highway_tests {
    use super::*;

    #[test]
    fn highway_drive_is_fast_smooth_and_deterministic() {
        let poses = highway_trajectory(200, 3);
        assert_eq!(poses.len(), 200);
        assert_eq!(poses, highway_trajectory(200, 3));
        for w in poses.windows(2) {
            let step = (w[1].translation.vector - w[0].translation.vector).norm();
            assert!((2.45..=3.05).contains(&step), "step {step} m");
            let turn = (w[0].rotation.inverse() * w[1].rotation)
                .angle()
                .to_degrees();
            assert!(turn < 0.3, "turn {turn} deg a frame");
        }
    }
}
