//! Trajectory alignment (Umeyama 1991, "Least-squares estimation of transformation parameters
//! between two point patterns", eqs. 40–42) and the absolute trajectory error (ATE).
//!
//! The alignment maps estimate positions onto ground truth, `p_gt ≈ s R p_est + t`, minimising
//! the sum of squared position differences; `s = 1` for SE(3), free for Sim(3) (monocular
//! estimates have no metric scale).

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::Serialize;
use visnav_core::Pose;

use crate::PoseMatrix;

/// A similarity transform `p ↦ s R p + t` taking estimate coordinates to ground-truth ones.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sim3 {
    /// Rotation `R`.
    pub rotation: Rotation3<f64>,
    /// Translation `t`, metres.
    pub translation: Vector3<f64>,
    /// Scale `s` (1 for an SE(3) alignment).
    pub scale: f64,
}

impl Sim3 {
    /// The identity transform.
    #[must_use]
    pub fn identity() -> Self {
        Self {
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// Applies the transform to a point.
    #[must_use]
    pub fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation * p) + self.translation
    }

    /// Applies the transform to a `world_from_cam` pose: rotation `R R_cam`, position
    /// `s R t_cam + t`.
    #[must_use]
    pub fn apply_pose(&self, pose: &Pose) -> Pose {
        Pose::from_parts(
            self.apply(&pose.translation.vector).into(),
            UnitQuaternion::from_rotation_matrix(&self.rotation) * pose.rotation,
        )
    }
}

/// Umeyama's closed-form alignment of `src` onto `dst` (eqs. 40–42): the `R`, `t` (and `s` when
/// `with_scale`) minimising `Σ |dst_i - (s R src_i + t)|²`. `None` when fewer than 2 pairs, the
/// lengths differ, or `src` has no spread.
#[must_use]
pub fn umeyama(src: &[Vector3<f64>], dst: &[Vector3<f64>], with_scale: bool) -> Option<Sim3> {
    let n = src.len();
    if n < 2 || dst.len() != n {
        return None;
    }
    let nf = n as f64;
    let mu_src = src.iter().sum::<Vector3<f64>>() / nf;
    let mu_dst = dst.iter().sum::<Vector3<f64>>() / nf;
    let mut sigma_src_sq = 0.0;
    let mut cov = Matrix3::zeros();
    for (s, d) in src.iter().zip(dst) {
        let (sc, dc) = (s - mu_src, d - mu_dst);
        sigma_src_sq += sc.norm_squared();
        cov += dc * sc.transpose();
    }
    sigma_src_sq /= nf;
    cov /= nf;
    if sigma_src_sq.is_nan() || sigma_src_sq <= 1e-300 || !cov.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s_diag = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        s_diag.z = -1.0;
    }
    let r = u * Matrix3::from_diagonal(&s_diag) * v_t;
    let scale = if with_scale {
        svd.singular_values.dot(&s_diag) / sigma_src_sq
    } else {
        1.0
    };
    let rotation = Rotation3::from_matrix_unchecked(r);
    let translation = mu_dst - scale * (rotation * mu_src);
    Some(Sim3 {
        rotation,
        translation,
        scale,
    })
}

/// Absolute trajectory error after alignment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AteResult {
    /// Root mean square position error, metres.
    pub rmse_m: f64,
    /// Mean position error, metres.
    pub mean_m: f64,
    /// Median position error, metres.
    pub median_m: f64,
    /// Largest position error, metres.
    pub max_m: f64,
    /// Number of poses compared.
    pub poses: usize,
    /// The alignment applied to the estimate.
    pub alignment: Sim3,
}

