//! Pose-graph optimisation: linear initialisation ([`crate::init`]) then Levenberg–Marquardt on
//! SE(3) with analytic Jacobians ([`crate::lie`]) and a sparse Cholesky whose symbolic
//! factorisation is computed once.
//!
//! The objective is the standard one, `χ² = Σ e_ijᵀ Ω_ij e_ij` with `e_ij = Log(Z_ij⁻¹ X_i⁻¹ X_j)`
//! (GTSAM's `BetweenFactor<Pose3>` with the exact SE(3) logarithm; GTSAM reports `½ χ²`). Poses
//! are updated on the right, `X ← X Exp(δ)`; fixed vertices (g2o `FIX`, or the first vertex when
//! none is marked) are held.
//!
//! **Robustness to wrong loop closures.** Edges between consecutive vertex ids are odometry and
//! always trusted; every other edge is a loop closure that may be wrong.
//!
//! * [`RobustKernel::PairwiseConsistency`] (default): (1) the pairwise consistency test of PCM
//!   (Mangelson et al. 2018) restricted to closures linked by short odometry chains
//!   ([`crate::consistency`]) keeps the closures confirmed by another closure; (2) the linear
//!   initialisation and Levenberg–Marquardt solve the standard objective over odometry and those
//!   closures; (3) every closure is re-classified by its whitened residual at that optimum
//!   (`χ²₆` gate, [`GraphConfig::inlier_chi2_pose`]) — isolated genuine closures come in, wrong
//!   closures that happened to be confirmed go out — and the solve is repeated while the
//!   classification changes. When no closure at all is confirmed (e.g. a single loop closure)
//!   it falls back to the GNC mode below.
//! * [`RobustKernel::GncGemanMcClure`]: graduated non-convexity with the Geman–McClure kernel on
//!   the loop closures inside the *linear* initialisation, where each GNC step is one cheap
//!   3-block sparse solve; edges whose GNC weight ends below ½ are set aside, then the same
//!   solve and re-classification as above.
//!
//! Why preselection by consistency: GNC (Yang et al. 2020) starts from the least-squares solution
//! over *all* edges and relies on wrong closures having the largest residuals there. With 30 %
//! wrong closures on sphere2500, half of them claiming "same place" (identity) and consistent in
//! rotation, that start is so bent that GNC ends in the odometry-dominated basin and rejects about
//! 800 genuine closures too (ATE 43 % of the extent, measured). The consistency test does not
//! look at any global solution: a genuine closure is confirmed by its neighbours in a run of
//! closures through a few odometry steps, which random wrong closures almost never have, so the
//! first solve sees (nearly) only genuine closures and its optimum is the clean one. It costs
//! one small cycle composition per closure and removes the wrong edges from the sparse
//! factorisation (with them, the random long edges filled the Cholesky factor: 5.7–11 s at 10 %
//! on sphere2500). Switchable constraints / DCS (Agarwal et al. 2013) were not chosen: they add
//! a variable (or a weight) per closure, their optimum depends on a prior weight `Φ`, and they
//! still start from the bent all-edge solution. A full PCM maximum clique is unnecessary here
//! (and exponential in the worst case); the final `χ²₆` re-classification plays its role of
//! removing the rare wrong closure that found a consistent partner.
//!
//! The result is the optimum of the standard objective over the accepted edges; on a graph
//! without wrong closures it is the plain optimum.

use std::time::Instant;

use nalgebra::{Matrix6, Vector6};
use visnav_core::Pose;
use visnav_core::se3::se3_exp;

use crate::certificate::CertifyConfig;
use crate::consistency::{closure_confirmation, closure_support};
use crate::error::GraphError;
use crate::graph::{Objective, PoseGraph};
use crate::init::{Layout, linear_init, linear_init_over};
use crate::lie::residual_and_jacobians;
use crate::numeric::{NumericProblem, numeric_problem};
use crate::sparse::BlockSystem;

/// Where Levenberg–Marquardt starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Initialisation {
    /// Chordal rotations then linear positions (reference \[17\]'s spirit).
    Chordal,
    /// The vertex poses of the input graph.
    Input,
}

