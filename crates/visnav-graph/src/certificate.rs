//! SE-Sync's dual certificate of global optimality (Rosen, Carlone, Bandeira and Leonard, IJRR
//! 2019, §4; the extended report arXiv:1612.07386 numbers the multiplier formula eq. 119).
//!
//! **The problem certified** is SE-Sync's maximum-likelihood estimation (Problem 1), the
//! objective `f` of [`crate::sesync`] with the isotropic weights `τ`, `κ` of each edge. Written
//! with one `3 x 4` block `Y_i = [t_i | R_i]` per vertex, `f = tr(Y M Yᵀ)` for the sparse
//! symmetric data matrix `M` (`4n x 4n`, the "explicit" formulation with the translations kept):
//! an edge `i → j` with measurement `(R̃, t̃)` adds, with `u = (1, 0, 0, 0)ᵀ`, `v = (1, t̃)ᵀ`,
//! `P = [0; I₃]` and `P̃ = [0; R̃]` (`4 x 3`),
//!
//! `M_jj += τ u uᵀ + κ P Pᵀ`, `M_ii += τ v vᵀ + κ P̃ P̃ᵀ`, `M_ij += −τ v uᵀ − κ P̃ Pᵀ`.
//!
//! **The certificate.** At a first-order critical point `Y` of `f` on `(R³ × SO(3))ⁿ` the
//! Lagrange multipliers of the constraints `R_iᵀ R_i = I` are `Λ_i = Sym(R_iᵀ (Y M)_{i,R})`
//! (the rotation columns of block `i` of `Y M`; the translation columns are zero), and
//! `f(Y) = Σ tr Λ_i`. With `Λ̄ = blockdiag(diag(0, Λ_i))` the certificate matrix is
//! `S = M − Λ̄`. For any feasible `Y'`, `f(Y') = tr(Y' S Y'ᵀ) + Σ tr Λ_i`, so when `S ⪰ 0`
//! no feasible point has a lower `f`: `Y` is a global minimum (the semidefinite relaxation is
//! exact). At a critical point `S Yᵀ = 0` and `S` annihilates the common translation
//! `(1, 0, 0, 0, 1, 0, 0, 0, …)`: its smallest eigenvalues are 0 when `Y` is optimal and one is
//! clearly negative when it is not. As SE-Sync does, `S` is accepted as positive semidefinite
//! when `λ_min(S) ≥ −ε`; here `ε` is relative to the scale of `M` (the largest diagonal entry),
//! so that a graph whose information is in other units gets the same verdict.
//!
//! **Computing it.** The solver's optimum minimises the SE(3) objective `χ²` with each edge's
//! full information matrix — another function than `f` — so [`certify`] first refines it to a
//! critical point of `f` (a Newton–Levenberg–Marquardt, module `refine`; a few iterations from the `χ²` optimum), then
//!
//! 1. factorises `S + ε I` with the sparse Cholesky used by the solver (same pattern as the
//!    graph, `4 x 4` blocks): it exists exactly when `λ_min(S) > −ε`, which is the verdict;
//! 2. estimates `λ_min` by inverse iteration with that factor (the "shifted power iteration":
//!    `x ← (S − σ I)⁻¹ x`, then the Rayleigh quotient `xᵀ S x`), where `σ` is `−ε` when the
//!    factorisation succeeded, else the first of `−2ε, −4ε, …` for which it does.
//!
//! Why inverse iteration and not power iteration or Lanczos on `S` itself: the smallest
//! eigenvalues of `S` sit in a cluster at 0 (four exact zeros at an optimum: the three rows of
//! `Y` and the common translation), next to the small eigenvalues of the graph's Laplacian, while
//! the largest is of the order of the largest diagonal entry. Power iteration on `c I − S` shrinks
//! the unwanted components by `1 − gap/spread` a step and Lanczos by about its square root — for a
//! gap many orders below the spread, hundreds to thousands of sparse products, and no proof of
//! positivity at the end (a Ritz value only bounds `λ_min` from above). With the shift `σ` just
//! below `λ_min` (`σ = −ε`, ε = 1e-7 of the scale), each inverse iteration divides the unwanted
//! components by `(λ₂ − σ)/(λ_min − σ)`, so a few steps converge into the cluster, each costing one
//! pair of sparse triangular solves; and the factorisation itself is the proof that
//! `S + εI ≻ 0` (sphere2500: 10,000 unknowns, the whole certificate after the refinement about
//! 0.1 s). The Rayleigh quotient is never below `λ_min`: an estimate below `−ε` proves that the
//! point is not optimal.