/// ATE of `est` against `gt` (same length, frame `i` matching frame `i`) after an SE(3)
/// (`with_scale = false`) or Sim(3) Umeyama alignment of the positions. `None` when the
/// alignment is degenerate (fewer than 2 poses or an estimate that does not move).
#[must_use]
pub fn ate(gt: &[PoseMatrix], est: &[PoseMatrix], with_scale: bool) -> Option<AteResult> {
    let n = gt.len().min(est.len());
    let position = |m: &PoseMatrix| -> Vector3<f64> { m.fixed_view::<3, 1>(0, 3).into_owned() };
    let p_gt: Vec<Vector3<f64>> = gt[..n].iter().map(position).collect();
    let p_est: Vec<Vector3<f64>> = est[..n].iter().map(position).collect();
    let alignment = umeyama(&p_est, &p_gt, with_scale)?;
    let mut errs: Vec<f64> = p_est
        .iter()
        .zip(&p_gt)
        .map(|(e, g)| (alignment.apply(e) - g).norm())
        .collect();
    let nf = n as f64;
    let rmse_m = (errs.iter().map(|e| e * e).sum::<f64>() / nf).sqrt();
    let mean_m = errs.iter().sum::<f64>() / nf;
    let max_m = errs.iter().copied().fold(0.0, f64::max);
    errs.sort_by(f64::total_cmp);
    let median_m = if n % 2 == 1 {
        errs[n / 2]
    } else {
        0.5 * (errs[n / 2 - 1] + errs[n / 2])
    };
    Some(AteResult {
        rmse_m,
        mean_m,
        median_m,
        max_m,
        poses: n,
        alignment,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use rand::{Rng, SeedableRng};
    use visnav_core::se3::se3_exp;

    #[test]
    fn umeyama_recovers_a_known_similarity() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let truth = Sim3 {
            rotation: Rotation3::from_scaled_axis(Vector3::new(0.3, -1.1, 0.7)),
            translation: Vector3::new(4.0, -2.0, 10.0),
            scale: 2.5,
        };
        let src: Vec<Vector3<f64>> = (0..50)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-5.0..5.0),
                    rng.random_range(-5.0..5.0),
                    rng.random_range(0.0..30.0),
                )
            })
            .collect();
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| truth.apply(p)).collect();
        let got = umeyama(&src, &dst, true).unwrap();
        assert!((got.scale - 2.5).abs() < 1e-10, "{}", got.scale);
        assert!(
            (got.rotation.matrix() - truth.rotation.matrix())
                .abs()
                .max()
                < 1e-10
        );
        assert!((got.translation - truth.translation).norm() < 1e-9);
        let rigid = umeyama(&src, &dst, false).unwrap();
        assert_eq!(rigid.scale, 1.0);
        // a reflection in the data must still give a proper rotation
        let mirrored: Vec<Vector3<f64>> =
            src.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let r = umeyama(&src, &mirrored, false).unwrap();
        assert!((r.rotation.matrix().determinant() - 1.0).abs() < 1e-9);
        assert!(umeyama(&src[..1], &dst[..1], true).is_none());
        let still = vec![Vector3::new(1.0, 2.0, 3.0); 5];
        assert!(umeyama(&still, &dst[..5], true).is_none());
    }

    proptest::proptest! {
        #[test]
        fn umeyama_recovers_any_similarity(
            axis in proptest::array::uniform3(-3.0f64..3.0),
            t in proptest::array::uniform3(-100.0f64..100.0),
            scale in 0.01f64..100.0,
            seed in 0u64..1000,
        ) {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let truth = Sim3 {
                rotation: Rotation3::from_scaled_axis(Vector3::from(axis)),
                translation: Vector3::from(t),
                scale,
            };
            let src: Vec<Vector3<f64>> = (0..10)
                .map(|_| Vector3::new(rng.random_range(-10.0..10.0), rng.random_range(-10.0..10.0), rng.random_range(-10.0..10.0)))
                .collect();
            let dst: Vec<Vector3<f64>> = src.iter().map(|p| truth.apply(p)).collect();
            let got = umeyama(&src, &dst, true).unwrap();
            proptest::prop_assert!((got.scale - scale).abs() < 1e-8 * scale);
            for (s, d) in src.iter().zip(&dst) {
                proptest::prop_assert!((got.apply(s) - d).norm() < 1e-7 * (1.0 + d.norm()));
            }
        }
    }

    #[test]
    fn ate_is_zero_after_alignment_of_a_transformed_copy() {
        let gt: Vec<Pose> = (0..40)
            .map(|i| {
                let f = f64::from(i);
                se3_exp(&Vector6::new(
                    0.3 * f,
                    0.01 * f * f,
                    1.5 * f,
                    0.0,
                    0.05 * f,
                    0.0,
                ))
            })
            .collect();
        let s = Sim3 {
            rotation: Rotation3::from_scaled_axis(Vector3::new(0.0, 0.4, 0.1)),
            translation: Vector3::new(1.0, 2.0, 3.0),
            scale: 0.3,
        };
        let est: Vec<Pose> = gt.iter().map(|p| s.apply_pose(p)).collect();
        let gt = crate::pose_matrices(&gt);
        let est = crate::pose_matrices(&est);
        let sim = ate(&gt, &est, true).unwrap();
        assert!(sim.rmse_m < 1e-9, "{}", sim.rmse_m);
        assert!((sim.alignment.scale - 1.0 / 0.3).abs() < 1e-9);
        let se = ate(&gt, &est, false).unwrap();
        assert!(se.rmse_m > 1.0);
        assert!(se.median_m <= se.max_m && se.mean_m <= se.rmse_m + 1e-12);
    }
}
