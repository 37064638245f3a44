//! Windowed stereo bundle adjustment: the poses of the last keyframes and the points they
//! observe, refined jointly on the reprojection errors of rectified stereo observations.
//!
//! Not in the RotROCC paper (its estimate is frame-to-frame); this is the refinement the stereo
//! issue asks for on top of it, built as the field's standard tools build it (Triggs et al.,
//! *Bundle Adjustment — A Modern Synthesis*, 2000; ORB-SLAM's local BA; basalt's window):
//!
//! * **Unknowns.** Each window frame `k` has `cam_from_world` `T_k` (updated on the left,
//!   `T_k ← exp(ξ_k) · T_k`, `ξ = (v, ω)` as [`visnav_core::se3::se3_exp`]); each point a world
//!   position `X_j` (metres). The first [`BaConfig::fixed_frames`] frames are held fixed: the
//!   gauge (6 DoF) and the link to the trajectory before the window, instead of marginalising
//!   the frames that leave it (a fixed-window approximation: the prior of the dropped frames is
//!   not carried).
//! * **The rig's disparity offset** (optional, [`BaConfig::estimate_right_cx_offset`]): one more
//!   unknown shared by the whole window, the right principal point's column offset `ε`
//!   ([`visnav_core::StereoCamera::right_cx_offset_px`], `û_r` below shifted by it), kept as the last row of
//!   the reduced camera system. Observable because a wrong `ε` moves near and far points by
//!   different shares of their depth, which no rigid motion explains.
//! * **Residual** of an observation of point `j` in frame `k` ([`residual::StereoResidual`]):
//!   `r = (u_l − fx·x/z − cx, v_l − fy·y/z − cy, u_r − fx·(x − b)/z − cx)` with
//!   `(x, y, z) = T_k · X_j` in the left camera, `b` the baseline — the left reprojection error
//!   and the right one's horizontal part (rectified: the right row equals the left one). An
//!   observation without a right match has the first two components only.
//! * **Weights.** Each component is divided by the observation's standard deviation in pixels
//!   (the left pixel's, and the right column's for the third),
//!   then a Huber kernel ([`BaConfig::huber_px`], on the whitened norm) down-weights outliers by
//!   iteratively reweighted least squares. Huber alone keeps a linear pull of gross outliers, so
//!   as in ORB-SLAM's local BA the solve runs in [`BaConfig::rounds`] rounds: after each, the
//!   observations whose whitened squared error exceeds [`BaConfig::outlier_chi2`] are dropped
//!   for the next. A point behind the camera has no residual: its observation costs what one at
//!   the threshold costs, `ρ(outlier_chi2)` (a step that moves a well-measured point there is
//!   refused; with no cost at all it would have been free), and it is an outlier.
//! * **Solver.** Levenberg–Marquardt on the normal equations. The point block is 3x3
//!   block-diagonal, so points are eliminated per point (Schur complement) and the reduced
//!   camera system, `6·(K − fixed)` unknowns, is dense and solved by Cholesky (nalgebra);
//!   points are then back-substituted. Analytic Jacobians are checked against finite differences
//!   in the tests.
//!
//! [`WindowBa::solve`] returns a [`BaReport`] with the cost before and after, the iterations and
//! the observations the kernel down-weighted.

pub mod covariance;
mod problem;
pub mod residual;
mod schur;

pub use covariance::CovarianceScale;
pub use problem::{BaConfig, BaError, BaReport, Observation, WindowBa, huber_rho, huber_weight};
pub use residual::StereoResidual;

impl WindowBa {
    /// Refines the free poses and all points in place.
    ///
    /// # Errors
    /// An observation with an index outside the window, or nothing to adjust.
    pub fn solve(&mut self, config: &BaConfig) -> Result<BaReport, BaError> {
        self.check(config)?;
        let mut active = vec![true; self.observations.len()];
        let initial_cost = self.cost(config, &active);
        let mut iterations = 0;
        let mut cost = initial_cost;
        for round in 0..config.rounds.max(1) {
            if round > 0 {
                for (a, o) in active.iter_mut().zip(&self.observations) {
                    *a = *a && !self.is_outlier(o, config);
                }
            }
            let (c, it) = self.levenberg_marquardt(config, &active);
            cost = c;
            iterations += it;
        }
        let outliers = self
            .observations
            .iter()
            .filter(|o| self.is_outlier(o, config))
            .count();
        Ok(BaReport {
            initial_cost,
            final_cost: cost,
            iterations,
            outliers,
        })
    }

