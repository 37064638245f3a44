//! Relative pose from the fundamental matrix: `E = Kᵀ F K` (one camera), the four `(R, t)`
//! factorisations of `E` (Hartley & Zisserman, result 9.19) and cheirality by triangulation.

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use visnav_core::{PinholeCamera, Pose};

use crate::correspondence::Correspondence;
use crate::triangulation::in_front_of_both;

/// `E = Kᵀ F K`.
#[must_use]
pub fn essential_from_fundamental(f: &Matrix3<f64>, camera: &PinholeCamera) -> Matrix3<f64> {
    let k = camera.k();
    k.transpose() * f * k
}

/// The four candidate poses `cam2_from_cam1 = (R, t)` with `‖t‖ = 1` of an essential matrix:
/// `R ∈ {U W Vᵀ, U Wᵀ Vᵀ}`, `t = ±u₃`. `None` if the SVD fails.
#[must_use]
pub fn decompose_essential(e: &Matrix3<f64>) -> Option<[Pose; 4]> {
    let svd = e.svd(true, true);
    let (Some(mut u), Some(mut v_t)) = (svd.u, svd.v_t) else {
        return None;
    };
    if u.determinant() < 0.0 {
        u = -u;
    }
    if v_t.determinant() < 0.0 {
        v_t = -v_t;
    }
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let r1 = Rotation3::from_matrix_unchecked(u * w * v_t);
    let r2 = Rotation3::from_matrix_unchecked(u * w.transpose() * v_t);
    let t: Vector3<f64> = u.column(2).into_owned();
    let make = |r: &Rotation3<f64>, t: Vector3<f64>| {
        Pose::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_rotation_matrix(r),
        )
    };
    Some([make(&r1, t), make(&r1, -t), make(&r2, t), make(&r2, -t)])
}

/// A relative pose recovered from `F`.
#[derive(Debug, Clone, PartialEq)]
pub struct RelativePose {
    /// `cam2_from_cam1` with unit-norm translation.
    pub cam2_from_cam1: Pose,
    /// Correspondences triangulated in front of both cameras with this candidate.
    pub points_in_front: usize,
    /// The same count for each of the four candidates (diagnostics).
    pub candidate_counts: [usize; 4],
}

/// Decomposes `E = Kᵀ F K` and keeps the candidate with the most correspondences in front of
/// both cameras. `None` if no candidate has any point in front.
#[must_use]
pub fn relative_pose_from_fundamental(
    f: &Matrix3<f64>,
    camera: &PinholeCamera,
    data: &[&Correspondence],
) -> Option<RelativePose> {
    let e = essential_from_fundamental(f, camera);
    let candidates = decompose_essential(&e)?;
    let rays: Vec<(Vector3<f64>, Vector3<f64>)> = data
        .iter()
        .map(|c| (camera.ray(&c.p1_px), camera.ray(&c.p2_px)))
        .collect();
    let mut counts = [0usize; 4];
    for (count, pose) in counts.iter_mut().zip(&candidates) {
        *count = rays
            .iter()
            .filter(|(r1, r2)| in_front_of_both(r1, r2, pose))
            .count();
    }
    let (best, &n) = counts.iter().enumerate().max_by_key(|(_, c)| **c)?;
    (n > 0).then(|| RelativePose {
        cam2_from_cam1: candidates[best],
        points_in_front: n,
        candidate_counts: counts,
    })
}
