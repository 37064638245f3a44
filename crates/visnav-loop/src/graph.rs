//! The pose graph of a monocular run (§5 of Ng, Li and Kim 2021): one vertex per frame of the run
//! (`world_from_cam`), an odometry edge between consecutive frames and one edge per accepted loop
//! closure, optimised by [`visnav_graph::solve`] (robust kernel on loop closures by default).
//!
//! Edge convention (visnav-graph): an edge `i → j` measures `Z_ij = i_from_j`; the residual is
//! `Log(Z⁻¹ X_i⁻¹ X_j)` ordered `(v, ω)`.

use nalgebra::{Matrix6, Vector6};
use serde::{Deserialize, Serialize};
use visnav_core::Pose;
use visnav_graph::{Edge, GraphConfig, GraphError, PoseGraph, Solution, Vertex};

/// Noise model of the odometry edges. The monocular pipeline reports no covariance per frame, so
/// the odometry edges take a diagonal one: translation `σ_t = translation_fraction · ‖t‖ +
/// translation_floor_m` per axis, rotation `σ_r = rotation_rad` per axis. Not in the paper (which
/// gives no numbers). The defaults are generous on purpose: the robust optimiser sets aside a
/// closure whose correction the odometry noise cannot explain, and the monocular odometry drifted
/// 8 % of the distance (11.9 m over 143 m, mostly heading) on the 320x96 synthetic loop drive;
/// tighter values (5 %, 0.002 rad) made the optimiser reject that drive's genuine closures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoise {
    /// Translation standard deviation per axis as a fraction of the step length. Default 0.1.
    pub translation_fraction: f64,
    /// Added translation standard deviation per axis, metres. Default 0.05.
    pub translation_floor_m: f64,
    /// Rotation standard deviation per axis, radians. Default 0.01 (≈ 0.57 deg).
    pub rotation_rad: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self {
            translation_fraction: 0.1,
            translation_floor_m: 0.05,
            rotation_rad: 0.01,
        }
    }
}

impl OdometryNoise {
    /// The information matrix of an odometry step `prev_from_cur`, ordered `(v, ω)`.
    #[must_use]
    pub fn information(&self, prev_from_cur: &Pose) -> Matrix6<f64> {
        let sigma_t_m = self.translation_fraction * prev_from_cur.translation.vector.norm()
            + self.translation_floor_m;
        let t = 1.0 / (sigma_t_m * sigma_t_m);
        let r = 1.0 / (self.rotation_rad * self.rotation_rad);
        Matrix6::from_diagonal(&Vector6::new(t, t, t, r, r, r))
    }
}

/// The growing pose graph of a run and its current (optimised) poses.
#[derive(Debug, Clone, Default)]
pub struct LoopGraph {
    graph: PoseGraph,
}

impl LoopGraph {
    /// An empty graph.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of vertices (frames of the run so far).
    #[must_use]
    pub fn len(&self) -> usize {
        self.graph.vertices.len()
    }