use std::time::Instant;

use nalgebra::{Matrix3, Matrix4, Matrix4x3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use visnav_core::Pose;

use crate::error::GraphError;
use crate::graph::{PoseGraph, Vertex};
use crate::init::Layout;
use crate::refine::refine;
use crate::sesync::SeSyncWeights;
use crate::sparse::BlockSystem;

/// Settings of [`certify`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CertifyConfig {
    /// `ε` of the test `λ_min(S) ≥ −ε`, relative to the largest diagonal entry of the data
    /// matrix `M`. Default 1e-7: the refined optima of sphere2500 and parking-garage have
    /// `|λ_min|` below 1e-11 of that scale, the local minima of the tests below −1e-3 of it
    /// (`docs/benchmarks.md`). SE-Sync's default is an absolute 1e-6 on its own scale.
    pub relative_tolerance: f64,
    /// Maximum Levenberg–Marquardt iterations of the refinement to a critical point of `f`.
    /// Default 100.
    pub max_refinement_iterations: usize,
    /// The refinement stops when a step changes `f` by less than this fraction. Default 1e-10
    /// (sphere2500: three Newton steps from the `χ²` optimum change `f` by 2.5 %, 1e-7, then
    /// 7e-11; the next is at the rounding level of the sum).
    pub refinement_tolerance: f64,
    /// Inverse iterations for the estimate of `λ_min`. Default 20.
    pub inverse_iterations: usize,
}

impl Default for CertifyConfig {
    fn default() -> Self {
        Self {
            relative_tolerance: 1e-7,
            max_refinement_iterations: 100,
            refinement_tolerance: 1e-10,
            inverse_iterations: 20,
        }
    }
}

