//! RotROCC motion estimation (Buczko & Willert, §V-B): the rotation phase (eq. 25–26), the
//! rotation compensation (eq. 27–28) and the translation phase with the decoupled normalized
//! reprojection error (DNRE, eq. 24, 29–30), plus the paper's reference outlier rules
//! (eq. 31, 32) and the low-speed rule.
//!
//! Frames and units: each [`Observation`] holds a point `p_in_prev` triangulated in the left camera
//! at t-1 (metres) and its measured pixels in the left and right images at t. The estimated motion
//! is `cur_from_prev` (maps points of the t-1 camera into the t camera), so the predicted left pixel
//! is `π(R p + t)` and the right one `π(R p + t − (b, 0, 0))` with baseline `b`. The paper writes
//! the same error with the roles of t and t-1 exchanged (eq. 2).
//!
//! Perturbation convention of the 6-DoF Gauss–Newton: `cur_from_prev ← exp(δ) · cur_from_prev`
//! with `δ = (v, ω)` (translation first, as [`visnav_core::se3::se3_exp`]), so
//! `∂q/∂δ = [I | −[q]×]` for `q = cur_from_prev · p`.

use nalgebra::{
    Matrix2x3, Matrix3, Matrix6, Point2, SMatrix, SVector, Translation3, Vector2, Vector3, Vector6,
};
use serde::{Deserialize, Serialize};
use visnav_core::se3::{se3_exp, skew};
use visnav_core::{Pose, StereoCamera};

use crate::RelativeMotion;
use crate::stereo::config::{OutlierMode, PhaseConfig, StereoConfig};

/// One tracked feature: its 3-D point at t-1 and its measurements at t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The point triangulated at t-1, in the left camera frame at t-1, metres.
    pub p_in_prev: Vector3<f64>,
    /// Measured left pixel at t.
    pub left_px: Point2<f64>,
    /// Measured right pixel at t.
    pub right_px: Point2<f64>,
    /// Row offset `v_right − v_left` measured at t-1 (pixels; 0 for a perfectly rectified rig).
    /// The right prediction is shifted by it, so a residual vertical misalignment of the rig does
    /// not bias the pitch.
    pub right_row_offset_px: f64,
}

/// Result of [`estimate_motion`].
#[derive(Debug, Clone, PartialEq)]
pub struct MotionEstimate {
    /// The estimated motion t-1 → t (computed as its `cur_from_prev`).
    pub motion: RelativeMotion,
    /// Features kept by the rotation phase.
    pub rotation_inliers: usize,
    /// Iterations of the rotation phase.
    pub rotation_iterations: usize,
    /// Features kept by the translation phase (0 when skipped).
    pub translation_inliers: usize,
    /// Iterations of the translation phase (0 when skipped).
    pub translation_iterations: usize,
    /// Whether the low-speed rule skipped phases 2 and 3.
    pub low_speed: bool,
    /// Median rotation-compensated flow (eq. 28) over all features, pixels.
    pub median_translation_flow_px: f64,
    /// Final inlier flags, one per observation (translation set, or rotation set when skipped).
    pub inliers: Vec<bool>,
}

/// Per-feature diagnostics for a motion hypothesis (used by tests and plots).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureErrors {
    /// Reprojection error (eq. 2), RMS over the cameras used, pixels.
    pub reprojection_px: f64,
    /// Rotation-compensated flow (eq. 28), RMS over the cameras used, pixels.
    pub translation_flow_px: f64,
    /// Decoupled normalized reprojection error (eq. 24), unitless.
    pub dnre: f64,
}

/// Left (and right) pixel residuals `π(q) − x` with Jacobians with respect to `q` (the point in
/// the current left camera); `None` when the point is not in front of a camera.
struct Residual {
    r: [Vector2<f64>; 2],
    j_q: [Matrix2x3<f64>; 2],
    cams: usize,
}