/// Treatment of loop-closure (non-odometry) edges.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RobustKernel {
    /// Plain least squares: every edge is trusted.
    None,
    /// Graduated non-convexity with the Geman–McClure kernel, then outlier rejection.
    GncGemanMcClure,
    /// Pairwise-consistency preselection of loop closures ([`crate::consistency`]), then
    /// Levenberg–Marquardt on odometry and the supported closures, then gated re-admission of
    /// every closure at the optimum. Falls back to [`RobustKernel::GncGemanMcClure`] when no
    /// closure is supported by another.
    PairwiseConsistency,
}

/// Configuration of [`solve`]. Reference \[17\] gives no numeric settings; the defaults below are
/// chi-square quantiles (99.99 %) for the thresholds and standard Levenberg–Marquardt settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraphConfig {
    /// Start of Levenberg–Marquardt. Default: chordal.
    pub initialisation: Initialisation,
    /// Robust treatment of loop closures. Default: pairwise consistency.
    pub robust: RobustKernel,
    /// Maximum Levenberg–Marquardt iterations (each a factorisation). Default 100.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers `χ²` by less than this fraction. Default 1e-7 (GTSAM's
    /// default is 1e-5; 1e-7 leaves the objective within 1e-6 of the optimum on the benchmarks).
    pub relative_tolerance: f64,
    /// Initial damping `λ` (relative to the diagonal of `JᵀΩJ`, Marquardt scaling). Default 1e-5.
    pub initial_lambda: f64,
    /// GNC threshold `c²` on the chordal rotation residual `κ ‖R_j − R_i R_ij‖²_F`
    /// (≈ χ² with 3 degrees of freedom). Default 21.11 (χ²₃ 99.99 %).
    pub inlier_chi2_rotation: f64,
    /// GNC threshold `c²` on the whitened position residual (3 dof). Default 21.11.
    pub inlier_chi2_position: f64,
    /// Threshold on the whitened SE(3) residual `eᵀΩe` (6 dof) above which a loop closure is
    /// rejected at the optimum. Default 27.86 (χ²₆ 99.99 %; at 99 % genuine closures of graphs
    /// with realistic noise, e.g. smallGrid3D, were rejected by the dozen).
    pub inlier_chi2_pose: f64,
    /// Factor by which GNC divides `μ` at each step. Default 1.4 (Yang et al. 2020).
    pub gnc_step: f64,
    /// Maximum re-classification rounds after the first optimum. Default 3.
    pub max_reclassification_rounds: usize,
    /// Pairwise consistency: two loop closures are compared when both their ends are within this
    /// many vertex ids (consecutive poses) of each other. Default 10.
    pub consistency_window: u64,
    /// Pairwise consistency: gate on the whitened cycle error `χ²` (6 dof). Default 27.86
    /// (χ²₆ 99.99 %).
    pub consistency_chi2: f64,
    /// Pairwise mode: the probability that the `χ²` gate at the optimum rejects any of the
    /// closures the pairwise test confirmed, on a graph whose closures are all consistent with
    /// each other. Each such closure of the `m` is tested at the `χ²₆` quantile `1 − p/m`
    /// (family-wise, Bonferroni; at least `inlier_chi2_pose`, which the unconfirmed ones keep):
    /// a per-closure 99.99 % gate rejects a genuine closure of a consistent graph with
    /// probability `1 − 0.9999^m` (two-lap synthetic loop, 100 closures: one rejected at
    /// χ² 28.06). Default 1e-4 (the per-closure gate's level, now for the graph; 45.3 for
    /// sphere2500's 2,449 closures).
    pub closure_false_rejection_probability: f64,
    /// Pairwise consistency: consistent partners a closure needs to be trusted in the first
    /// solve. Default 2 (with 1, pairs of wrong "same place" closures along parallel stretches
    /// of odometry confirm each other: 23 of 1485 on sphere2500 with 30 % wrong closures).
    pub consistency_min_partners: usize,
    /// Settings of the certificate of global optimality ([`crate::certify`]; used only when
    /// one is asked for, e.g. `visnav posegraph --certify`).
    pub certify: CertifyConfig,
}

impl Default for GraphConfig {
    fn default() -> Self {
        Self {
            initialisation: Initialisation::Chordal,
            robust: RobustKernel::PairwiseConsistency,
            max_iterations: 100,
            relative_tolerance: 1e-7,
            initial_lambda: 1e-5,
            inlier_chi2_rotation: 21.11,
            inlier_chi2_position: 21.11,
            inlier_chi2_pose: 27.86,
            gnc_step: 1.4,
            max_reclassification_rounds: 3,
            consistency_window: 10,
            consistency_chi2: 27.86,
            consistency_min_partners: 2,
            closure_false_rejection_probability: 1e-4,
            certify: CertifyConfig::default(),
        }
    }
}

