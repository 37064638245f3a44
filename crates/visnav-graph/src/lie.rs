//! SE(3) Jacobians for the pose-graph residual, tangent order `(v, ω)`.
//!
//! Perturbations are on the right: `X ← X · Exp(δ)`. With `E = Z⁻¹ X_i⁻¹ X_j` and `e = Log(E)`:
//! * `∂e/∂δ_j = J_r⁻¹(e)`,
//! * `∂e/∂δ_i = −J_r⁻¹(e) · Ad(X_j⁻¹ X_i)`,
//!
//! where `J_r(ξ) = J_l(−ξ)` and the SE(3) left Jacobian is `J_l = [[J, Q], [0, J]]`
//! (Barfoot, "State Estimation for Robotics", eq. 7.85–7.86), `J` the SO(3) left Jacobian.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use visnav_core::Pose;
use visnav_core::se3::{skew, so3_left_jacobian_inv};

/// The adjoint of `T = (R, t)` in the `(v, ω)` order: `[[R, [t]x R], [0, R]]`, so that
/// `T · Exp(δ) · T⁻¹ = Exp(Ad(T) δ)`.
#[must_use]
pub fn adjoint(pose: &Pose) -> Matrix6<f64> {
    let r = *pose.rotation.to_rotation_matrix().matrix();
    let t = pose.translation.vector;
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew(&t) * r));
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// Barfoot's `Q(ρ, φ)` block of the SE(3) left Jacobian (eq. 7.86), with Taylor series for small
/// angles.
#[must_use]
fn q_block(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let (c1, c2, c3) = if theta2 < 1e-2 {
        let t4 = theta2 * theta2;
        (
            1.0 / 6.0 - theta2 / 120.0 + t4 / 5040.0,
            1.0 / 24.0 - theta2 / 720.0 + t4 / 40320.0,
            1.0 / 120.0 - theta2 / 2520.0 + t4 / 120_960.0,
        )
    } else {
        let theta = theta2.sqrt();
        let (s, c) = theta.sin_cos();
        let t3 = theta2 * theta;
        let t4 = theta2 * theta2;
        (
            (theta - s) / t3,
            (theta2 + 2.0 * c - 2.0) / (2.0 * t4),
            (2.0 * theta - 3.0 * s + theta * c) / (2.0 * t4 * theta),
        )
    };
    let p = skew(rho);
    let w = skew(phi);
    let wp = w * p;
    let pw = p * w;
    let wpw = wp * w;
    let ww = w * w;
    0.5 * p + c1 * (wp + pw + wpw) + c2 * (ww * p + pw * w - 3.0 * wpw) + c3 * (wpw * w + w * wpw)
}

/// Inverse of the SE(3) left Jacobian, `J_l⁻¹(ξ) = [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]]`.
#[must_use]
pub fn se3_left_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let rho = xi.fixed_rows::<3>(0).into_owned();
    let phi = xi.fixed_rows::<3>(3).into_owned();
    let j_inv = so3_left_jacobian_inv(&phi);
    let q = q_block(&rho, &phi);
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&j_inv);
    out.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-(j_inv * q * j_inv)));
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&j_inv);
    out
}

/// Inverse of the SE(3) right Jacobian, `J_r⁻¹(ξ) = J_l⁻¹(−ξ)`.
#[must_use]
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian_inv(&(-xi))
}