fn project_with_jacobian(
    rig: &StereoCamera,
    q: &Vector3<f64>,
    offset_x: f64,
) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
    let (x, y, z) = (q.x - offset_x, q.y, q.z);
    if z < 1e-3 {
        return None;
    }
    let c = &rig.left;
    let iz = 1.0 / z;
    let u = Vector2::new(c.fx * x * iz + c.cx, c.fy * y * iz + c.cy);
    let j = Matrix2x3::new(
        c.fx * iz,
        0.0,
        -c.fx * x * iz * iz,
        0.0,
        c.fy * iz,
        -c.fy * y * iz * iz,
    );
    Some((u, j))
}

fn residual(
    rig: &StereoCamera,
    obs: &Observation,
    q: &Vector3<f64>,
    use_right: bool,
) -> Option<Residual> {
    let (ul, jl) = project_with_jacobian(rig, q, 0.0)?;
    let rl = ul - obs.left_px.coords;
    if use_right {
        let (ur, jr) = project_with_jacobian(rig, q, rig.baseline_m)?;
        Some(Residual {
            r: [
                rl,
                ur + Vector2::new(rig.right_cx_offset_px, obs.right_row_offset_px)
                    - obs.right_px.coords,
            ],
            j_q: [jl, jr],
            cams: 2,
        })
    } else {
        Some(Residual {
            r: [rl, Vector2::zeros()],
            j_q: [jl, Matrix2x3::zeros()],
            cams: 1,
        })
    }
}

/// Reprojection error of one feature under `cur_from_prev` (eq. 2): RMS over the cameras of the
/// pixel distance; infinite when the point falls behind a camera.
#[must_use]
pub fn reprojection_error(
    rig: &StereoCamera,
    obs: &Observation,
    cur_from_prev: &Pose,
    use_right: bool,
) -> f64 {
    let q = cur_from_prev.rotation * obs.p_in_prev + cur_from_prev.translation.vector;
    residual(rig, obs, &q, use_right).map_or(f64::INFINITY, |r| {
        let s: f64 = r.r[..r.cams].iter().map(Vector2::norm_squared).sum();
        (s / r.cams as f64).sqrt()
    })
}

/// The reprojection error, the rotation-compensated flow (eq. 28) and their ratio, the DNRE
/// (eq. 24), of one feature under `cur_from_prev`, compensating with its rotation.
#[must_use]
pub fn feature_errors(
    rig: &StereoCamera,
    obs: &Observation,
    cur_from_prev: &Pose,
    use_right: bool,
) -> FeatureErrors {
    let reprojection_px = reprojection_error(rig, obs, cur_from_prev, use_right);
    let rotated = cur_from_prev.rotation * obs.p_in_prev;
    let flow = residual(rig, obs, &rotated, use_right).map_or(f64::INFINITY, |r| {
        let s: f64 = r.r[..r.cams].iter().map(Vector2::norm_squared).sum();
        (s / r.cams as f64).sqrt()
    });
    FeatureErrors {
        reprojection_px,
        translation_flow_px: flow,
        dnre: reprojection_px / flow.max(1e-9),
    }
}

/// Gauss–Newton on SE(3) over the features flagged in `mask` (eq. 25), starting from `pose`.
/// Returns `None` when fewer than 3 features project or the normal equations are singular.
#[must_use]
pub fn solve_pose(
    rig: &StereoCamera,
    obs: &[Observation],
    mask: &[bool],
    pose: &Pose,
    steps: usize,
    use_right: bool,
) -> Option<Pose> {
    let mut pose = *pose;
    for _ in 0..steps {
        let mut h = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        let mut used = 0usize;
        for (o, _) in obs.iter().zip(mask).filter(|(_, m)| **m) {
            let q = pose.rotation * o.p_in_prev + pose.translation.vector;
            let Some(res) = residual(rig, o, &q, use_right) else {
                continue;
            };
            let mut dq = SMatrix::<f64, 3, 6>::zeros();
            dq.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&Matrix3::identity());
            dq.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&q)));
            for c in 0..res.cams {
                let j = res.j_q[c] * dq;
                h += j.transpose() * j;
                g += j.transpose() * res.r[c];
            }
            used += 1;
        }
        if used < 3 {
            return None;
        }
        let delta = damped_solve(h, &g)?;
        pose = se3_exp(&delta) * pose;
        if delta.norm() < 1e-10 {
            break;
        }
    }
    Some(pose)
}

