//! Linear initialisation in the spirit of Cheng et al. 2015 (reference \[17\] of Ng, Li and Kim
//! 2021), optionally robustified by graduated non-convexity.
//!
//! 1. **Rotations (chordal relaxation).** Minimise `Σ w κ ‖R_j − R_i R_ij‖²_F` over unconstrained
//!    3x3 matrices with the fixed vertices' rotations held, where
//!    `κ = 3 / (2 tr(Ω_rot⁻¹))` (SE-Sync's weight; `κ ‖ΔR‖²_F ≈ θ² ω` for `Ω_rot = ω I`). The rows
//!    decouple: row `r` of every `R` solves one sparse 3-block system `x_j − R_ijᵀ x_i = 0`, so one
//!    factorisation serves the three right-hand sides. Each result is projected onto SO(3).
//! 2. **Positions.** With the rotations fixed, minimise `Σ w dᵀ W d` with
//!    `d = t_j − t_i − R_i t_ij` and `W = R_j Ω_t R_jᵀ` (the translation information rotated into the
//!    world frame, `R_j = R_i R_ij`).
//!
//! **Robustness (GNC, Yang, Antonante, Tzoumas and Carlone, RA-L 2020).** Non-odometry edges get
//! Geman–McClure weights `w = (μ c² / (r² + μ c²))²` where `r²` is the edge's whitened residual;
//! `μ` starts at `2 r²_max / c²` (the surrogate is then convex) and is divided by 1.4 after each
//! weighted solve until it reaches 1. Both stages are linear, so each GNC step costs one sparse
//! factorisation of a 3-block system.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use visnav_core::Pose;
use visnav_core::se3::project_to_so3;

use crate::error::GraphError;
use crate::graph::PoseGraph;
use crate::sparse::BlockSystem;

/// The variables of a graph: which vertices are free and their variable index.
#[derive(Debug, Clone)]
pub struct Layout {
    /// Variable index of each vertex; `None` for fixed vertices.
    pub var_of: Vec<Option<usize>>,
    /// Number of free vertices.
    pub n_vars: usize,
}

impl Layout {
    /// Fixes the vertices marked fixed (or the first vertex when none is) and checks that every
    /// vertex is connected to a fixed one.
    pub fn new(graph: &PoseGraph) -> Result<Self, GraphError> {
        let n = graph.vertices.len();
        if n == 0 {
            return Err(GraphError::Empty);
        }
        let mut fixed: Vec<bool> = graph.vertices.iter().map(|v| v.fixed).collect();
        if !fixed.iter().any(|f| *f) {
            fixed[0] = true;
        }
        // Connectivity by union–find.
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut a: usize) -> usize {
            while parent[a] != a {
                parent[a] = parent[parent[a]];
                a = parent[a];
            }
            a
        }
        for e in &graph.edges {
            let (a, b) = (find(&mut parent, e.from), find(&mut parent, e.to));
            parent[a] = b;
        }
        let mut anchored = vec![false; n];
        for (k, f) in fixed.iter().enumerate() {
            if *f {
                let r = find(&mut parent, k);
                anchored[r] = true;
            }
        }
        for k in 0..n {
            let r = find(&mut parent, k);
            if !anchored[r] {
                return Err(GraphError::Disconnected {
                    id: graph.vertices[k].id,
                });
            }
        }
        let mut var_of = vec![None; n];
        let mut n_vars = 0;
        for (k, f) in fixed.iter().enumerate() {
            if !*f {
                var_of[k] = Some(n_vars);
                n_vars += 1;
            }
        }
        Ok(Self { var_of, n_vars })
    }

    /// Whether every vertex is linked to a fixed vertex through the selected edges alone.
    #[must_use]
    pub fn connected_over(graph: &PoseGraph, keep: &[bool]) -> bool {
        let mut sub = PoseGraph {
            vertices: graph.vertices.clone(),
            edges: Vec::new(),
        };
        sub.edges = graph
            .edges
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(e, _)| e.clone())
            .collect();
        Self::new(&sub).is_ok()
    }

    /// Variable pairs of the selected edges whose both ends are free.
    #[must_use]
    pub fn pairs(&self, graph: &PoseGraph, active: &[bool]) -> Vec<(usize, usize)> {
        graph
            .edges
            .iter()
            .zip(active)
            .filter(|(_, a)| **a)
            .filter_map(|(e, _)| Some((self.var_of[e.from]?, self.var_of[e.to]?)))
            .collect()
    }
}

