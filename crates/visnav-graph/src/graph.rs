//! The SE(3) pose graph: vertices (absolute poses `world_from_vertex`) and relative-pose edges.
//!
//! An edge from vertex `i` to vertex `j` measures `i_from_j` (`Z_ij`); its 6x6 information matrix
//! is ordered (translation, rotation) as in g2o, which matches the tangent order `(v, ω)` of
//! `visnav_core::se3`. The residual of an edge is `e_ij = Log(Z_ij⁻¹ X_i⁻¹ X_j)` (the exact SE(3)
//! logarithm, as GTSAM's `BetweenFactor<Pose3>` defines it) and the objective is
//! `χ² = Σ e_ijᵀ Ω_ij e_ij`; GTSAM reports `½ χ²`.

use nalgebra::Matrix6;
use visnav_core::Pose;
use visnav_core::se3::se3_log;

/// One pose of the graph.
#[derive(Debug, Clone, PartialEq)]
pub struct Vertex {
    /// The vertex id of the file (ids need not be contiguous).
    pub id: u64,
    /// The pose, `world_from_vertex`.
    pub world_from_vertex: Pose,
    /// Held constant by the optimiser.
    pub fixed: bool,
}

/// A relative-pose measurement between two vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Index (into [`PoseGraph::vertices`]) of the first vertex `i`.
    pub from: usize,
    /// Index of the second vertex `j`.
    pub to: usize,
    /// The measured relative pose `Z_ij = i_from_j`.
    pub from_from_to: Pose,
    /// Information matrix (inverse covariance) of the residual, ordered (translation, rotation).
    pub information: Matrix6<f64>,
}

/// A pose graph on SE(3).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseGraph {
    /// The vertices in file order.
    pub vertices: Vec<Vertex>,
    /// The edges in file order.
    pub edges: Vec<Edge>,
}

impl Edge {
    /// The residual `e = Log(Z⁻¹ X_i⁻¹ X_j)` ordered `(v, ω)`, for the given vertex poses.
    #[must_use]
    pub fn residual(&self, world_from_i: &Pose, world_from_j: &Pose) -> nalgebra::Vector6<f64> {
        se3_log(&(self.from_from_to.inverse() * world_from_i.inverse() * world_from_j))
    }

    /// The squared whitened residual `eᵀ Ω e`.
    #[must_use]
    pub fn chi2(&self, world_from_i: &Pose, world_from_j: &Pose) -> f64 {
        let e = self.residual(world_from_i, world_from_j);
        e.dot(&(self.information * e))
    }
}

/// Value of the standard objective over a set of poses.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Objective {
    /// `χ² = Σ eᵀ Ω e` over all edges (the g2o convention).
    pub chi2: f64,
    /// GTSAM's error, `½ χ²`.
    pub gtsam_error: f64,
}

impl Objective {
    fn from_chi2(chi2: f64) -> Self {
        Self {
            chi2,
            gtsam_error: 0.5 * chi2,
        }
    }
}

impl PoseGraph {
    /// The vertex poses, in vertex order.
    #[must_use]
    pub fn poses(&self) -> Vec<Pose> {
        self.vertices.iter().map(|v| v.world_from_vertex).collect()
    }

    /// Replaces the vertex poses (in vertex order; extra or missing entries are ignored).
    pub fn set_poses(&mut self, poses: &[Pose]) {
        for (v, p) in self.vertices.iter_mut().zip(poses) {
            v.world_from_vertex = *p;
        }
    }

    /// Whether an edge is odometry (consecutive vertex ids), as opposed to a loop closure.
    #[must_use]
    pub fn is_odometry(&self, edge: &Edge) -> bool {
        self.vertices[edge.from]
            .id
            .abs_diff(self.vertices[edge.to].id)
            == 1
    }

    /// The objective at the graph's own vertex poses.
    #[must_use]
    pub fn objective(&self) -> Objective {
        self.objective_at(&self.poses())
    }

    /// The objective at the given poses (in vertex order).
    #[must_use]
    pub fn objective_at(&self, poses: &[Pose]) -> Objective {
        Objective::from_chi2(
            self.edges
                .iter()
                .map(|e| e.chi2(&poses[e.from], &poses[e.to]))
                .sum(),
        )
    }

    /// The objective over a subset of edges (`keep[k]` selects edge `k`).
    #[must_use]
    pub fn objective_over(&self, poses: &[Pose], keep: &[bool]) -> Objective {
        Objective::from_chi2(
            self.edges
                .iter()
                .zip(keep)
                .filter(|(_, k)| **k)
                .map(|(e, _)| e.chi2(&poses[e.from], &poses[e.to]))
                .sum(),
        )
    }
}
