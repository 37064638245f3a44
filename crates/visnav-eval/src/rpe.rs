//! Relative pose error (RPE, Sturm et al. 2012): for every frame pair `(i, i + Δ)`, the error of
//! the estimated relative motion, `E_i = inv(inv(gt_i) gt_{i+Δ}) · (inv(est_i) est_{i+Δ})`;
//! reported as the RMSE of `|t(E_i)|` (metres) and of `angle(E_i)` (degrees).

use serde::Serialize;

use crate::PoseMatrix;
use crate::kitti::{invert, rotation_error, translation_error};

/// Relative pose error at one frame offset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RpeResult {
    /// Frame offset Δ.
    pub delta_frames: usize,
    /// Number of frame pairs.
    pub pairs: usize,
    /// RMSE of the translation error, metres.
    pub trans_rmse_m: f64,
    /// Mean translation error, metres.
    pub trans_mean_m: f64,
    /// RMSE of the rotation error, degrees.
    pub rot_rmse_deg: f64,
    /// Mean rotation error, degrees.
    pub rot_mean_deg: f64,
}

/// RPE of `est` against `gt` (frame `i` matching frame `i`) at offset `delta_frames`. `None`
/// when `delta_frames` is 0 or the trajectories have no pair that far apart.
#[must_use]
pub fn rpe(gt: &[PoseMatrix], est: &[PoseMatrix], delta_frames: usize) -> Option<RpeResult> {
    let n = gt.len().min(est.len());
    if delta_frames == 0 || n <= delta_frames {
        return None;
    }
    let (mut t_sq, mut t_sum, mut r_sq, mut r_sum) = (0.0, 0.0, 0.0, 0.0);
    let pairs = n - delta_frames;
    for i in 0..pairs {
        let j = i + delta_frames;
        let gt_rel = invert(&gt[i]) * gt[j];
        let est_rel = invert(&est[i]) * est[j];
        let e = invert(&gt_rel) * est_rel;
        let t = translation_error(&e);
        let r = rotation_error(&e).to_degrees();
        t_sq += t * t;
        t_sum += t;
        r_sq += r * r;
        r_sum += r;
    }
    let m = pairs as f64;
    Some(RpeResult {
        delta_frames,
        pairs,
        trans_rmse_m: (t_sq / m).sqrt(),
        trans_mean_m: t_sum / m,
        rot_rmse_deg: (r_sq / m).sqrt(),
        rot_mean_deg: r_sum / m,
    })
}

/// Pools per-sequence results at the same offset: RMSEs over all pairs, means over all pairs.
#[must_use]
pub fn pool(results: &[RpeResult]) -> Option<RpeResult> {
    let first = results.first()?;
    let pairs: usize = results.iter().map(|r| r.pairs).sum();
    let m = pairs as f64;
    let w = |f: &dyn Fn(&RpeResult) -> f64| {
        results.iter().map(|r| f(r) * r.pairs as f64).sum::<f64>() / m
    };
    Some(RpeResult {
        delta_frames: first.delta_frames,
        pairs,
        trans_rmse_m: w(&|r| r.trans_rmse_m * r.trans_rmse_m).sqrt(),
        trans_mean_m: w(&|r| r.trans_mean_m),
        rot_rmse_deg: w(&|r| r.rot_rmse_deg * r.rot_rmse_deg).sqrt(),
        rot_mean_deg: w(&|r| r.rot_mean_deg),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use visnav_core::Pose;

    #[test]
    fn constant_motion_error_is_recovered() {
        let step = |s: f64, yaw: f64| {
            Pose::from_parts(
                Translation3::new(0.0, 0.0, s),
                UnitQuaternion::from_scaled_axis(Vector3::new(0.0, yaw, 0.0)),
            )
        };
        let mut gt = vec![Pose::identity()];
        let mut est = vec![Pose::identity()];
        for _ in 0..20 {
            gt.push(gt[gt.len() - 1] * step(1.0, 0.01));
            est.push(est[est.len() - 1] * step(1.1, 0.01 + 0.002));
        }
        let gt = crate::pose_matrices(&gt);
        let est = crate::pose_matrices(&est);
        let r = rpe(&gt, &est, 1).unwrap();
        assert_eq!(r.pairs, 20);
        // E = inv(step(1, a)) step(1.1, a + 0.002): rotation 0.002 rad
        assert!((r.rot_rmse_deg - 0.002f64.to_degrees()).abs() < 1e-9);
        assert!((r.trans_rmse_m - 0.1).abs() < 1e-3);
        assert!(rpe(&gt, &gt, 5).unwrap().trans_rmse_m < 1e-12);
        assert!(rpe(&gt, &est, 21).is_none());
        let p = pool(&[r, r]).unwrap();
        assert_eq!(p.pairs, 40);
        assert!((p.trans_rmse_m - r.trans_rmse_m).abs() < 1e-12);
    }
}