impl GraphConfig {
    /// Checks the fields.
    ///
    /// # Errors
    /// [`GraphError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), GraphError> {
        let positive = [
            ("relative_tolerance", self.relative_tolerance),
            ("initial_lambda", self.initial_lambda),
            ("inlier_chi2_rotation", self.inlier_chi2_rotation),
            ("inlier_chi2_position", self.inlier_chi2_position),
            ("inlier_chi2_pose", self.inlier_chi2_pose),
            ("consistency_chi2", self.consistency_chi2),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(GraphError::InvalidConfig {
                    field,
                    message: format!("must be positive and finite, got {v}"),
                });
            }
        }
        let p = self.closure_false_rejection_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(GraphError::InvalidConfig {
                field: "closure_false_rejection_probability",
                message: format!("must be in (0, 1), got {p}"),
            });
        }
        if !(self.gnc_step.is_finite() && self.gnc_step > 1.0) {
            return Err(GraphError::InvalidConfig {
                field: "gnc_step",
                message: format!("must be > 1, got {}", self.gnc_step),
            });
        }
        self.certify.validate()
    }
}

/// Wall-clock times of the stages, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Timing {
    /// Linear initialisation (including GNC and the pairwise consistency test).
    pub initialisation_ms: f64,
    /// Levenberg–Marquardt (all rounds).
    pub optimisation_ms: f64,
    /// Everything.
    pub total_ms: f64,
}

/// The result of [`solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Optimised `world_from_vertex` of each vertex, in vertex order.
    pub poses: Vec<Pose>,
    /// Objective over all edges at the input poses.
    pub initial: Objective,
    /// Objective over all edges after the linear initialisation.
    pub after_initialisation: Objective,
    /// Objective over all edges at the solution.
    pub final_all_edges: Objective,
    /// Objective over the accepted edges at the solution (what was minimised).
    pub final_inliers: Objective,
    /// Levenberg–Marquardt iterations over all rounds.
    pub iterations: usize,
    /// Whether the last round met the tolerance before `max_iterations`.
    pub converged: bool,
    /// Indices of the edges rejected as wrong loop closures.
    pub rejected_edges: Vec<usize>,
    /// Loop closures supported by another one ([`RobustKernel::PairwiseConsistency`] only; 0
    /// otherwise).
    pub supported_closures: usize,
    /// Stage timings.
    pub timing: Timing,
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Stage 1 of [`solve`], the initialisation: the starting poses and the edges Levenberg–Marquardt
/// starts with.
#[derive(Debug, Clone)]
struct InitialEstimate {
    /// Starting `world_from_vertex` per vertex.
    poses: Vec<Pose>,
    /// Per edge: whether it is in the objective (not set aside as a wrong loop closure).
    active: Vec<bool>,
    /// Per edge: a loop closure supported by enough consistent partners (pairwise consistency
    /// only; all `false` otherwise).
    supported: Vec<bool>,
    /// Per edge: the loop closures consistent with it ([`closure_confirmation`]; pairwise
    /// consistency only, empty otherwise), for the final gate ([`closure_gates`]).
    partners: Vec<Vec<usize>>,
}

/// Stage 2 of [`solve`], the optimisation: Levenberg–Marquardt rounds with re-classification
/// of the loop closures between rounds.
#[derive(Debug, Clone, Copy)]
struct Optimisation {
    /// Levenberg–Marquardt iterations over all rounds.
    iterations: usize,
    /// Whether the last round met the tolerance.
    converged: bool,
}

/// The outcome of [`consistency_initialisation`].
struct ConsistencyInitialisation {
    /// Per edge: a loop closure supported by enough consistent partners.
    supported: Vec<bool>,
    /// Per edge: the consistent partners ([`InitialEstimate::partners`]).
    partners: Vec<Vec<usize>>,
    /// The initial estimate over the supported core, when there is one.
    estimate: Option<InitialEstimate>,
}

