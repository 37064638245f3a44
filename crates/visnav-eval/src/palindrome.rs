//! Palindrome drift test (§6.2 of Ng, Li & Kim 2021): the frames `0..N` are played forward and
//! then backward (`N−1` once, the turning frame), so the true trajectory ends where it started.
//! Without ground truth, two figures measure the drift of a monocular odometry on such a run:
//!
//! - the **end-point error**: distance between the first and the last camera centre, metres and
//!   as a fraction of the distance travelled (sum of the step lengths of the whole run);
//! - the **scale drift**: mean step length on the way back divided by the mean step length on the
//!   way out (1 = no scale drift; the paper plots this as a percentage scale difference);
//! - the **farthest point** from the start on the way out, which the paper's UAV experiment
//!   compares with GPS (Table 3).

use serde::{Deserialize, Serialize};
use visnav_core::Pose;

/// Drift figures of a palindrome run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PalindromeDrift {
    /// Frames of the forward half (`N`).
    pub frames_out: usize,
    /// Distance travelled over the whole run (forward and back), metres.
    pub distance_travelled_m: f64,
    /// Distance between the first and the last camera centre, metres.
    pub end_point_error_m: f64,
    /// `end_point_error_m / distance_travelled_m` (0 when nothing was travelled).
    pub end_point_error_relative: f64,
    /// Mean step length of the forward half, metres.
    pub mean_step_out_m: f64,
    /// Mean step length of the backward half, metres.
    pub mean_step_back_m: f64,
    /// `mean_step_back_m / mean_step_out_m` (1 = no scale drift; NaN without forward motion,
    /// `null` in JSON).
    #[serde(deserialize_with = "f64_or_nan")]
    pub scale_drift_ratio: f64,
    /// Largest distance of a camera centre of the forward half from the first, metres (0 in
    /// reports written before it existed).
    #[serde(default)]
    pub farthest_from_start_m: f64,
    /// The frame (of the forward half) where it is reached.
    #[serde(default)]
    pub farthest_frame: usize,
}

/// The CLI's table of the drift figures, one line each.
impl std::fmt::Display for PalindromeDrift {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "palindrome drift (§6.2)")?;
        writeln!(
            f,
            "  distance travelled   {:>10.3} m",
            self.distance_travelled_m
        )?;
        writeln!(
            f,
            "  end-point error      {:>10.3} m  ({:.2} % of the distance)",
            self.end_point_error_m,
            100.0 * self.end_point_error_relative
        )?;
        writeln!(
            f,
            "  scale drift          {:>10.4}    (mean step back {:.3} m / out {:.3} m)",
            self.scale_drift_ratio, self.mean_step_back_m, self.mean_step_out_m
        )?;
        writeln!(
            f,
            "  farthest from start  {:>10.3} m  (frame {}; the paper's Table 3)",
            self.farthest_from_start_m, self.farthest_frame
        )
    }
}

/// A number that JSON may hold as `null` (NaN).
fn f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Option::<f64>::deserialize(d).map(|v| v.unwrap_or(f64::NAN))
}

/// Drift of a palindrome run from its `2n − 1` poses `world_from_cam` (in the order of
/// `visnav_io::source::palindrome_order`). `None` when `poses.len()` is not odd or below 3.
#[must_use]
pub fn palindrome_drift(poses: &[Pose]) -> Option<PalindromeDrift> {
    if poses.len() < 3 || poses.len().is_multiple_of(2) {
        return None;
    }
    let n = poses.len().div_ceil(2);
    let steps: Vec<f64> = poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .collect();
    let (out, back) = steps.split_at(n - 1);
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let distance_travelled_m: f64 = steps.iter().sum();
    let end_point_error_m =
        (poses[poses.len() - 1].translation.vector - poses[0].translation.vector).norm();
    let (farthest_frame, farthest_from_start_m) = poses[..n]
        .iter()
        .map(|p| (p.translation.vector - poses[0].translation.vector).norm())
        .enumerate()
        .fold(
            (0, 0.0),
            |best, (i, d)| if d > best.1 { (i, d) } else { best },
        );
    let mean_step_out_m = mean(out);
    let mean_step_back_m = mean(back);
    Some(PalindromeDrift {
        frames_out: n,
        distance_travelled_m,
        end_point_error_m,
        end_point_error_relative: if distance_travelled_m > 0.0 {
            end_point_error_m / distance_travelled_m
        } else {
            0.0
        },
        mean_step_out_m,
        mean_step_back_m,
        scale_drift_ratio: if mean_step_out_m > 0.0 {
            mean_step_back_m / mean_step_out_m
        } else {
            f64::NAN
        },
        farthest_from_start_m,
        farthest_frame,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use visnav_io::source::palindrome_order;

    fn at(z: f64) -> Pose {
        Pose::from_parts(Translation3::new(0.0, 0.0, z), UnitQuaternion::identity())
    }

    #[test]
    fn perfect_run_has_no_drift() {
        let poses: Vec<Pose> = palindrome_order(5).iter().map(|&i| at(i as f64)).collect();
        let d = palindrome_drift(&poses).unwrap();
        assert_eq!(d.frames_out, 5);
        assert!((d.distance_travelled_m - 8.0).abs() < 1e-12);
        assert!(d.end_point_error_m < 1e-12);
        assert!((d.scale_drift_ratio - 1.0).abs() < 1e-12);
    }

    #[test]
    fn shrinking_scale_on_the_way_back_is_measured() {
        // out: 4 steps of 1 m; back: 4 steps of 0.5 m -> ends 2 m from the start
        let mut poses: Vec<Pose> = (0..5).map(|i| at(f64::from(i))).collect();
        poses.extend((0..4).rev().map(|i| at(2.0 + 0.5 * f64::from(i))));
        let d = palindrome_drift(&poses).unwrap();
        assert!((d.scale_drift_ratio - 0.5).abs() < 1e-12);
        assert!((d.end_point_error_m - 2.0).abs() < 1e-12);
        assert!((d.end_point_error_relative - 2.0 / 6.0).abs() < 1e-12);
        assert_eq!(d.farthest_frame, 4);
        assert!((d.farthest_from_start_m - 4.0).abs() < 1e-12);
        assert!(palindrome_drift(&poses[..8]).is_none());
    }
}
