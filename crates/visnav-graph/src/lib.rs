//! Robust pose-graph optimisation on SE(3).
//!
//! The back-end of the monocular pipeline (§5 of Ng, Li and Kim 2021) optimises a graph of
//! keyframe poses linked by odometry and loop-closure edges. Following the spirit of its
//! reference \[17\] (Cheng, Kim, Shao and Zhang, "Robust linear pose graph-based SLAM", RAS 2015),
//! [`solve`] first initialises linearly — rotations by a chordal relaxation (linear least squares
//! over rotation matrices, projected back to SO(3)), then positions by linear least squares — and
//! then runs Levenberg–Marquardt on the manifold with analytic Jacobians and a sparse Cholesky
//! (`faer`). Wrong loop closures are set aside by a pairwise consistency test between closures
//! before the solve and by a `χ²₆` gate at the optimum (see [`solver`], [`consistency`]).
//!
//! * [`graph`]: vertices, edges, the standard objective `Σ eᵀ Ω e`, `e = Log(Z⁻¹ X_i⁻¹ X_j)`.
//! * [`g2o`]: the solver graph of a g2o file (the format is `visnav_io::g2o`), information
//!   matrices that are not positive definite replaced by SE-Sync's isotropic ones.
//! * [`lie`]: SE(3) adjoint and Jacobians.
//! * [`numeric`]: the numeric range a graph must lie in for `f64`.
//! * [`init`]: chordal rotation and linear position initialisation.
//! * [`consistency`]: pairwise consistency of loop closures (PCM-style preselection).
//! * [`solver`]: configuration, Levenberg–Marquardt, robust estimation, results.
//! * [`sesync`]: SE-Sync's objective and isotropic edge weights (Rosen et al. 2019).
//! * [`certificate`]: SE-Sync's dual certificate of global optimality.
//! * `synthetic` (the `test-support` feature, for tests and benchmarks): seeded loop-drive
//!   graphs with ground truth, wrong loop closures, ATE.
//!
//! Three poses a metre apart along x, the last one drifted to 2.5 m, and a closure that measures
//! the whole 2 m: [`solve`] puts it back.
//!
//! ```
//! use nalgebra::{Matrix6, Translation3, UnitQuaternion};
//! use visnav_core::Pose;
//! use visnav_graph::{Edge, GraphConfig, PoseGraph, Vertex, solve};
//!
//! let at = |x: f64| Pose::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity());
//! let vertices = [0.0, 1.0, 2.5]
//!     .iter()
//!     .enumerate()
//!     .map(|(i, &x)| Vertex { id: i as u64, world_from_vertex: at(x), fixed: i == 0 })
//!     .collect();
//! let edge = |from, to, metres| Edge {
//!     from,
//!     to,
//!     from_from_to: at(metres),
//!     information: Matrix6::identity() * 100.0,
//! };
//! let graph = PoseGraph { vertices, edges: vec![edge(0, 1, 1.0), edge(1, 2, 1.0), edge(0, 2, 2.0)] };
//! let solution = solve(&graph, &GraphConfig::default()).unwrap();
//! let last_x = solution.poses[2].translation.vector.x;
//! assert!((last_x - 2.0).abs() < 1e-6, "{last_x}");
//! assert!(solution.final_all_edges.chi2 < 1e-9);
//! ```

pub mod certificate;
pub mod consistency;
pub mod error;
pub mod g2o;
pub mod graph;
pub mod init;
pub mod lie;
pub mod numeric;
mod refine;
pub mod sesync;
pub mod solver;
mod sparse;
/// Seeded loop-drive graphs for tests and benchmarks: compiled only with the `test-support`
/// feature (dev-dependencies enable it), not the library's API.
#[cfg(any(test, feature = "test-support"))]
pub mod synthetic;

pub use certificate::{Certificate, CertifyConfig, Verdict, certify};
pub use consistency::{ClosureSupport, closure_confirmation, closure_support};
pub use error::GraphError;
pub use g2o::{
    G2oReport, ReplacedEdge, Replacement, format_g2o, parse_g2o, parse_g2o_with_report, read_g2o,
    read_g2o_with_report, write_g2o,
};
pub use graph::{Edge, Objective, PoseGraph, Vertex};
pub use sesync::{SeSyncWeights, isotropic_information, sesync_weights};
pub use solver::{GraphConfig, Initialisation, RobustKernel, Solution, Timing, solve};