/// Residual `e = Log(Z⁻¹ X_i⁻¹ X_j)` and its Jacobians `(∂e/∂δ_i, ∂e/∂δ_j)` for right
/// perturbations.
#[must_use]
pub fn residual_and_jacobians(
    from_from_to: &Pose,
    world_from_i: &Pose,
    world_from_j: &Pose,
) -> (Vector6<f64>, Matrix6<f64>, Matrix6<f64>) {
    let i_from_j = world_from_i.inverse() * world_from_j;
    let e = visnav_core::se3::se3_log(&(from_from_to.inverse() * i_from_j));
    let jr_inv = se3_right_jacobian_inv(&e);
    let jac_i = -(jr_inv * adjoint(&i_from_j.inverse()));
    (e, jac_i, jr_inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::se3::{se3_exp, se3_log};

    fn numeric_jacobians(z: &Pose, xi: &Pose, xj: &Pose) -> (Matrix6<f64>, Matrix6<f64>) {
        let h = 1e-6;
        let mut ji = Matrix6::zeros();
        let mut jj = Matrix6::zeros();
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let res = |a: &Pose, b: &Pose| se3_log(&(z.inverse() * a.inverse() * b));
            let col_i = (res(&(xi * se3_exp(&d)), xj) - res(&(xi * se3_exp(&-d)), xj)) / (2.0 * h);
            let col_j = (res(xi, &(xj * se3_exp(&d))) - res(xi, &(xj * se3_exp(&-d)))) / (2.0 * h);
            ji.set_column(k, &col_i);
            jj.set_column(k, &col_j);
        }
        (ji, jj)
    }

    #[test]
    fn analytic_jacobians_match_finite_differences() {
        let cases = [
            (
                Vector6::new(0.3, -0.2, 0.5, 0.1, -0.4, 0.2),
                Vector6::new(1.0, 2.0, -0.5, 0.7, 0.2, -0.3),
                Vector6::new(0.2, 0.1, 0.0, -0.05, 0.1, 0.02),
            ),
            // large residual (about 2 rad)
            (
                Vector6::new(-1.0, 0.5, 2.0, 1.2, 0.4, -0.8),
                Vector6::new(0.5, -1.5, 0.3, -0.6, 0.9, 0.4),
                Vector6::new(2.0, -1.0, 0.5, 0.3, 1.5, -1.0),
            ),
            // tiny residual (series branch)
            (
                Vector6::new(0.1, 0.2, 0.3, 0.01, 0.02, 0.03),
                Vector6::new(0.1, 0.2, 0.3, 0.01, 0.02, 0.031),
                Vector6::zeros(),
            ),
        ];
        for (a, b, noise) in cases {
            let xi = se3_exp(&a);
            let xj = se3_exp(&b);
            let z = xi.inverse() * xj * se3_exp(&noise);
            let (_, ji, jj) = residual_and_jacobians(&z, &xi, &xj);
            let (ni, nj) = numeric_jacobians(&z, &xi, &xj);
            assert!((ji - ni).amax() < 1e-6, "J_i {ji} vs {ni}");
            assert!((jj - nj).amax() < 1e-6, "J_j {jj} vs {nj}");
        }
    }

    #[test]
    fn left_jacobian_inverse_matches_exp_perturbation() {
        // Exp(ξ + δ) ≈ Exp(J_l δ) Exp(ξ)  ⇒  Log(Exp(ε) Exp(ξ)) ≈ ξ + J_l⁻¹ ε.
        for xi in [
            Vector6::new(0.4, -1.0, 0.3, 0.9, -0.2, 0.5),
            Vector6::new(0.4, -1.0, 0.3, 1e-3, -2e-3, 5e-4),
        ] {
            let jinv = se3_left_jacobian_inv(&xi);
            let h = 1e-6;
            for k in 0..6 {
                let mut d = Vector6::zeros();
                d[k] = h;
                let plus = se3_log(&(se3_exp(&d) * se3_exp(&xi)));
                let minus = se3_log(&(se3_exp(&-d) * se3_exp(&xi)));
                let col = (plus - minus) / (2.0 * h);
                assert!(
                    (col - jinv.column(k)).amax() < 1e-6,
                    "{col} vs {}",
                    jinv.column(k)
                );
            }
        }
    }

    #[test]
    fn adjoint_moves_perturbations() {
        let t = se3_exp(&Vector6::new(1.0, -2.0, 0.5, 0.3, 0.2, -0.1));
        let d = Vector6::new(0.01, 0.02, -0.03, 0.02, -0.01, 0.015);
        let lhs = t * se3_exp(&d) * t.inverse();
        let rhs = se3_exp(&(adjoint(&t) * d));
        assert!((lhs.to_homogeneous() - rhs.to_homogeneous()).amax() < 1e-12);
    }
}