/// The Gauss–Newton step `-H⁻¹ g` with a tiny Levenberg damping (1e-9 of the trace) that keeps
/// the solve defined for near-degenerate sets; `None` when `H` is not positive definite or the
/// step is not finite.
fn damped_solve<const N: usize>(
    mut h: SMatrix<f64, N, N>,
    g: &SVector<f64, N>,
) -> Option<SVector<f64, N>> {
    let damping = 1e-9 * h.trace().max(1e-12);
    for i in 0..N {
        h[(i, i)] += damping;
    }
    let delta = h.cholesky()?.solve(&(-g));
    delta.iter().all(|v| v.is_finite()).then_some(delta)
}

/// Translation-only Gauss–Newton with the rotation fixed (eq. 27, 29): minimises the reprojection
/// errors of the rotated points `R p` over `t`.
#[must_use]
pub fn solve_translation(
    rig: &StereoCamera,
    obs: &[Observation],
    mask: &[bool],
    pose: &Pose,
    steps: usize,
    use_right: bool,
) -> Option<Pose> {
    let mut t = pose.translation.vector;
    let rotated: Vec<Vector3<f64>> = obs.iter().map(|o| pose.rotation * o.p_in_prev).collect();
    for _ in 0..steps {
        let mut h = Matrix3::<f64>::zeros();
        let mut g = Vector3::<f64>::zeros();
        let mut used = 0usize;
        for ((o, rp), _) in obs.iter().zip(&rotated).zip(mask).filter(|(_, m)| **m) {
            let q = rp + t;
            let Some(res) = residual(rig, o, &q, use_right) else {
                continue;
            };
            for c in 0..res.cams {
                let j = res.j_q[c];
                h += j.transpose() * j;
                g += j.transpose() * res.r[c];
            }
            used += 1;
        }
        if used < 2 {
            return None;
        }
        let delta = damped_solve(h, &g)?;
        t += delta;
        if delta.norm() < 1e-12 {
            break;
        }
    }
    Some(Pose::from_parts(Translation3::from(t), pose.rotation))
}

/// The rule that shrinks a feature set from its errors.
#[derive(Debug, Clone, Copy)]
enum Rule {
    /// Eq. 26 / 30: keep `e < max(b-th largest, limit)`.
    Rank { b: usize, limit: f64 },
    /// Eq. 31: keep `e − μ < 1.5 σ`.
    Mean,
    /// Eq. 32: keep `e < 3² μ`.
    Std,
}

/// Applies `rule` to the features currently in `mask` (removal only). Returns whether the set
/// changed; refuses (returns false, mask unchanged) a step that would leave fewer than `min_keep`.
fn shrink(mask: &mut [bool], errors: &[f64], rule: Rule, min_keep: usize) -> bool {
    let current: Vec<f64> = errors
        .iter()
        .zip(mask.iter())
        .filter(|(_, m)| **m)
        .map(|(e, _)| *e)
        .collect();
    let n = current.len();
    if n == 0 {
        return false;
    }
    let threshold_ok: Box<dyn Fn(f64) -> bool> = match rule {
        Rule::Rank { b, limit } => {
            let mut sorted: Vec<f64> = current.iter().copied().filter(|e| e.is_finite()).collect();
            sorted.sort_by(|a, b| b.total_cmp(a));
            let bth = sorted
                .get(b.min(sorted.len()).saturating_sub(1))
                .copied()
                .unwrap_or(limit);
            let thresh = bth.max(limit);
            Box::new(move |e| e < thresh)
        }
        Rule::Mean => {
            let finite: Vec<f64> = current.iter().copied().filter(|e| e.is_finite()).collect();
            let m = finite.len().max(2) as f64;
            let mu = finite.iter().sum::<f64>() / m;
            let var = finite.iter().map(|e| (e - mu) * (e - mu)).sum::<f64>() / (m - 1.0);
            let sigma = var.sqrt();
            Box::new(move |e| e - mu < 1.5 * sigma)
        }
        Rule::Std => {
            let finite: Vec<f64> = current.iter().copied().filter(|e| e.is_finite()).collect();
            let mu = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
            Box::new(move |e| e < 9.0 * mu)
        }
    };
    let new: Vec<bool> = mask
        .iter()
        .zip(errors)
        .map(|(m, e)| *m && e.is_finite() && threshold_ok(*e))
        .collect();
    let kept = new.iter().filter(|m| **m).count();
    if kept < min_keep || kept == n {
        return false;
    }
    mask.copy_from_slice(&new);
    true
}