/// Rotations, positions and the final edge weights of the linear initialisation.
#[derive(Debug, Clone)]
pub struct LinearInit {
    /// Rotation of each vertex (`world_from_vertex`).
    pub rotations: Vec<Rotation3<f64>>,
    /// Position of each vertex in the world frame, metres.
    pub positions: Vec<Vector3<f64>>,
    /// Weight of each edge after GNC (1 for odometry and without robustness).
    pub weights: Vec<f64>,
}

impl LinearInit {
    /// The poses `world_from_vertex` (rotation and position of each vertex).
    #[must_use]
    pub fn poses(&self) -> Vec<Pose> {
        self.rotations
            .iter()
            .zip(&self.positions)
            .map(|(r, t)| {
                Isometry3::from_parts(
                    Translation3::from(*t),
                    UnitQuaternion::from_rotation_matrix(r),
                )
            })
            .collect()
    }
}

/// Geman–McClure GNC weight.
pub(crate) fn gm_weight(r2: f64, c2: f64, mu: f64) -> f64 {
    let s = mu * c2;
    (s / (r2 + s)).powi(2)
}

/// SE-Sync's rotation weight `κ = 3 / (2 tr(Ω_rot⁻¹))`.
fn kappa(info: &nalgebra::Matrix6<f64>) -> f64 {
    let rot = info.fixed_view::<3, 3>(3, 3).into_owned();
    rot.try_inverse()
        .map_or(0.0, |inv| 1.5 / inv.trace().max(f64::MIN_POSITIVE))
}

/// One linear edge `A_i x_i + A_j x_j ≈ c` (three right-hand sides in the columns of `c`) with
/// weight matrix `W`; fixed ends move to the right-hand side.
struct LinearEdge {
    i: usize,
    j: usize,
    a_i: Matrix3<f64>,
    a_j: Matrix3<f64>,
    w: Matrix3<f64>,
    c: Matrix3<f64>,
}

/// Solves the weighted linear least squares of `edges`; returns each vertex's 3x3 value
/// (columns = right-hand sides), with `fixed_value` for fixed vertices.
fn solve_linear(
    layout: &Layout,
    sys: &mut BlockSystem<3>,
    edges: &[LinearEdge],
    fixed_value: &dyn Fn(usize) -> Matrix3<f64>,
    stage: &'static str,
) -> Result<Vec<Matrix3<f64>>, GraphError> {
    sys.clear();
    let n = sys.n_blocks() * 3;
    let mut rhs = vec![0.0; n * 3];
    for e in edges.iter().filter(|e| e.w != Matrix3::zeros()) {
        let (vi, vj) = (layout.var_of[e.i], layout.var_of[e.j]);
        let mut c = e.c;
        if vi.is_none() {
            c -= e.a_i * fixed_value(e.i);
        }
        if vj.is_none() {
            c -= e.a_j * fixed_value(e.j);
        }
        let ends = [(vi, e.a_i), (vj, e.a_j)];
        for (va, a) in ends {
            let Some(va) = va else { continue };
            let at_w = a.transpose() * e.w;
            let b = at_w * c;
            for col in 0..3 {
                for r in 0..3 {
                    rhs[col * n + va * 3 + r] += b[(r, col)];
                }
            }
            for (vb, bmat) in ends {
                let Some(vb) = vb else { continue };
                if vb < va {
                    continue;
                }
                if let Some(slot) = sys.slot(va, vb) {
                    sys.add(slot, va, vb, &(at_w * bmat));
                }
            }
        }
    }
    sys.solve_in_place(&mut rhs, 3, stage)?;
    Ok(layout
        .var_of
        .iter()
        .enumerate()
        .map(|(k, v)| match v {
            Some(v) => Matrix3::from_fn(|r, col| rhs[col * n + v * 3 + r]),
            None => fixed_value(k),
        })
        .collect())
}