impl CertifyConfig {
    /// Checks the fields.
    ///
    /// # Errors
    /// [`GraphError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), GraphError> {
        for (field, v) in [
            ("certify.relative_tolerance", self.relative_tolerance),
            ("certify.refinement_tolerance", self.refinement_tolerance),
        ] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err(GraphError::InvalidConfig {
                    field,
                    message: format!("must be in (0, 1), got {v}"),
                });
            }
        }
        if self.inverse_iterations == 0 {
            return Err(GraphError::InvalidConfig {
                field: "certify.inverse_iterations",
                message: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// The verdict of the certificate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// `λ_min(S) ≥ −ε`: the refined poses are a global minimum of SE-Sync's problem.
    GloballyOptimal,
    /// `λ_min(S) < −ε`: a local minimum or saddle, not certified.
    NotCertified,
}

/// The result of [`certify`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Certificate {
    /// The verdict.
    pub verdict: Verdict,
    /// Estimate of the smallest eigenvalue of `S` (a Rayleigh quotient: never below the true
    /// one).
    pub lambda_min: f64,
    /// The tolerance `ε` (absolute, in the units of `M`).
    pub tolerance: f64,
    /// The scale of `M` (its largest diagonal entry) that `ε` is relative to.
    pub scale: f64,
    /// SE-Sync's objective `f` at the poses given to [`certify`].
    pub objective_at_input: f64,
    /// `f` at the refined critical point (the certified optimum when globally optimal).
    pub objective: f64,
    /// `Σ tr Λ_i`: a lower bound on every feasible `f` when `S ⪰ 0` (equal to `objective` at
    /// an exact critical point).
    pub dual_bound: f64,
    /// Levenberg–Marquardt iterations of the refinement.
    pub refinement_iterations: usize,
    /// Whether the refinement converged (else it stopped at its iteration limit, and the point
    /// may not be critical: a negative `λ_min` then proves nothing about the optimum).
    pub refinement_converged: bool,
    /// Edges in the certified problem.
    pub edges: usize,
    /// Wall-clock time of the whole certification, milliseconds.
    pub time_ms: f64,
    /// The refined `world_from_vertex` of each vertex (a critical point of `f`).
    #[serde(skip)]
    pub poses: Vec<Pose>,
}

/// The certified sub-problem: the kept edges, their weights, one vertex held for the gauge.
struct Problem {
    graph: PoseGraph,
    weights: Vec<SeSyncWeights>,
}

impl Problem {
    /// The kept edges of `graph` with SE-Sync's weights; every vertex free except the first
    /// fixed one (SE-Sync fixes only the gauge; `f` is invariant to a common rigid motion, so
    /// holding one vertex loses no optimum).
    fn new(graph: &PoseGraph, keep: &[bool]) -> Result<Self, GraphError> {
        let anchor = graph.vertices.iter().position(|v| v.fixed).unwrap_or(0);
        let vertices = graph
            .vertices
            .iter()
            .enumerate()
            .map(|(k, v)| Vertex {
                fixed: k == anchor,
                ..v.clone()
            })
            .collect();
        let mut edges = Vec::new();
        let mut weights = Vec::new();
        for (k, e) in graph.edges.iter().enumerate() {
            if !keep.get(k).copied().unwrap_or(false) {
                continue;
            }
            let w = crate::sesync::sesync_weights(&e.information).ok_or_else(|| {
                GraphError::NoSeSyncWeights {
                    edge: k,
                    from_id: graph.vertices[e.from].id,
                    to_id: graph.vertices[e.to].id,
                }
            })?;
            edges.push(e.clone());
            weights.push(w);
        }
        Ok(Self {
            graph: PoseGraph { vertices, edges },
            weights,
        })
    }

    /// The data matrix `M` (module doc) in a block system of `4 x 4` blocks over all vertices.
    fn data_matrix(&self) -> Result<BlockSystem<4>, GraphError> {
        let pairs: Vec<(usize, usize)> = self.graph.edges.iter().map(|e| (e.from, e.to)).collect();
        let mut m = BlockSystem::<4>::new(self.graph.vertices.len(), &pairs)?;
        let p = Matrix4x3::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        let u = Vector4::new(1.0, 0.0, 0.0, 0.0);
        for (e, w) in self.graph.edges.iter().zip(&self.weights) {
            let r = e.from_from_to.rotation.to_rotation_matrix().into_inner();
            let t = e.from_from_to.translation.vector;
            let v = Vector4::new(1.0, t.x, t.y, t.z);
            let p_meas = p * r;
            let m_jj: Matrix4<f64> = u * u.transpose() * w.tau + p * p.transpose() * w.kappa;
            let m_ii: Matrix4<f64> =
                v * v.transpose() * w.tau + p_meas * p_meas.transpose() * w.kappa;
            let m_ij: Matrix4<f64> =
                -(v * u.transpose() * w.tau + p_meas * p.transpose() * w.kappa);
            for (a, b, block) in [
                (e.to, e.to, m_jj),
                (e.from, e.from, m_ii),
                (e.from, e.to, m_ij),
            ] {
                if let Some(slot) = m.slot(a, b) {
                    m.add(slot, a, b, &block);
                }
            }
        }
        Ok(m)
    }
}

/// `Y` as a `3 x 4n` row-major set of three `4n` vectors (rows of `Y`).
fn stack_rows(poses: &[Pose]) -> [Vec<f64>; 3] {
    let mut rows = [
        vec![0.0; 4 * poses.len()],
        vec![0.0; 4 * poses.len()],
        vec![0.0; 4 * poses.len()],
    ];
    for (i, pose) in poses.iter().enumerate() {
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let t = pose.translation.vector;
        for (row, values) in rows.iter_mut().enumerate() {
            values[4 * i] = t[row];
            for c in 0..3 {
                values[4 * i + 1 + c] = r[(row, c)];
            }
        }
    }
    rows
}

/// The multipliers `Λ_i = Sym(R_iᵀ (Y M)_{i,R})` of every vertex.
fn multipliers(m: &BlockSystem<4>, poses: &[Pose]) -> Vec<Matrix3<f64>> {
    let rows = stack_rows(poses);
    let mut ym = [
        vec![0.0; rows[0].len()],
        vec![0.0; rows[0].len()],
        vec![0.0; rows[0].len()],
    ];
    for (row, out) in rows.iter().zip(ym.iter_mut()) {
        m.multiply(row, out);
    }
    poses
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let r = pose.rotation.to_rotation_matrix().into_inner();
            let g = Matrix3::from_fn(|row, c| ym[row][4 * i + 1 + c]);
            let l = r.transpose() * g;
            (l + l.transpose()) * 0.5
        })
        .collect()
}