    /// Whether the graph has no vertex.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.graph.vertices.is_empty()
    }

    /// The underlying graph.
    #[must_use]
    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

    /// The current pose of every vertex (`world_from_cam`), in run order.
    #[must_use]
    pub fn poses(&self) -> Vec<Pose> {
        self.graph.poses()
    }

    /// The current pose of vertex `i`.
    #[must_use]
    pub fn pose(&self, i: usize) -> Option<Pose> {
        self.graph.vertices.get(i).map(|v| v.world_from_vertex)
    }

    /// Appends the next frame, reached from the last one by the odometry motion `prev_from_cur`
    /// (ignored for the first frame, which is the world origin and held fixed). Its pose is the
    /// last vertex's current pose composed with the motion. Returns the new vertex index.
    pub fn push_odometry(&mut self, prev_from_cur: &Pose, information: Matrix6<f64>) -> usize {
        let i = self.graph.vertices.len();
        let (world_from_vertex, fixed) = match self.graph.vertices.last() {
            Some(prev) => (prev.world_from_vertex * prev_from_cur, false),
            None => (Pose::identity(), true),
        };
        self.graph.vertices.push(Vertex {
            id: i as u64,
            world_from_vertex,
            fixed,
        });
        if i > 0 {
            self.graph.edges.push(Edge {
                from: i - 1,
                to: i,
                from_from_to: *prev_from_cur,
                information,
            });
        }
        i
    }

    /// Adds a loop closure between the earlier vertex `earlier` and the later vertex `later`:
    /// `later_from_earlier` maps points of the earlier camera into the later one. Returns the
    /// edge index, or `None` when a vertex does not exist or the two are the same.
    pub fn add_loop(
        &mut self,
        earlier: usize,
        later: usize,
        later_from_earlier: &Pose,
        information: Matrix6<f64>,
    ) -> Option<usize> {
        let n = self.graph.vertices.len();
        if earlier >= n || later >= n || earlier == later {
            return None;
        }
        self.graph.edges.push(Edge {
            from: earlier,
            to: later,
            from_from_to: later_from_earlier.inverse(),
            information,
        });
        Some(self.graph.edges.len() - 1)
    }

    /// Optimises the graph and takes the solution as the current poses.
    ///
    /// # Errors
    /// [`GraphError`] from the solver (the poses are then unchanged).
    pub fn optimise(&mut self, config: &GraphConfig) -> Result<Solution, GraphError> {
        let solution = visnav_graph::solve(&self.graph, config)?;
        self.graph.set_poses(&solution.poses);
        Ok(solution)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn step(forward_m: f64, yaw_rad: f64) -> Pose {
        // prev_from_cur of a camera moving `forward_m` along its z axis while turning by yaw
        Pose::from_parts(
            Translation3::new(0.0, 0.0, forward_m),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_rad),
        )
    }

    /// A square drive of 40 steps of 1 m with four 90-degree turns, each step scaled by
    /// `scale` and each turn by `turn`.
    fn square_drive(noise: &OdometryNoise, scale: f64, turn: f64) -> LoopGraph {
        let mut g = LoopGraph::new();
        g.push_odometry(&Pose::identity(), noise.information(&Pose::identity()));
        for k in 0..40 {
            let yaw = if k % 10 == 9 {
                std::f64::consts::FRAC_PI_2
            } else {
                0.0
            };
            let s = step(scale, yaw * turn);
            g.push_odometry(&s, noise.information(&s));
        }
        g
    }

    /// The odometry of the square over-estimates every step by 3 % and turns 1 % too far: the end
    /// is far from the start. One exact loop closure between the last and the first frame brings
    /// the end back and spreads the correction over the loop.
    #[test]
    fn a_loop_closure_pulls_the_drifted_end_back() {
        let noise = OdometryNoise::default();
        let truth = square_drive(&noise, 1.0, 1.0).poses();
        let before = square_drive(&noise, 1.03, 1.01).poses();
        let mut drifted = square_drive(&noise, 1.03, 1.01);
        assert_eq!(drifted.len(), 41);
        assert_eq!(drifted.graph().edges.len(), 40);
        // the exact square closes on itself
        assert!(truth[40].translation.vector.norm() < 1e-9);
        let end_before = before[40].translation.vector.norm();
        assert!(end_before > 0.3, "{end_before}");
        // later (40) from earlier (0), as the front-end measures it: the identity here
        let later_from_earlier = truth[40].inverse() * truth[0];
        let info = Matrix6::identity() * 1e4;
        let e = drifted.add_loop(0, 40, &later_from_earlier, info).unwrap();
        assert_eq!(e, 40);
        assert!(drifted.add_loop(0, 41, &later_from_earlier, info).is_none());
        assert!(drifted.add_loop(3, 3, &later_from_earlier, info).is_none());
        let solution = drifted.optimise(&GraphConfig::default()).unwrap();
        assert!(solution.rejected_edges.is_empty());
        let poses = drifted.poses();
        let end_after = poses[40].translation.vector.norm();
        assert!(end_after < 0.05 * end_before, "{end_before} -> {end_after}");
        // the first frame stays the origin; the closure is satisfied at the optimum
        assert!(poses[0].translation.vector.norm() < 1e-9);
        let closure = &drifted.graph().edges[e];
        assert!(closure.chi2(&poses[0], &poses[40]) < 1.0);
    }

    #[test]
    fn odometry_information_follows_the_step_length() {
        let noise = OdometryNoise::default();
        let short = noise.information(&step(0.1, 0.0));
        let long = noise.information(&step(2.0, 0.0));
        // σ_t = 0.1 · 2 + 0.05 = 0.25 m
        assert!((long[(0, 0)] - 1.0 / (0.25 * 0.25)).abs() < 1e-9);
        assert!(short[(2, 2)] > long[(2, 2)]);
        assert!((long[(5, 5)] - 1.0 / (0.01 * 0.01)).abs() < 1e-6);
    }
}