/// The pairwise-consistency initialisation ([`RobustKernel::PairwiseConsistency`]): the
/// linear initialisation over odometry and the supported closures. `None` when no closure is
/// supported (while some exist) or the supported core leaves a vertex undetermined: the caller
/// falls back to GNC over every closure.
fn consistency_initialisation(
    graph: &PoseGraph,
    layout: &Layout,
    config: &GraphConfig,
    input: &[Pose],
) -> Result<ConsistencyInitialisation, GraphError> {
    let support = closure_support(
        graph,
        config.consistency_window,
        config.consistency_chi2,
        config.consistency_min_partners,
    );
    let supported_closures = support.n_supported();
    // The same test on every pair a closure needs (`closure_support` stops early, which can
    // leave the last closure of a run untested), keeping the partners for the final gate.
    let partners = closure_confirmation(
        graph,
        config.consistency_window,
        config.consistency_chi2,
        config.consistency_min_partners,
    )
    .partners;
    log::debug!(
        "pairwise consistency: {supported_closures} of {} loop closures supported ({} cycles tested)",
        support.closures,
        support.pairs_tested
    );
    if !(supported_closures > 0 || support.closures == 0) {
        log::debug!("no loop closure is supported by another: GNC over all of them");
        return Ok(ConsistencyInitialisation {
            supported: support.supported,
            partners,
            estimate: None,
        });
    }
    let core: Vec<bool> = graph
        .edges
        .iter()
        .zip(&support.supported)
        .map(|(e, s)| *s || graph.is_odometry(e))
        .collect();
    // The core may leave a vertex undetermined (linked only by unsupported closures):
    // then GNC over every closure instead.
    if !Layout::connected_over(graph, &core) {
        return Ok(ConsistencyInitialisation {
            supported: support.supported,
            partners,
            estimate: None,
        });
    }
    let poses = if config.initialisation == Initialisation::Chordal {
        linear_init_over(graph, layout, &core)?.poses()
    } else {
        input.to_vec()
    };
    // Unsupported closures already consistent with the core's initial estimate join now
    // (saving a second Levenberg–Marquardt round on clean graphs); the others are judged at
    // the optimum.
    let active = core
        .iter()
        .zip(&graph.edges)
        .map(|(c, e)| *c || e.chi2(&poses[e.from], &poses[e.to]) <= config.inlier_chi2_pose)
        .collect();
    Ok(ConsistencyInitialisation {
        supported: support.supported.clone(),
        partners: partners.clone(),
        estimate: Some(InitialEstimate {
            poses,
            active,
            supported: support.supported,
            partners,
        }),
    })
}

impl InitialEstimate {
    /// Stage 1: pairwise consistency (when configured), else the linear initialisation with GNC
    /// on the loop closures (robust modes) or without (plain chordal); `--init input` keeps the
    /// input poses.
    fn compute(
        graph: &PoseGraph,
        layout: &Layout,
        config: &GraphConfig,
        input: &[Pose],
    ) -> Result<Self, GraphError> {
        let robust = config.robust != RobustKernel::None;
        let mut supported = vec![false; graph.edges.len()];
        let mut partners = vec![Vec::new(); graph.edges.len()];
        if config.robust == RobustKernel::PairwiseConsistency {
            let c = consistency_initialisation(graph, layout, config, input)?;
            supported = c.supported;
            partners = c.partners;
            if let Some(estimate) = c.estimate {
                return Ok(estimate);
            }
        }
        let mut active = vec![true; graph.edges.len()];
        let mut poses = input.to_vec();
        if robust || config.initialisation == Initialisation::Chordal {
            let lin = linear_init(
                graph,
                layout,
                robust,
                config.inlier_chi2_rotation,
                config.inlier_chi2_position,
                config.gnc_step,
            )?;
            for (a, w) in active.iter_mut().zip(&lin.weights) {
                *a = *w >= 0.5;
            }
            if config.initialisation == Initialisation::Chordal {
                poses = lin.poses();
            }
        }
        Ok(Self {
            poses,
            active,
            supported,
            partners,
        })
    }
}

/// Survival function of the χ² distribution with 6 degrees of freedom,
/// `P(χ²₆ > x) = e^{−x/2} (1 + x/2 + x²/8)`.
fn chi2_6_survival(x: f64) -> f64 {
    let h = 0.5 * x.max(0.0);
    (-h).exp() * (1.0 + h + 0.5 * h * h)
}