/// Adds `−Λ̄` to `M` (making it `S`).
fn subtract_multipliers(s: &mut BlockSystem<4>, lambda: &[Matrix3<f64>]) {
    for (i, l) in lambda.iter().enumerate() {
        let mut block = Matrix4::zeros();
        block.fixed_view_mut::<3, 3>(1, 1).copy_from(&(-l));
        if let Some(slot) = s.slot(i, i) {
            s.add(slot, i, i, &block);
        }
    }
}

/// The smallest eigenvalue of `S` (module doc): `(λ_min estimate, whether S + εI ≻ 0)`.
fn smallest_eigenvalue(
    s: &mut BlockSystem<4>,
    epsilon: f64,
    iterations: usize,
    start: &[f64],
) -> (f64, bool) {
    let n = start.len();
    let mut shift = epsilon;
    let mut positive = false;
    // σ = −shift; S − σI = S + shift I.
    for attempt in 0..64 {
        s.add_to_diagonal(&vec![shift; n]);
        let ok = s.factorise();
        s.add_to_diagonal(&vec![-shift; n]);
        if ok {
            positive = attempt == 0;
            break;
        }
        shift *= 2.0;
        if !shift.is_finite() {
            return (f64::NEG_INFINITY, false);
        }
    }
    let mut x = start.to_vec();
    let mut y = vec![0.0; n];
    let mut estimate = f64::NAN;
    for _ in 0..iterations {
        let length = norm(&x);
        if !(length.is_finite() && length > 0.0) {
            break;
        }
        x.iter_mut().for_each(|v| *v /= length);
        s.multiply(&x, &mut y);
        estimate = x.iter().zip(&y).map(|(a, b)| a * b).sum();
        s.solve_factored(&mut x);
    }
    (estimate, positive)
}