    /// One round: Levenberg–Marquardt on the active observations; the final cost and the
    /// iterations.
    fn levenberg_marquardt(&mut self, config: &BaConfig, active: &[bool]) -> (f64, usize) {
        let mut lambda = config.initial_lambda;
        let mut cost = self.cost(config, active);
        let mut iterations = 0;
        while iterations < config.max_iterations {
            iterations += 1;
            let system = schur::NormalEquations::build(self, config, active);
            let Some(step) = system.solve(lambda) else {
                lambda *= 10.0;
                continue;
            };
            let before = (
                self.cam_from_world.clone(),
                self.points_w.clone(),
                self.rig.right_cx_offset_px,
            );
            self.apply(&step, config.fixed_frames);
            let new_cost = self.cost(config, active);
            if new_cost < cost {
                let decrease = (cost - new_cost) / cost.max(f64::MIN_POSITIVE);
                cost = new_cost;
                lambda = (lambda * 0.3).max(1e-12);
                if decrease < config.min_relative_decrease {
                    break;
                }
            } else {
                (
                    self.cam_from_world,
                    self.points_w,
                    self.rig.right_cx_offset_px,
                ) = before;
                lambda *= 10.0;
                if lambda > 1e8 {
                    break;
                }
            }
        }
        (cost, iterations)
    }

    fn check(&self, config: &BaConfig) -> Result<(), BaError> {
        for (index, o) in self.observations.iter().enumerate() {
            if o.frame >= self.cam_from_world.len() || o.point >= self.points_w.len() {
                return Err(BaError::BadIndex {
                    index,
                    frame: o.frame,
                    point: o.point,
                });
            }
        }
        if self.observations.is_empty() || config.fixed_frames >= self.cam_from_world.len() {
            return Err(BaError::Empty {
                frames: self.cam_from_world.len(),
                fixed: config.fixed_frames,
                observations: self.observations.len(),
            });
        }
        Ok(())
    }

    /// The squared whitened residual norm of one observation; `None` when its point is not in
    /// front of the camera (no projection).
    fn whitened_sq(&self, o: &Observation) -> Option<f64> {
        StereoResidual::new(&self.rig, o)
            .value(&self.cam_from_world[o.frame], &self.points_w[o.point])
            .map(|r| r.norm_squared())
    }

    /// Whether an observation is an outlier: beyond `outlier_chi2`, or its point behind the
    /// camera.
    fn is_outlier(&self, o: &Observation, config: &BaConfig) -> bool {
        self.whitened_sq(o).is_none_or(|s| s > config.outlier_chi2)
    }

    /// The robust cost ½ Σ ρ(‖r̃‖²) (Huber) of the active observations. An observation whose
    /// point is behind its camera counts as an outlier at the threshold, `ρ(outlier_chi2)`:
    /// moving a well-measured point behind a camera raises the cost (the step is refused), where
    /// a zero would have let a step drop the observation's cost for free, while an observation
    /// already beyond the threshold may still go there (it is dropped after the round).
    #[must_use]
    pub fn cost(&self, config: &BaConfig, active: &[bool]) -> f64 {
        self.observations
            .iter()
            .zip(active)
            .filter(|(_, a)| **a)
            .map(|(o, _)| {
                let s = self.whitened_sq(o).unwrap_or(config.outlier_chi2);
                0.5 * huber_rho(s, config.huber_px)
            })
            .sum()
    }

    /// Applies a step: `T_k ← exp(ξ_k) T_k` for the free frames, `X_j ← X_j + δ_j`.
    fn apply(&mut self, step: &schur::Step, fixed: usize) {
        for (k, xi) in step.poses.iter().enumerate() {
            let t = &mut self.cam_from_world[fixed + k];
            *t = visnav_core::se3::se3_exp(xi) * *t;
            // a product of unit quaternions drifts off the unit sphere over many steps
            t.rotation = nalgebra::UnitQuaternion::new_normalize(t.rotation.into_inner());
        }
        for (p, d) in self.points_w.iter_mut().zip(&step.points) {
            *p += d;
        }
        self.rig.right_cx_offset_px += step.offset_px;
    }
}