/// Which edges GNC may down-weight: the non-odometry ones (all `false` without robustness).
pub(crate) fn robust_mask(graph: &PoseGraph, robust: bool) -> Vec<bool> {
    graph
        .edges
        .iter()
        .map(|e| robust && !graph.is_odometry(e))
        .collect()
}

/// Runs GNC around `solve_and_residuals` (which solves with the given weights and returns the
/// squared whitened residual of each edge). Without robust edges, one plain solve.
fn graduated<T>(
    robust: &[bool],
    base_weights: &[f64],
    c2: f64,
    gnc_step: f64,
    from_trusted: bool,
    mut solve_and_residuals: impl FnMut(&[f64]) -> Result<(T, Vec<f64>), GraphError>,
) -> Result<(T, Vec<f64>), GraphError> {
    let mut weights = base_weights.to_vec();
    if !robust.iter().any(|r| *r) {
        let (sol, _) = solve_and_residuals(&weights)?;
        return Ok((sol, weights));
    }
    // Start from the trusted (non-robust) edges alone when they determine the problem: the
    // residuals of the robust edges there are not yet bent by wrong ones, and `μ` starts where
    // the median robust edge has weight (4/5)² (Yang et al. start from the all-edge least squares
    // with μ = 2 r²_max / c², which a large share of wrong closures drags away).
    let trusted_only: Vec<f64> = weights
        .iter()
        .zip(robust)
        .map(|(w, r)| if *r { 0.0 } else { *w })
        .collect();
    let start = if from_trusted {
        solve_and_residuals(&trusted_only).ok()
    } else {
        None
    };
    let (mut r2, mut mu) = match start {
        Some((_, r2)) => {
            let mut robust_r2: Vec<f64> = r2
                .iter()
                .zip(robust)
                .zip(base_weights)
                .filter(|((_, r), b)| **r && **b > 0.0)
                .map(|((v, _), _)| *v)
                .collect();
            robust_r2.sort_unstable_by(f64::total_cmp);
            let median = robust_r2.get(robust_r2.len() / 2).copied().unwrap_or(0.0);
            (r2, (4.0 * median / c2).max(1.0))
        }
        None => {
            let (_, r2) = solve_and_residuals(&weights)?;
            let r2_max = r2
                .iter()
                .zip(robust)
                .filter(|(_, r)| **r)
                .map(|(v, _)| *v)
                .fold(0.0, f64::max);
            (r2, (2.0 * r2_max / c2).max(1.0))
        }
    };
    let mut steps = 0;
    let mut settle = 0;
    loop {
        steps += 1;
        let mut change: f64 = 0.0;
        for k in 0..weights.len() {
            if robust[k] {
                let w = base_weights[k] * gm_weight(r2[k], c2, mu);
                change = change.max((w - weights[k]).abs());
                weights[k] = w;
            }
        }
        let (sol, new_r2) = solve_and_residuals(&weights)?;
        r2 = new_r2;
        if mu <= 1.0 {
            settle += 1;
        }
        if mu <= 1.0 && (change < 1e-3 || settle >= 10) {
            let low = weights
                .iter()
                .zip(robust)
                .filter(|(w, r)| **r && **w < 0.5)
                .count();
            log::debug!("GNC: {steps} steps, {low} edges below weight 0.5");
            return Ok((sol, weights));
        }
        mu = (mu / gnc_step).max(1.0);
    }
}

/// Weight 1 for kept edges, 0 otherwise.
fn indicator(kept: &[bool]) -> Vec<f64> {
    kept.iter().map(|k| if *k { 1.0 } else { 0.0 }).collect()
}

/// Rotations, final GNC weights and chordal residuals of every edge.
type RotationStage = (Vec<Rotation3<f64>>, Vec<f64>, Vec<f64>);

