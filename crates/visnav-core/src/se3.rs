//! Rigid motions in 3-D.
//!
//! A [`Pose`] is an `Isometry3<f64>`; by convention a variable named `a_from_b` maps points given in
//! frame `b` into frame `a`, so `world_from_cam * p_in_cam = p_in_world` and
//! `a_from_b * b_from_c = a_from_c`. Tangent vectors are ordered `(translation, rotation)` =
//! `(v, ω)`, and the perturbation convention of the optimisers is documented where they are defined.

use nalgebra::{
    Isometry3, Matrix3, Matrix3x4, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// A rigid motion `a_from_b` (rotation and translation, metres).
pub type Pose = Isometry3<f64>;

/// The skew-symmetric matrix `[v]x` such that `[v]x w = v × w`.
#[must_use]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// SO(3) exponential map: rotation vector (axis · angle, radians) to rotation.
#[must_use]
pub fn so3_exp(omega: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*omega)
}

/// SO(3) logarithm: rotation to rotation vector (axis · angle, radians), angle in [0, π].
#[must_use]
pub fn so3_log(r: &Rotation3<f64>) -> Vector3<f64> {
    r.scaled_axis()
}

/// Left Jacobian of SO(3), `J(ω)`, used by the SE(3) exponential: `t = J(ω) v`.
#[must_use]
pub fn so3_left_jacobian(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = omega.norm_squared();
    let k = skew(omega);
    if theta2 < 1e-10 {
        return Matrix3::identity() + 0.5 * k + k * k / 6.0;
    }
    let theta = theta2.sqrt();
    let a = (1.0 - theta.cos()) / theta2;
    let b = (theta - theta.sin()) / (theta2 * theta);
    Matrix3::identity() + a * k + b * k * k
}

/// Inverse of the left Jacobian of SO(3).
#[must_use]
pub fn so3_left_jacobian_inv(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = omega.norm_squared();
    let k = skew(omega);
    if theta2 < 1e-10 {
        return Matrix3::identity() - 0.5 * k + k * k / 12.0;
    }
    let theta = theta2.sqrt();
    let half = 0.5 * theta;
    let c = (1.0 - half * half.cos() / half.sin()) / theta2;
    Matrix3::identity() - 0.5 * k + c * k * k
}

/// SE(3) exponential map of the twist `ξ = (v, ω)` (translation part first).
#[must_use]
pub fn se3_exp(xi: &Vector6<f64>) -> Pose {
    let v = xi.fixed_rows::<3>(0).into_owned();
    let omega = xi.fixed_rows::<3>(3).into_owned();
    let rot = so3_exp(&omega);
    let t = so3_left_jacobian(&omega) * v;
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// SE(3) logarithm: the twist `ξ = (v, ω)` with `se3_exp(ξ) = pose`.
#[must_use]
pub fn se3_log(pose: &Pose) -> Vector6<f64> {
    let omega = pose.rotation.scaled_axis();
    let v = so3_left_jacobian_inv(&omega) * pose.translation.vector;
    Vector6::new(v.x, v.y, v.z, omega.x, omega.y, omega.z)
}

/// Rotation angle of a pose in radians, computed as the KITTI devkit does
/// (`acos(max(min((trace - 1) / 2, 1), -1))`).
#[must_use]
pub fn rotation_angle(pose: &Pose) -> f64 {
    let r = pose.rotation.to_rotation_matrix();
    let d = 0.5 * (r.matrix().trace() - 1.0);
    d.clamp(-1.0, 1.0).acos()
}

/// Builds a pose from a row-major 3x4 matrix `[R | t]`, projecting `R` onto SO(3)
/// (the nearest rotation in the Frobenius norm) to absorb rounding in text files.
#[must_use]
pub fn pose_from_matrix3x4(m: &Matrix3x4<f64>) -> Pose {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let t = m.column(3).into_owned();
    let rot = project_to_so3(&r);
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// The rotation nearest to `m` in the Frobenius norm (`U diag(1, 1, det(UVᵀ)) Vᵀ` from the SVD).
#[must_use]
pub fn project_to_so3(m: &Matrix3<f64>) -> Rotation3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Rotation3::identity();
    };
    let d = (u * v_t).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    Rotation3::from_matrix_unchecked(r)
}