fn rule_for(mode: OutlierMode, phase: &PhaseConfig) -> Rule {
    match mode {
        OutlierMode::Dnre | OutlierMode::Re => Rule::Rank {
            b: phase.b,
            limit: phase.fixed_limit,
        },
        OutlierMode::Mean => Rule::Mean,
        OutlierMode::Std => Rule::Std,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Estimates the motion t-1 → t from the observations with the RotROCC scheme (§V-B), starting
/// from `init` (the previous frame's motion). `None` when the least squares fail (too few
/// features, degenerate geometry).
#[must_use]
pub fn estimate_motion(
    rig: &StereoCamera,
    obs: &[Observation],
    init: &RelativeMotion,
    config: &StereoConfig,
) -> Option<MotionEstimate> {
    // the Gauss–Newton works on `cur_from_prev` (see the module docs)
    let init = init.cur_from_prev();
    let use_right = config.use_right_reprojection;
    let min_keep = config.min_features.min(obs.len()).max(6);
    if obs.len() < 6 {
        return None;
    }
    // Phase 1: rotation phase on the reprojection error (eq. 25–26).
    let rot_rule = rule_for(config.outlier, &config.rotation);
    let mut mask_r = vec![true; obs.len()];
    let mut pose_r = init;
    let mut iterations_r = 0;
    for i in 0..config.rotation.max_iterations {
        iterations_r = i + 1;
        pose_r = solve_pose(
            rig,
            obs,
            &mask_r,
            &pose_r,
            config.rotation.gauss_newton_steps,
            use_right,
        )?;
        let errors: Vec<f64> = obs
            .iter()
            .map(|o| reprojection_error(rig, o, &pose_r, use_right))
            .collect();
        if !shrink(&mut mask_r, &errors, rot_rule, min_keep) {
            break;
        }
    }
    let rotation_inliers = mask_r.iter().filter(|m| **m).count();
    // Rotation compensation (eq. 27–28): the flow left when the rotation is removed.
    let errors_r: Vec<FeatureErrors> = obs
        .iter()
        .map(|o| feature_errors(rig, o, &pose_r, use_right))
        .collect();
    let median_flow = median(errors_r.iter().map(|e| e.translation_flow_px).collect());
    let low_speed = median_flow < config.low_speed_flow_px;
    if config.outlier != OutlierMode::Dnre || low_speed {
        return Some(MotionEstimate {
            motion: RelativeMotion::from_cur_from_prev(pose_r),
            rotation_inliers,
            rotation_iterations: iterations_r,
            translation_inliers: 0,
            translation_iterations: 0,
            low_speed,
            median_translation_flow_px: median_flow,
            inliers: mask_r,
        });
    }
    // Phase 3: translation only, DNRE outlier rejection (eq. 29–30), from the rotation phase's
    // inliers and the previous frame's translation. Starting from the full set let gross mistracks
    // in: their large flow divides their DNRE down (eq. 24), so they survived while good far
    // points were dropped, and on fast turns the translation converged metres off.
    let flows: Vec<f64> = errors_r
        .iter()
        .map(|e| e.translation_flow_px.max(1e-9))
        .collect();
    let trans_rule = Rule::Rank {
        b: config.translation.b,
        limit: config.translation.fixed_limit,
    };
    let mut mask_t = mask_r.clone();
    let mut pose_t = Pose::from_parts(init.translation, pose_r.rotation);
    let mut iterations_t = 0;
    for j in 0..config.translation.max_iterations {
        iterations_t = j + 1;
        pose_t = solve_translation(
            rig,
            obs,
            &mask_t,
            &pose_t,
            config.translation.gauss_newton_steps,
            use_right,
        )?;
        let dnre: Vec<f64> = obs
            .iter()
            .zip(&flows)
            .map(|(o, f)| reprojection_error(rig, o, &pose_t, use_right) / f)
            .collect();
        if !shrink(&mut mask_t, &dnre, trans_rule, min_keep) {
            break;
        }
    }
    Some(MotionEstimate {
        motion: RelativeMotion::from_cur_from_prev(pose_t),
        rotation_inliers,
        rotation_iterations: iterations_r,
        translation_inliers: mask_t.iter().filter(|m| **m).count(),
        translation_iterations: iterations_t,
        low_speed,
        median_translation_flow_px: median_flow,
        inliers: mask_t,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, UnitQuaternion};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use visnav_core::PinholeCamera;

    pub(crate) fn rig() -> StereoCamera {
        StereoCamera::new(PinholeCamera::kitti_default(), 0.537).unwrap()
    }

    /// Random points in view at t-1 and their exact projections at t under `cur_from_prev`.
    pub(crate) fn scene(cur_from_prev: &Pose, n: usize, seed: u64) -> Vec<Observation> {
        let rig = rig();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut out = Vec::new();
        while out.len() < n {
            let px = Point2::new(
                rng.random_range(20.0..1220.0),
                rng.random_range(20.0..356.0),
            );
            let z = rng.random_range(4.0..60.0);
            let p = rig.left.unproject(&px, z);
            let q = cur_from_prev * p;
            let (Some(l), Some(r)) = (rig.left.project(&q), rig.project_right(&q)) else {
                continue;
            };
            if !rig.left.contains(&l, 0.0) {
                continue;
            }
            out.push(Observation {
                p_in_prev: p.coords,
                left_px: l,
                right_px: r,
                right_row_offset_px: 0.0,
            });
        }
        out
    }

    fn motion(t: [f64; 3], w: [f64; 3]) -> Pose {
        Pose::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(Vector3::new(w[0], w[1], w[2])),
        )
    }

    fn pose_error(a: &Pose, b: &Pose) -> (f64, f64) {
        let d = a.inverse() * b;
        (d.translation.vector.norm(), d.rotation.angle())
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let rig = rig();
        let pose = motion([0.1, -0.05, 1.2], [0.01, 0.03, -0.02]);
        let o = scene(&pose, 1, 3)[0];
        let o = Observation {
            left_px: o.left_px + Vector2::new(0.7, -0.4),
            ..o
        };
        let q = pose.rotation * o.p_in_prev + pose.translation.vector;
        let res = residual(&rig, &o, &q, true).unwrap();
        let mut dq = SMatrix::<f64, 3, 6>::zeros();
        dq.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        dq.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&q)));
        for c in 0..2 {
            let analytic = res.j_q[c] * dq;
            for k in 0..6 {
                let h = 1e-6;
                let mut d = Vector6::zeros();
                d[k] = h;
                let plus = se3_exp(&d) * pose;
                d[k] = -h;
                let minus = se3_exp(&d) * pose;
                let rp = residual(&rig, &o, &(plus * Point3::from(o.p_in_prev)).coords, true)
                    .unwrap()
                    .r[c];
                let rm = residual(&rig, &o, &(minus * Point3::from(o.p_in_prev)).coords, true)
                    .unwrap()
                    .r[c];
                let numeric = (rp - rm) / (2.0 * h);
                let col = analytic.column(k);
                assert!(
                    (numeric - col).norm() < 1e-4 * (1.0 + col.norm()),
                    "cam {c} dof {k}: {numeric} vs {col}"
                );
            }
        }
    }

    #[test]
    fn pure_rotation_recovered() {
        let truth = motion([0.0, 0.0, 0.0], [0.004, 0.03, -0.002]);
        let obs = scene(&truth, 200, 1);
        let cfg = StereoConfig::default();
        let est = estimate_motion(&rig(), &obs, &RelativeMotion::identity(), &cfg).unwrap();
        let (dt, dr) = pose_error(&truth, &est.motion.cur_from_prev());
        assert!(dt < 1e-6 && dr < 1e-8, "dt {dt} dr {dr}");
        assert!(
            est.low_speed,
            "no translation flow: the low-speed rule applies"
        );
    }

    #[test]
    fn pure_translation_recovered() {
        let truth = motion([0.05, -0.02, 1.3], [0.0, 0.0, 0.0]);
        let obs = scene(&truth, 200, 2);
        let est = estimate_motion(
            &rig(),
            &obs,
            &RelativeMotion::identity(),
            &StereoConfig::default(),
        )
        .unwrap();
        let (dt, dr) = pose_error(&truth, &est.motion.cur_from_prev());
        assert!(dt < 1e-6 && dr < 1e-8, "dt {dt} dr {dr}");
        assert!(!est.low_speed);
        assert_eq!(est.translation_inliers, 200);
    }

    #[test]
    fn full_motion_recovered_in_every_mode() {
        let truth = motion([0.1, 0.02, 1.1], [0.01, -0.05, 0.004]);
        let obs = scene(&truth, 300, 3);
        for mode in [
            OutlierMode::Dnre,
            OutlierMode::Re,
            OutlierMode::Mean,
            OutlierMode::Std,
        ] {
            let cfg = StereoConfig {
                outlier: mode,
                ..StereoConfig::default()
            };
            let est = estimate_motion(&rig(), &obs, &RelativeMotion::identity(), &cfg).unwrap();
            let (dt, dr) = pose_error(&truth, &est.motion.cur_from_prev());
            assert!(dt < 1e-6 && dr < 1e-8, "{mode:?}: dt {dt} dr {dr}");
        }
    }

    /// Paper Fig. 4–5: for a correct rotation and a translation hypothesis that is 5 % off, the DNRE
    /// of ideal features is almost the same constant |E − 1| everywhere, while the reprojection
    /// error varies strongly with the feature position.
    #[test]
    fn dnre_is_invariant_to_feature_position() {
        let truth = motion([0.0, 0.0, 1.4], [0.005, 0.045, 0.0025]);
        let obs = scene(&truth, 500, 4);
        let wrong = Pose::from_parts(
            Translation3::from(truth.translation.vector * 1.05),
            truth.rotation,
        );
        let errs: Vec<FeatureErrors> = obs
            .iter()
            .map(|o| feature_errors(&rig(), o, &wrong, false))
            .collect();
        let spread = |v: Vec<f64>| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
            (m, s / m)
        };
        let (m_dnre, cv_dnre) = spread(errs.iter().map(|e| e.dnre).collect());
        let (_, cv_re) = spread(errs.iter().map(|e| e.reprojection_px).collect());
        assert!((m_dnre - 0.05).abs() < 0.01, "mean DNRE {m_dnre}");
        assert!(cv_dnre < 0.1, "DNRE coefficient of variation {cv_dnre}");
        assert!(cv_re > 5.0 * cv_dnre, "RE cv {cv_re} vs DNRE cv {cv_dnre}");
    }

    #[test]
    fn fewer_than_six_features_fail_cleanly() {
        let truth = motion([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]);
        let obs = scene(&truth, 5, 5);
        assert!(
            estimate_motion(
                &rig(),
                &obs,
                &RelativeMotion::identity(),
                &StereoConfig::default()
            )
            .is_none()
        );
    }
}