/// Chordal rotations over the kept edges (GNC on the robust ones). Returns the rotations, the
/// final weights and the chordal residual `κ ‖R_j − R_i R_ij‖²_F` of every edge.
fn rotation_stage(
    graph: &PoseGraph,
    layout: &Layout,
    kept: &[bool],
    mask: &[bool],
    c2: f64,
    gnc_step: f64,
) -> Result<RotationStage, GraphError> {
    let mut sys = BlockSystem::<3>::new(layout.n_vars, &layout.pairs(graph, kept))?;
    let kappas: Vec<f64> = graph.edges.iter().map(|e| kappa(&e.information)).collect();
    let fixed_rot: Vec<Matrix3<f64>> = graph
        .vertices
        .iter()
        .map(|v| {
            v.world_from_vertex
                .rotation
                .to_rotation_matrix()
                .into_inner()
                .transpose()
        })
        .collect();
    // Rows of R (x_i = column r of R_iᵀ): x_j − R_ijᵀ x_i = 0, i.e. R_jᵀ = R_ijᵀ R_iᵀ.
    let ((rotations, r2), weights) = graduated(mask, &indicator(kept), c2, gnc_step, false, |w| {
        let edges: Vec<LinearEdge> = graph
            .edges
            .iter()
            .zip(w)
            .zip(&kappas)
            .map(|((e, &wk), &kap)| {
                let r_ij = e.from_from_to.rotation.to_rotation_matrix().into_inner();
                LinearEdge {
                    i: e.from,
                    j: e.to,
                    a_i: -r_ij.transpose(),
                    a_j: Matrix3::identity(),
                    w: Matrix3::identity() * (wk * kap),
                    c: Matrix3::zeros(),
                }
            })
            .collect();
        let sol = solve_linear(layout, &mut sys, &edges, &|k| fixed_rot[k], "rotation")?;
        let rotations: Vec<Rotation3<f64>> = sol
            .iter()
            .zip(&graph.vertices)
            .zip(&layout.var_of)
            .map(|((m, v), var)| match var {
                Some(_) => project_to_so3(&m.transpose()),
                None => v.world_from_vertex.rotation.to_rotation_matrix(),
            })
            .collect();
        let r2: Vec<f64> = graph
            .edges
            .iter()
            .zip(&kappas)
            .map(|(e, &kap)| {
                let r_ij = e.from_from_to.rotation.to_rotation_matrix();
                let d = rotations[e.to].matrix() - (rotations[e.from] * r_ij).matrix();
                kap * d.norm_squared()
            })
            .collect();
        Ok(((rotations, r2.clone()), r2))
    })?;
    Ok((rotations, weights, r2))
}

/// Linear positions over the kept edges with the rotations held (GNC on the robust ones).
fn position_stage(
    graph: &PoseGraph,
    layout: &Layout,
    rotations: &[Rotation3<f64>],
    kept: &[bool],
    mask: &[bool],
    c2: f64,
    gnc_step: f64,
) -> Result<(Vec<Vector3<f64>>, Vec<f64>), GraphError> {
    let mut sys = BlockSystem::<3>::new(layout.n_vars, &layout.pairs(graph, kept))?;
    let fixed_pos: Vec<Matrix3<f64>> = graph
        .vertices
        .iter()
        .map(|v| {
            let mut m = Matrix3::zeros();
            m.set_column(0, &v.world_from_vertex.translation.vector);
            m
        })
        .collect();
    // t_j − t_i = R_i t_ij weighted by R_j Ω_t R_jᵀ.
    let world_info: Vec<Matrix3<f64>> = graph
        .edges
        .iter()
        .map(|e| {
            let r_j =
                (rotations[e.from] * e.from_from_to.rotation.to_rotation_matrix()).into_inner();
            let omega_t = e.information.fixed_view::<3, 3>(0, 0).into_owned();
            r_j * omega_t * r_j.transpose()
        })
        .collect();
    graduated(mask, &indicator(kept), c2, gnc_step, true, |w| {
        let edges: Vec<LinearEdge> = graph
            .edges
            .iter()
            .zip(w)
            .zip(&world_info)
            .map(|((e, &wk), info)| {
                let mut c = Matrix3::zeros();
                c.set_column(0, &(rotations[e.from] * e.from_from_to.translation.vector));
                LinearEdge {
                    i: e.from,
                    j: e.to,
                    a_i: -Matrix3::identity(),
                    a_j: Matrix3::identity(),
                    w: info * wk,
                    c,
                }
            })
            .collect();
        let sol = solve_linear(layout, &mut sys, &edges, &|k| fixed_pos[k], "position")?;
        let positions: Vec<Vector3<f64>> = sol.iter().map(|m| m.column(0).into_owned()).collect();
        let r2 = graph
            .edges
            .iter()
            .zip(&world_info)
            .map(|(e, info)| {
                let d = positions[e.to]
                    - positions[e.from]
                    - rotations[e.from] * e.from_from_to.translation.vector;
                d.dot(&(info * d))
            })
            .collect();
        Ok((positions, r2))
    })
}