/// The row-major 3x4 matrix `[R | t]` of a pose.
#[must_use]
pub fn pose_to_matrix3x4(pose: &Pose) -> Matrix3x4<f64> {
    pose.to_homogeneous().fixed_view::<3, 4>(0, 0).into_owned()
}

/// Largest coordinate a trajectory may hold, metres (a million kilometres): beyond it a file is
/// wrong, and squares of its coordinates (1e308 squared is infinite) would turn every score and
/// plot range into inf or NaN.
pub const MAX_COORDINATE_M: f64 = 1e9;

/// Largest deviation of `RᵀR` from the identity accepted for a rotation block: files written
/// with 6 significant digits are orthonormal to about 1e-6, a scaled or sheared block is off by
/// far more than 1e-2.
pub const ROTATION_TOLERANCE: f64 = 1e-2;

/// Checks a `[R | t]` pose: `R` a rotation (orthonormal within [`ROTATION_TOLERANCE`],
/// determinant +1) and `t` within [`MAX_COORDINATE_M`].
///
/// # Errors
/// A message saying what is wrong.
pub fn check_pose_matrix(m: &nalgebra::Matrix3x4<f64>) -> std::result::Result<(), String> {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let off = (r.transpose() * r - nalgebra::Matrix3::identity())
        .abs()
        .max();
    let det = r.determinant();
    // written so that NaN fails both checks
    let rotation = off <= ROTATION_TOLERANCE && det > 0.0;
    if !rotation {
        return Err(format!(
            "the 3x3 block is not a rotation (|RᵀR - I| = {off:.3e}, det = {det:.3e})"
        ));
    }
    check_position(m[(0, 3)], m[(1, 3)], m[(2, 3)])
}

/// Checks that a position is within [`MAX_COORDINATE_M`] of the origin.
///
/// # Errors
/// A message giving the position.
pub fn check_position(x: f64, y: f64, z: f64) -> std::result::Result<(), String> {
    let far = [x, y, z].into_iter().map(f64::abs).fold(0.0, f64::max);
    if far > MAX_COORDINATE_M {
        return Err(format!(
            "position ({x:e}, {y:e}, {z:e}) is more than {MAX_COORDINATE_M:e} m from the origin"
        ));
    }
    Ok(())
}

/// Length of the path through the camera centres of `poses` (sum of the step lengths), metres.
#[must_use]
pub fn path_length_m(poses: &[Pose]) -> f64 {
    poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn se3_exp_log_round_trip(v in prop::array::uniform6(-2.0f64..2.0)) {
            let mut xi = Vector6::from_row_slice(&v);
            // keep the angle below π so that log is unique
            let w = xi.fixed_rows::<3>(3).norm();
            if w > 3.0 { xi.fixed_rows_mut::<3>(3).scale_mut(3.0 / w); }
            let back = se3_log(&se3_exp(&xi));
            prop_assert!((back - xi).norm() < 1e-9, "{back} vs {xi}");
        }

        #[test]
        fn left_jacobian_inverse(v in prop::array::uniform3(-3.0f64..3.0)) {
            let w = Vector3::from_row_slice(&v);
            let prod = so3_left_jacobian(&w) * so3_left_jacobian_inv(&w);
            prop_assert!((prod - Matrix3::identity()).norm() < 1e-9);
        }
    }

    #[test]
    fn matrix_round_trip_and_angle() {
        let xi = Vector6::new(1.0, -2.0, 0.5, 0.1, 0.2, -0.3);
        let p = se3_exp(&xi);
        let q = pose_from_matrix3x4(&pose_to_matrix3x4(&p));
        assert_relative_eq!(p.to_homogeneous(), q.to_homogeneous(), epsilon = 1e-12);
        assert_relative_eq!(
            rotation_angle(&p),
            xi.fixed_rows::<3>(3).norm(),
            epsilon = 1e-12
        );
    }
}
