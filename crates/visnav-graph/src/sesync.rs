//! SE-Sync's objective and isotropic edge weights (Rosen, Carlone, Bandeira and Leonard,
//! "SE-Sync: a certifiably correct algorithm for synchronization over the special Euclidean
//! group", IJRR 2019).
//!
//! SE-Sync models each relative-pose measurement with isotropic noise: a Langevin rotation noise
//! of concentration `κ` and a Gaussian translation noise of precision `τ`. Its maximum
//! likelihood estimate (the paper's Problem 1) minimises
//!
//! `f = Σ_ij κ_ij ‖R_j − R_i R̃_ij‖²_F + τ_ij ‖t_j − t_i − R_i t̃_ij‖²`
//!
//! (no factor ½; `R_i`, `t_i` the rotation and position of `world_from_vertex`, `R̃_ij`,
//! `t̃_ij` the measurement `i_from_j`). For a g2o edge with information `Ω` (translation block
//! `Ω_tt`, rotation block `Ω_rr`), SE-Sync's loader takes the weights whose isotropic
//! distribution is closest to the edge's (in information divergence):
//! `τ = 3 / tr(Ω_tt⁻¹)` and `κ = 3 / (2 tr(Ω_rr⁻¹))`. The published certified optima of the
//! benchmark graphs (sphere2500 f* = 1687.0, parking-garage 1.263) are of this `f`.
//!
//! In the solver's SE(3) objective `χ² = Σ eᵀ Ω e` the same edge is the isotropic information
//! `diag(τ I₃, 2κ I₃)` ([`isotropic_information`]): for a small rotation error of angle `θ`,
//! `κ ‖R − R Exp(θ)‖²_F = 2κ (2 − 2 cos θ) ≈ 2κ θ²`.

use nalgebra::{Matrix3, Matrix6};
use visnav_core::Pose;

use crate::graph::PoseGraph;

/// SE-Sync's isotropic weights of one edge.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeSyncWeights {
    /// Translation precision `τ = 3 / tr(Ω_tt⁻¹)`, 1/m².
    pub tau: f64,
    /// Rotation concentration `κ = 3 / (2 tr(Ω_rr⁻¹))`, 1/rad².
    pub kappa: f64,
}

/// `3 / tr(B⁻¹)` of a 3x3 block: positive and finite only when the inverse exists and has a
/// positive trace.
fn inverse_trace_weight(block: &Matrix3<f64>) -> Option<f64> {
    let sym = (block + block.transpose()) * 0.5;
    let trace = sym.try_inverse()?.trace();
    let w = 3.0 / trace;
    (trace.is_finite() && trace > 0.0 && w.is_finite() && w > 0.0).then_some(w)
}

/// SE-Sync's weights of an edge from its information matrix (ordered translation, rotation):
/// `τ = 3 / tr(Ω_tt⁻¹)`, `κ = 3 / (2 tr(Ω_rr⁻¹))`. `None` when a block has no inverse or the
/// trace of its inverse is not positive (the weight would be infinite or negative).
#[must_use]
pub fn sesync_weights(information: &Matrix6<f64>) -> Option<SeSyncWeights> {
    if !information.iter().all(|v| v.is_finite()) {
        return None;
    }
    let tau = inverse_trace_weight(&information.fixed_view::<3, 3>(0, 0).into_owned())?;
    let kappa = 0.5 * inverse_trace_weight(&information.fixed_view::<3, 3>(3, 3).into_owned())?;
    Some(SeSyncWeights { tau, kappa })
}

/// The information matrix `diag(τ I₃, 2κ I₃)` (translation, rotation) whose SE(3) objective is
/// SE-Sync's to second order; its own [`sesync_weights`] are `τ` and `κ` again.
#[must_use]
pub fn isotropic_information(weights: SeSyncWeights) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    for k in 0..3 {
        m[(k, k)] = weights.tau;
        m[(k + 3, k + 3)] = 2.0 * weights.kappa;
    }
    m
}