/// The `χ²₆` value exceeded with probability `p` (bisection on the survival function).
fn chi2_6_upper_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 4000.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_6_survival(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The family-wise `χ²₆` gate of [`GraphConfig::closure_false_rejection_probability`] over the
/// graph's `m` loop closures: the quantile at `1 − p/m` (Bonferroni), never below
/// [`GraphConfig::inlier_chi2_pose`].
fn family_wise_chi2_6(graph: &PoseGraph, config: &GraphConfig) -> f64 {
    let closures = graph
        .edges
        .iter()
        .filter(|e| e.from != e.to && !graph.is_odometry(e))
        .count()
        .max(1);
    let p = config.closure_false_rejection_probability / closures as f64;
    config.inlier_chi2_pose.max(chi2_6_upper_quantile(p))
}

/// The gate on each loop closure's `χ²` at `poses` (odometry edges: unused). In pairwise mode a
/// closure with at least [`GraphConfig::consistency_min_partners`] consistent partners
/// ([`closure_confirmation`]) that are themselves accepted inliers at `poses` (`χ²` within the
/// per-closure gate) is confirmed by its neighbours: it is judged by the family-wise gate
/// ([`family_wise_chi2_6`]), so that only a residual beyond what `m` consistent closures reach by
/// chance sets it aside. Every other closure, and every closure in the other modes (the loop
/// closer's GNC graphs), keeps the per-closure gate [`GraphConfig::inlier_chi2_pose`]: a wrong
/// closure finds no partner, or only wrong ones, which the gate sets aside (with the
/// family-wise gate for every supported closure, a wrong closure of sphere2500 confirmed by two
/// wrong ones came back in: 494 of 495 rejected, ATE 0.09 % of the extent instead of 1e-6).
fn closure_gates(
    graph: &PoseGraph,
    config: &GraphConfig,
    poses: &[Pose],
    active: &[bool],
    partners: &[Vec<usize>],
) -> Vec<f64> {
    let per_closure = config.inlier_chi2_pose;
    if config.robust != RobustKernel::PairwiseConsistency || partners.iter().all(Vec::is_empty) {
        return vec![per_closure; graph.edges.len()];
    }
    let family_wise = family_wise_chi2_6(graph, config);
    let chi2: Vec<f64> = graph
        .edges
        .iter()
        .map(|e| e.chi2(&poses[e.from], &poses[e.to]))
        .collect();
    partners
        .iter()
        .map(|p| {
            let good = p
                .iter()
                .filter(|&&q| active[q] && chi2[q] <= per_closure)
                .count();
            if good >= config.consistency_min_partners.max(1) {
                family_wise
            } else {
                per_closure
            }
        })
        .collect()
}

/// Re-classifies every loop closure by its gate at `poses` ([`closure_gates`]); true when any
/// changed.
fn reclassify(
    graph: &PoseGraph,
    poses: &[Pose],
    active: &mut [bool],
    config: &GraphConfig,
    partners: &[Vec<usize>],
) -> bool {
    let gates = closure_gates(graph, config, poses, active, partners);
    let mut changed = false;
    for (k, e) in graph.edges.iter().enumerate() {
        if graph.is_odometry(e) {
            continue;
        }
        let inlier = e.chi2(&poses[e.from], &poses[e.to]) <= gates[k];
        if inlier != active[k] {
            active[k] = inlier;
            changed = true;
        }
    }
    changed
}

impl Optimisation {
    /// Stage 2: Levenberg–Marquardt over the active edges, then (robust modes) re-classification
    /// and another round while it changes, at most `max_reclassification_rounds` times.
    fn run(
        graph: &PoseGraph,
        layout: &Layout,
        config: &GraphConfig,
        poses: &mut [Pose],
        active: &mut [bool],
        partners: &[Vec<usize>],
    ) -> Result<Self, GraphError> {
        let robust = config.robust != RobustKernel::None;
        let mut iterations = 0;
        let mut converged;
        let mut round = 0;
        loop {
            // Rejected edges leave the pattern: rebuilt (symbolic factorisation included) per
            // round.
            let mut sys = BlockSystem::<6>::new(layout.n_vars, &layout.pairs(graph, active))?;
            let report = levenberg_marquardt(graph, layout, poses, active, config, &mut sys)?;
            iterations += report.iterations;
            converged = report.converged;
            if !robust || round >= config.max_reclassification_rounds {
                break;
            }
            if !reclassify(graph, poses, active, config, partners) {
                break;
            }
            round += 1;
        }
        Ok(Self {
            iterations,
            converged,
        })
    }
}

/// Relative tolerance of [`check_information`]: an eigenvalue below `-INDEFINITE_TOLERANCE`
/// times the largest absolute one makes a matrix indefinite (rounding leaves semi-definite
/// matrices slightly below zero).
const INDEFINITE_TOLERANCE: f64 = 1e-9;

/// Whether a symmetric matrix has an eigenvalue clearly below zero (or a non-finite entry).
fn is_indefinite(information: &Matrix6<f64>) -> bool {
    if !information.iter().all(|v| v.is_finite()) {
        return true;
    }
    if information.cholesky().is_some() {
        return false;
    }
    let eig = ((information + information.transpose()) * 0.5).symmetric_eigenvalues();
    let scale = eig.amax();
    eig.min() < -INDEFINITE_TOLERANCE * scale
}

/// No edge's information matrix may be indefinite: the objective would be indefinite and
/// Levenberg–Marquardt could run to a negative χ².
fn check_information(graph: &PoseGraph) -> Result<(), GraphError> {
    match graph
        .edges
        .iter()
        .position(|e| is_indefinite(&e.information))
    {
        Some(k) => {
            let e = &graph.edges[k];
            Err(GraphError::IndefiniteInformation {
                edge: k,
                from_id: graph.vertices[e.from].id,
                to_id: graph.vertices[e.to].id,
            })
        }
        None => Ok(()),
    }
}

/// Every edge and vertex inside the numeric range of `f64` ([`crate::numeric`]).
fn check_numeric_range(graph: &PoseGraph) -> Result<(), GraphError> {
    let Some(problem) = numeric_problem(graph) else {
        return Ok(());
    };
    let (what, message) = match problem {
        NumericProblem::Edge { edge, message } => {
            let e = &graph.edges[edge];
            (
                format!(
                    "edge {edge} ({} -> {})",
                    graph.vertices[e.from].id, graph.vertices[e.to].id
                ),
                message,
            )
        }
        NumericProblem::Vertex { vertex, message } => {
            (format!("vertex id {}", graph.vertices[vertex].id), message)
        }
    };
    Err(GraphError::NumericRange { what, message })
}

/// Optimises the vertex poses of `graph`.
///
/// Stages: `InitialEstimate::compute` (linear initialisation, robust preselection), then
/// `Optimisation::run` (Levenberg–Marquardt with re-classification of the loop closures).
///
/// # Errors
/// [`GraphError::InvalidConfig`], [`GraphError::Empty`], [`GraphError::Disconnected`] (a vertex
/// not linked to a fixed one), [`GraphError::IndefiniteInformation`] naming the first edge whose
/// information matrix is not positive definite, [`GraphError::NumericRange`] naming the first
/// edge or vertex outside the numeric range of `f64` ([`crate::numeric`]),
/// [`GraphError::Factorisation`] when the normal equations are singular.
pub fn solve(graph: &PoseGraph, config: &GraphConfig) -> Result<Solution, GraphError> {
    config.validate()?;
    check_information(graph)?;
    check_numeric_range(graph)?;
    let start = Instant::now();
    let layout = Layout::new(graph)?;
    let input = graph.poses();
    let initial = graph.objective_at(&input);
    let InitialEstimate {
        mut poses,
        mut active,
        supported,
        partners,
    } = InitialEstimate::compute(graph, &layout, config, &input)?;
    let after_initialisation = graph.objective_at(&poses);
    let initialisation_ms = ms_since(start);

    let t_lm = Instant::now();
    let Optimisation {
        iterations,
        converged,
    } = Optimisation::run(graph, &layout, config, &mut poses, &mut active, &partners)?;
    let optimisation_ms = ms_since(t_lm);
    let rejected_edges = active
        .iter()
        .enumerate()
        .filter(|(_, a)| !**a)
        .map(|(k, _)| k)
        .collect();
    Ok(Solution {
        final_all_edges: graph.objective_at(&poses),
        final_inliers: graph.objective_over(&poses, &active),
        poses,
        initial,
        after_initialisation,
        iterations,
        converged,
        rejected_edges,
        supported_closures: supported.iter().filter(|s| **s).count(),
        timing: Timing {
            initialisation_ms,
            optimisation_ms,
            total_ms: ms_since(start),
        },
    })
}

/// Iterations and convergence of one Levenberg–Marquardt run.
#[derive(Debug, Clone, Copy)]
struct LmReport {
    iterations: usize,
    converged: bool,
}

fn active_chi2(graph: &PoseGraph, poses: &[Pose], active: &[bool]) -> f64 {
    graph.objective_over(poses, active).chi2
}

/// Levenberg–Marquardt with Marquardt's diagonal damping on the active edges.
fn levenberg_marquardt(
    graph: &PoseGraph,
    layout: &Layout,
    poses: &mut [Pose],
    active: &[bool],
    config: &GraphConfig,
    sys: &mut BlockSystem<6>,
) -> Result<LmReport, GraphError> {
    let n = layout.n_vars * 6;
    let mut lambda = config.initial_lambda;
    let mut chi2 = active_chi2(graph, poses, active);
    let mut gradient = vec![0.0; n];
    let mut step = vec![0.0; n];
    let mut candidate = poses.to_vec();
    for iteration in 0..config.max_iterations {
        // Linearise: H = Σ Jᵀ Ω J, g = Σ Jᵀ Ω e.
        sys.clear();
        gradient.fill(0.0);
        for (e, _) in graph.edges.iter().zip(active).filter(|(_, a)| **a) {
            let (vi, vj) = (layout.var_of[e.from], layout.var_of[e.to]);
            let (r, jac_i, jac_j) =
                residual_and_jacobians(&e.from_from_to, &poses[e.from], &poses[e.to]);
            let info = &e.information;
            let ends: [(Option<usize>, Matrix6<f64>); 2] = [(vi, jac_i), (vj, jac_j)];
            for (va, ja) in &ends {
                let Some(va) = *va else { continue };
                let jt_info = ja.transpose() * info;
                let g = jt_info * r;
                for k in 0..6 {
                    gradient[va * 6 + k] += g[k];
                }
                for (vb, jb) in &ends {
                    let Some(vb) = *vb else { continue };
                    if vb < va {
                        continue;
                    }
                    if let Some(slot) = sys.slot(va, vb) {
                        sys.add(slot, va, vb, &(jt_info * jb));
                    }
                }
            }
        }
        let diagonal = sys.diagonal();
        loop {
            let damping: Vec<f64> = diagonal.iter().map(|d| lambda * d.max(1e-9)).collect();
            sys.add_to_diagonal(&damping);
            for (s, g) in step.iter_mut().zip(&gradient) {
                *s = -g;
            }
            let solved = sys.solve_in_place(&mut step, 1, "Levenberg-Marquardt");
            let undo: Vec<f64> = damping.iter().map(|d| -d).collect();
            sys.add_to_diagonal(&undo);
            if solved.is_ok() {
                for (k, var) in layout.var_of.iter().enumerate() {
                    candidate[k] = match var {
                        Some(v) => {
                            poses[k] * se3_exp(&Vector6::from_column_slice(&step[v * 6..v * 6 + 6]))
                        }
                        None => poses[k],
                    };
                }
                let new_chi2 = active_chi2(graph, &candidate, active);
                if new_chi2 <= chi2 {
                    poses.copy_from_slice(&candidate);
                    let decrease = chi2 - new_chi2;
                    chi2 = new_chi2;
                    lambda = (lambda * 0.1).max(1e-12);
                    if decrease <= config.relative_tolerance * chi2.max(f64::MIN_POSITIVE) {
                        return Ok(LmReport {
                            iterations: iteration + 1,
                            converged: true,
                        });
                    }
                    break;
                }
            }
            lambda *= 10.0;
            if lambda > 1e12 {
                // No step lowers the objective any more: at a minimum to machine precision.
                return Ok(LmReport {
                    iterations: iteration + 1,
                    converged: true,
                });
            }
        }
    }
    Ok(LmReport {
        iterations: config.max_iterations,
        converged: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{LoopDriveConfig, add_wrong_loop_closures, ate_and_extent, loop_drive};

    fn plain() -> GraphConfig {
        GraphConfig {
            robust: RobustKernel::None,
            ..GraphConfig::default()
        }
    }

    #[test]
    fn a_single_loop_closure_falls_back_to_gnc_and_is_kept() {
        let synth = loop_drive(&LoopDriveConfig {
            closure_every: 1000,
            ..LoopDriveConfig::default()
        });
        let sol = solve(&synth.graph, &GraphConfig::default()).unwrap();
        assert_eq!(sol.supported_closures, 0);
        assert!(sol.rejected_edges.is_empty());
        let clean = solve(&synth.graph, &plain()).unwrap();
        let (ate, extent) = ate_and_extent(&sol.poses, &clean.poses);
        assert!(ate < 1e-6 * extent, "{ate}");
    }

    #[test]
    fn pairwise_consistency_rejects_wrong_closures_and_keeps_genuine_ones() {
        let synth = loop_drive(&LoopDriveConfig::default());
        let mut graph = synth.graph.clone();
        let wrong = add_wrong_loop_closures(&mut graph, 0.3, 20.0, 9);
        let sol = solve(&graph, &GraphConfig::default()).unwrap();
        assert!(sol.supported_closures >= 45, "{}", sol.supported_closures);
        for k in &wrong {
            assert!(sol.rejected_edges.contains(k), "wrong closure {k} accepted");
        }
        // Genuine closures are rejected only by the χ²₆ gate at the optimum (a handful at most).
        assert!(sol.rejected_edges.len() <= wrong.len() + 6);
    }

    #[test]
    fn confirmed_closures_get_the_family_wise_gate_in_pairwise_mode_only() {
        // the χ²₆ quantiles: 99.99 % is the documented 27.86
        assert!((chi2_6_upper_quantile(1e-4) - 27.856).abs() < 1e-3);
        assert!((chi2_6_survival(chi2_6_upper_quantile(2e-8)) - 2e-8).abs() < 1e-12);
        let many = loop_drive(&LoopDriveConfig::default());
        let graph = &many.graph;
        let config = GraphConfig::default();
        let m = graph.edges.iter().filter(|e| !graph.is_odometry(e)).count();
        let fw = family_wise_chi2_6(graph, &config);
        assert!((chi2_6_survival(fw) * m as f64 - 1e-4).abs() < 1e-9);
        assert!(fw > 33.0 && fw < 40.0, "{fw}");
        let poses = &many.ground_truth;
        let mut active = vec![true; graph.edges.len()];
        let closures: Vec<usize> = (0..graph.edges.len())
            .filter(|&k| !graph.is_odometry(&graph.edges[k]))
            .collect();
        let (a, b, c) = (closures[0], closures[1], closures[2]);
        let mut partners = vec![Vec::new(); graph.edges.len()];
        // no partners at all (the GNC fallback): the per-closure gate everywhere
        let gates = closure_gates(graph, &config, poses, &active, &partners);
        assert!(gates.iter().all(|g| (g - 27.86).abs() < 1e-12));
        partners[a] = vec![b, c];
        let gates = closure_gates(graph, &config, poses, &active, &partners);
        assert!((gates[a] - fw).abs() < 1e-12);
        assert!((gates[b] - 27.86).abs() < 1e-12);
        // a partner set aside: not confirmed any more
        active[c] = false;
        let gates = closure_gates(graph, &config, poses, &active, &partners);
        assert!((gates[a] - 27.86).abs() < 1e-12);
        active[c] = true;
        let gnc = GraphConfig {
            robust: RobustKernel::GncGemanMcClure,
            ..GraphConfig::default()
        };
        let gates = closure_gates(graph, &gnc, poses, &active, &partners);
        assert!(gates.iter().all(|g| (g - 27.86).abs() < 1e-12));
    }

    /// Regression (issue 53, item 8): a consistent graph of 100 closures lost one to the
    /// per-closure 99.99 % gate (χ² 28.06 at the optimum), although the pairwise test found it
    /// consistent with its neighbours; the family-wise gate keeps it.
    #[test]
    fn a_consistent_two_lap_graph_loses_no_closure() {
        let synth = loop_drive(&LoopDriveConfig {
            closure_every: 1,
            ..LoopDriveConfig::default()
        });
        let sol = solve(&synth.graph, &GraphConfig::default()).unwrap();
        assert!(sol.rejected_edges.is_empty(), "{:?}", sol.rejected_edges);
        // the per-closure gate (the GNC mode's) rejects it: the test can fail
        let per_closure = solve(
            &synth.graph,
            &GraphConfig {
                closure_false_rejection_probability: 0.999_999,
                ..GraphConfig::default()
            },
        )
        .unwrap();
        assert_eq!(per_closure.rejected_edges.len(), 1);
    }

    #[test]
    fn invalid_consistency_gate_is_reported() {
        let config = GraphConfig {
            consistency_chi2: -1.0,
            ..GraphConfig::default()
        };
        assert!(matches!(
            config.validate(),
            Err(GraphError::InvalidConfig {
                field: "consistency_chi2",
                ..
            })
        ));
    }
}