/// Certifies `poses` (one per vertex) for SE-Sync's problem over the edges selected by `keep`
/// (module doc): refines them to a critical point of `f`, builds `S = M − Λ̄` there and tests
/// `λ_min(S) ≥ −ε`.
///
/// # Errors
/// [`GraphError::InvalidConfig`] for a field out of range, [`GraphError::NoSeSyncWeights`]
/// for a kept edge whose information has no SE-Sync weights, [`GraphError::Disconnected`]
/// when the kept edges do not connect the graph, [`GraphError::Factorisation`] when the sparse
/// pattern cannot be analysed.
pub fn certify(
    graph: &PoseGraph,
    poses: &[Pose],
    keep: &[bool],
    config: &CertifyConfig,
) -> Result<Certificate, GraphError> {
    config.validate()?;
    let start = Instant::now();
    let problem = Problem::new(graph, keep)?;
    let layout = Layout::new(&problem.graph)?;
    let objective_at_input = problem
        .graph
        .sesync_objective(poses, None)
        .unwrap_or(f64::NAN);
    let refined = refine(
        &problem.graph,
        &problem.weights,
        &layout,
        poses,
        config.max_refinement_iterations,
        config.refinement_tolerance,
    )?;
    let mut s = problem.data_matrix()?;
    let scale = s.diagonal().into_iter().fold(0.0, f64::max);
    let lambda = multipliers(&s, &refined.poses);
    let dual_bound = lambda.iter().map(Matrix3::trace).sum();
    subtract_multipliers(&mut s, &lambda);
    let tolerance = config.relative_tolerance * scale;
    // Start near the null space of S at an optimum (the first row of Y), perturbed by about
    // 3 % so that a negative direction, if any, is not missed (as SE-Sync starts its Lanczos
    // iterations); seeded, so that the estimate is reproducible.
    let mut x = stack_rows(&refined.poses)[0].clone();
    let mut rng = ChaCha8Rng::seed_from_u64(0x5e5c);
    let noise: Vec<f64> = x.iter().map(|_| rng.random::<f64>() - 0.5).collect();
    let ratio = 0.03 * norm(&x) / norm(&noise).max(f64::MIN_POSITIVE);
    for (v, p) in x.iter_mut().zip(&noise) {
        *v += ratio * p;
    }
    let (lambda_min, positive) =
        smallest_eigenvalue(&mut s, tolerance, config.inverse_iterations, &x);
    Ok(Certificate {
        verdict: if positive {
            Verdict::GloballyOptimal
        } else {
            Verdict::NotCertified
        },
        lambda_min,
        tolerance,
        scale,
        objective_at_input,
        objective: refined.objective,
        dual_bound,
        refinement_iterations: refined.iterations,
        refinement_converged: refined.converged,
        edges: problem.graph.edges.len(),
        time_ms: start.elapsed().as_secs_f64() * 1e3,
        poses: refined.poses,
    })
}

/// The Euclidean norm.
fn norm(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{LoopDriveConfig, loop_drive};
    use nalgebra::Vector6;
    use visnav_core::se3::se3_exp;

    /// `f = tr(Y M Yᵀ)`: the data matrix reproduces SE-Sync's objective computed edge by edge,
    /// at poses away from any optimum.
    #[test]
    fn the_data_matrix_reproduces_the_objective() {
        let graph = loop_drive(&LoopDriveConfig {
            poses_per_lap: 20,
            ..LoopDriveConfig::default()
        })
        .graph;
        let poses: Vec<Pose> = graph
            .poses()
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let a = k as f64;
                p * se3_exp(&Vector6::new(
                    0.1 * a.sin(),
                    0.2 * a.cos(),
                    -0.1,
                    0.05 * a.cos(),
                    0.1,
                    -0.07 * a.sin(),
                ))
            })
            .collect();
        let keep = vec![true; graph.edges.len()];
        let problem = Problem::new(&graph, &keep).unwrap();
        let m = problem.data_matrix().unwrap();
        let rows = stack_rows(&poses);
        let mut y = vec![0.0; rows[0].len()];
        let mut trace = 0.0;
        for row in &rows {
            m.multiply(row, &mut y);
            trace += row.iter().zip(&y).map(|(a, b)| a * b).sum::<f64>();
        }
        let f = graph.sesync_objective(&poses, None).unwrap();
        assert!((trace - f).abs() <= 1e-9 * f, "{trace} vs {f}");
        // the common translation is in the null space of M
        let ones: Vec<f64> = (0..rows[0].len())
            .map(|k| if k % 4 == 0 { 1.0 } else { 0.0 })
            .collect();
        m.multiply(&ones, &mut y);
        assert!(norm(&y) < 1e-9 * m.diagonal().iter().fold(0.0, |a, b| a + b.abs()));
    }

    #[test]
    fn config_is_validated() {
        assert!(CertifyConfig::default().validate().is_ok());
        let bad = CertifyConfig {
            relative_tolerance: 0.0,
            ..CertifyConfig::default()
        };
        assert!(matches!(
            bad.validate(),
            Err(GraphError::InvalidConfig {
                field: "certify.relative_tolerance",
                ..
            })
        ));
    }
}