/// One edge's term of SE-Sync's objective at the given end poses.
#[must_use]
pub fn sesync_edge_cost(
    weights: SeSyncWeights,
    from_from_to: &Pose,
    world_from_i: &Pose,
    world_from_j: &Pose,
) -> f64 {
    let r_i = world_from_i.rotation.to_rotation_matrix().into_inner();
    let r_j = world_from_j.rotation.to_rotation_matrix().into_inner();
    let r_ij = from_from_to.rotation.to_rotation_matrix().into_inner();
    let dt = world_from_j.translation.vector
        - world_from_i.translation.vector
        - r_i * from_from_to.translation.vector;
    weights.kappa * (r_j - r_i * r_ij).norm_squared() + weights.tau * dt.norm_squared()
}

impl PoseGraph {
    /// SE-Sync's weights of every edge ([`sesync_weights`]); `None` for an edge without.
    #[must_use]
    pub fn sesync_weights(&self) -> Vec<Option<SeSyncWeights>> {
        self.edges
            .iter()
            .map(|e| sesync_weights(&e.information))
            .collect()
    }

    /// SE-Sync's objective `f` (module doc) at `poses` over the edges selected by `keep` (all
    /// when `None`). `None` when a selected edge has no SE-Sync weights.
    #[must_use]
    pub fn sesync_objective(&self, poses: &[Pose], keep: Option<&[bool]>) -> Option<f64> {
        let mut sum = 0.0;
        for (k, e) in self.edges.iter().enumerate() {
            if keep.is_some_and(|keep| !keep.get(k).copied().unwrap_or(false)) {
                continue;
            }
            let w = sesync_weights(&e.information)?;
            sum += sesync_edge_cost(w, &e.from_from_to, &poses[e.from], &poses[e.to]);
        }
        Some(sum)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use visnav_core::se3::se3_exp;

    #[test]
    fn weights_of_an_isotropic_matrix_are_its_own() {
        let w = SeSyncWeights {
            tau: 10.0,
            kappa: 200.0,
        };
        let back = sesync_weights(&isotropic_information(w)).unwrap();
        assert!((back.tau - 10.0).abs() < 1e-12 && (back.kappa - 200.0).abs() < 1e-9);
        // sphere2500's first edge: translation 10 I, rotation block ≈ diag(400, 400, 99.2)
        let mut info = Matrix6::zeros();
        for k in 0..3 {
            info[(k, k)] = 10.0;
        }
        info[(3, 3)] = 400.0;
        info[(4, 4)] = 400.0;
        info[(5, 5)] = 100.0;
        let w = sesync_weights(&info).unwrap();
        assert!((w.tau - 10.0).abs() < 1e-12);
        // 3 / (2 (1/400 + 1/400 + 1/100)) = 100
        assert!((w.kappa - 100.0).abs() < 1e-9, "{}", w.kappa);
        // a singular or negative block has no weight
        info[(0, 0)] = 0.0;
        assert!(sesync_weights(&info).is_none());
        info[(0, 0)] = -50.0;
        info[(1, 1)] = -50.0;
        info[(2, 2)] = -50.0;
        assert!(sesync_weights(&info).is_none());
    }

    #[test]
    fn objective_matches_chi2_of_the_isotropic_matrix_for_small_errors() {
        let w = SeSyncWeights {
            tau: 4.0,
            kappa: 50.0,
        };
        let z = se3_exp(&Vector6::new(1.0, 0.5, -0.2, 0.1, 0.3, -0.2));
        let xi = Pose::identity();
        let err = Vector6::new(1e-3, -2e-3, 5e-4, 2e-4, -1e-4, 3e-4);
        let xj = z * se3_exp(&err);
        let f = sesync_edge_cost(w, &z, &xi, &xj);
        let info = isotropic_information(w);
        // χ² of e = Log(Z⁻¹ X_i⁻¹ X_j) = err; the translation part differs by the rotation of
        // the frame only (isotropic), the rotation part to second order
        let chi2 = err.dot(&(info * err));
        assert!((f - chi2).abs() < 1e-3 * chi2, "{f} vs {chi2}");
        // exact at the measurement
        assert!(sesync_edge_cost(w, &z, &xi, &z) < 1e-20);
    }
}