/// The plain (non-robust) linear initialisation over the edges selected by `kept`.
///
/// # Errors
/// [`GraphError::Factorisation`] when the selected edges leave some vertex undetermined.
pub fn linear_init_over(
    graph: &PoseGraph,
    layout: &Layout,
    kept: &[bool],
) -> Result<LinearInit, GraphError> {
    let mask = vec![false; graph.edges.len()];
    // The GNC thresholds and step are unused without robust edges.
    let (rotations, _, _) = rotation_stage(graph, layout, kept, &mask, 1.0, 2.0)?;
    let (positions, weights) = position_stage(graph, layout, &rotations, kept, &mask, 1.0, 2.0)?;
    Ok(LinearInit {
        rotations,
        positions,
        weights,
    })
}

/// The linear initialisation with optional GNC. `c2_rotation`/`c2_position` are the GNC
/// thresholds on the whitened residuals of each stage.
///
/// With robustness and when round 1 down-weighted some edge, two rounds: (1) rotations by GNC over all edges, positions by GNC over the
/// edges the rotations kept; (2) rotations again over the edges round 1 kept (wrong closures
/// that happened to be rotation-consistent no longer bend them), then positions by GNC over
/// every rotation-consistent edge (`κ‖ΔR‖² ≤ c2_rotation` under the new rotations).
///
/// # Errors
/// [`GraphError::Factorisation`] when a linear system is singular (e.g. a vertex only linked by
/// rejected edges).
pub fn linear_init(
    graph: &PoseGraph,
    layout: &Layout,
    robust: bool,
    c2_rotation: f64,
    c2_position: f64,
    gnc_step: f64,
) -> Result<LinearInit, GraphError> {
    let mask = robust_mask(graph, robust);
    let all = vec![true; graph.edges.len()];
    let (mut rotations, rot_weights, _) =
        rotation_stage(graph, layout, &all, &mask, c2_rotation, gnc_step)?;
    let kept: Vec<bool> = rot_weights.iter().map(|w| *w >= 0.5).collect();
    let (mut positions, mut weights) = position_stage(
        graph,
        layout,
        &rotations,
        &kept,
        &mask,
        c2_position,
        gnc_step,
    )?;
    if robust && weights.iter().any(|w| *w < 0.5) {
        let kept: Vec<bool> = weights.iter().map(|w| *w >= 0.5).collect();
        let (r2_rotations, _, r2) =
            rotation_stage(graph, layout, &kept, &mask, c2_rotation, gnc_step)?;
        rotations = r2_rotations;
        let consistent: Vec<bool> = r2
            .iter()
            .zip(&mask)
            .map(|(r, m)| !*m || *r <= c2_rotation)
            .collect();
        (positions, weights) = position_stage(
            graph,
            layout,
            &rotations,
            &consistent,
            &mask,
            c2_position,
            gnc_step,
        )?;
    }
    Ok(LinearInit {
        rotations,
        positions,
        weights,
    })
}
