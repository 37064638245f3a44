//! Scoring one or several (ground truth, estimate) pairs at once: the KITTI metric pooled over
//! all segments of all sequences, ATE after SE(3) and Sim(3) alignment, and RPE.

use serde::{Deserialize, Serialize};

use crate::PoseMatrix;

use crate::align::{AteResult, ate};
use crate::associate::{Association, associate_by_timestamp};
use crate::error::{EvalError, Result};
use crate::kitti::{BinScore, KittiMetricConfig, SegmentError, kitti_score, sequence_errors};
use crate::rpe::{RpeResult, pool, rpe};

/// Settings of [`evaluate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// The KITTI metric (lengths 100..800 m, step 10 frames, 0.1 s a frame).
    pub kitti: KittiMetricConfig,
    /// An RPE offset in frames reported besides the frame-to-frame RPE (Δ = 1); `None` for none.
    pub rpe_delta_frames: Option<usize>,
    /// Make a length mismatch between estimate and ground truth an error instead of scoring the
    /// common prefix with a warning (default false).
    pub strict: bool,
    /// Largest timestamp difference for matching frames by timestamp, seconds (default 0.01).
    pub max_time_diff_s: f64,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            kitti: KittiMetricConfig::default(),
            rpe_delta_frames: None,
            strict: false,
            max_time_diff_s: 0.01,
        }
    }
}

impl EvalConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// An invalid KITTI config, an RPE offset of 0, or a negative or non-finite time tolerance.
    pub fn validate(&self) -> Result<()> {
        self.kitti.validate()?;
        if self.rpe_delta_frames == Some(0) {
            return Err(EvalError::InvalidConfig {
                field: "rpe_delta_frames",
                value: "0".into(),
                expected: "at least 1 frame",
            });
        }
        if !(self.max_time_diff_s.is_finite() && self.max_time_diff_s >= 0.0) {
            return Err(EvalError::InvalidConfig {
                field: "max_time_diff_s",
                value: self.max_time_diff_s.to_string(),
                expected: "a finite non-negative time in seconds",
            });
        }
        Ok(())
    }
}

/// One (ground truth, estimate) pair to score, poses `world_from_cam` as 4x4 matrices (see
/// [`crate::pose_matrices`] for [`visnav_core::Pose`]s).
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryPair<'a> {
    /// Ground-truth poses.
    pub gt: &'a [PoseMatrix],
    /// Estimated poses.
    pub est: &'a [PoseMatrix],
    /// Ground-truth timestamps in seconds, if known.
    pub gt_timestamps: Option<&'a [f64]>,
    /// Estimate timestamps in seconds, if known.
    pub est_timestamps: Option<&'a [f64]>,
}

impl<'a> TrajectoryPair<'a> {
    /// A pair matched by frame index.
    #[must_use]
    pub fn by_index(gt: &'a [PoseMatrix], est: &'a [PoseMatrix]) -> Self {
        Self {
            gt,
            est,
            gt_timestamps: None,
            est_timestamps: None,
        }
    }
}

/// The frames of a pair matched for scoring.
#[derive(Debug, Clone, PartialEq)]
pub struct MatchedPoses {
    /// Ground-truth poses of the matched frames.
    pub gt: Vec<PoseMatrix>,
    /// Estimated poses of the matched frames.
    pub est: Vec<PoseMatrix>,
    /// How they were matched.
    pub association: Association,
}

/// Matches the frames of a pair: by timestamp (nearest within `max_time_diff_s`) when both carry
/// timestamps, else by index. Frames without a partner are dropped with a `log::warn!`, or make
/// an error when `strict`.
///
/// # Errors
/// [`EvalError::LengthMismatch`] in strict mode, [`EvalError::NothingToScore`] for an empty
/// trajectory, mismatched timestamp counts, or no matching timestamps.
pub fn match_poses(
    pair: &TrajectoryPair<'_>,
    config: &EvalConfig,
    sequence: usize,
) -> Result<MatchedPoses> {
    let nothing = |message: String| EvalError::NothingToScore { sequence, message };
    if pair.gt.is_empty() || pair.est.is_empty() {
        return Err(nothing(format!(
            "empty trajectory ({} ground-truth poses, {} estimated poses)",
            pair.gt.len(),
            pair.est.len()
        )));
    }
    let mismatch = EvalError::LengthMismatch {
        sequence,
        estimate: pair.est.len(),
        ground_truth: pair.gt.len(),
    };
    if let (Some(tg), Some(te)) = (pair.gt_timestamps, pair.est_timestamps) {
        if tg.len() != pair.gt.len() || te.len() != pair.est.len() {
            return Err(nothing("timestamps and poses differ in count".into()));
        }
        let m = associate_by_timestamp(tg, te, config.max_time_diff_s);
        if m.is_empty() {
            return Err(nothing(format!(
                "no estimate timestamp within {} s of a ground-truth timestamp",
                config.max_time_diff_s
            )));
        }
        if m.len() != pair.gt.len() || m.len() != pair.est.len() {
            if config.strict {
                return Err(mismatch);
            }
            log::warn!(
                "sequence {sequence}: {} of {} estimated and {} ground-truth poses matched by timestamp; scoring those",
                m.len(),
                pair.est.len(),
                pair.gt.len()
            );
        }
        return Ok(MatchedPoses {
            gt: m.iter().map(|&(g, _)| pair.gt[g]).collect(),
            est: m.iter().map(|&(_, e)| pair.est[e]).collect(),
            association: Association::Timestamp,
        });
    }
    let n = pair.gt.len().min(pair.est.len());
    if pair.gt.len() != pair.est.len() {
        if config.strict {
            return Err(mismatch);
        }
        log::warn!(
            "sequence {sequence}: the estimate has {} poses, the ground truth {}; scoring the first {n}",
            pair.est.len(),
            pair.gt.len()
        );
    }
    Ok(MatchedPoses {
        gt: pair.gt[..n].to_vec(),
        est: pair.est[..n].to_vec(),
        association: Association::Index,
    })
}

/// The scores of one pair.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SequenceReport {
    /// Index of the pair, from 0.
    pub sequence: usize,
    /// Poses in the ground truth.
    pub gt_poses: usize,
    /// Poses in the estimate.
    pub est_poses: usize,
    /// Poses scored (matched frames).
    pub scored_poses: usize,
    /// How the frames were matched.
    pub association: Association,
    /// Ground-truth path length, metres.
    pub path_length_m: f64,
    /// KITTI translation error of this sequence, %.
    pub t_err_percent: f64,
    /// KITTI rotation error of this sequence, deg/100 m.
    pub r_err_deg_per_100m: f64,
    /// KITTI segments of this sequence.
    pub segments: usize,
    /// Per-length breakdown of this sequence.
    pub per_length: Vec<BinScore>,
    /// Per-speed breakdown of this sequence.
    pub per_speed: Vec<BinScore>,
    /// ATE after SE(3) alignment (`None` when degenerate).
    pub ate_se3: Option<AteResult>,
    /// ATE after Sim(3) alignment (`None` when degenerate).
    pub ate_sim3: Option<AteResult>,
    /// Frame-to-frame RPE.
    pub rpe: Option<RpeResult>,
    /// RPE at the configured extra offset.
    pub rpe_delta: Option<RpeResult>,
}

/// The scores of all pairs, with the KITTI metric pooled over all segments.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// Mean translation error over all segments of all sequences, % (NaN/null without segments).
    pub t_err_percent: f64,
    /// Mean rotation error over all segments of all sequences, deg/100 m.
    pub r_err_deg_per_100m: f64,
    /// Number of segments.
    pub segments: usize,
    /// Segment lengths used, metres.
    pub lengths_m: Vec<f64>,
    /// Pooled per-length breakdown (`key` = length, m).
    pub per_length: Vec<BinScore>,
    /// Pooled per-speed breakdown (`key` = speed, m/s).
    pub per_speed: Vec<BinScore>,
    /// ATE RMSE after SE(3) alignment (each sequence aligned alone, RMSE over all poses), m.
    pub ate_se3_m: Option<f64>,
    /// ATE RMSE after Sim(3) alignment, m.
    pub ate_sim3_m: Option<f64>,
    /// Frame-to-frame RPE, pooled.
    pub rpe: Option<RpeResult>,
    /// RPE at the extra offset, pooled.
    pub rpe_delta: Option<RpeResult>,
    /// Per-sequence scores.
    pub sequences: Vec<SequenceReport>,
    /// Every segment's error (not serialised).
    #[serde(skip)]
    pub segment_errors: Vec<SegmentError>,
    /// The matched frames of each pair, for plots (not serialised).
    #[serde(skip)]
    pub matched: Vec<MatchedPoses>,
}

fn pooled_ate(results: &[Option<AteResult>]) -> Option<f64> {
    let (mut sq, mut n) = (0.0, 0usize);
    for r in results {
        let r = r.as_ref()?;
        sq += r.rmse_m * r.rmse_m * r.poses as f64;
        n += r.poses;
    }
    (n > 0).then(|| (sq / n as f64).sqrt())
}

/// Scores every pair and pools the KITTI metric over all segments (as the devkit's total), the
/// ATE over all poses and the RPE over all frame pairs.
///
/// # Errors
/// An invalid config, or a pair that [`match_poses`] rejects.
pub fn evaluate(pairs: &[TrajectoryPair<'_>], config: &EvalConfig) -> Result<EvalReport> {
    config.validate()?;
    if pairs.is_empty() {
        return Err(EvalError::NothingToScore {
            sequence: 0,
            message: "no trajectory pair given".into(),
        });
    }
    let lengths = &config.kitti.lengths_m;
    let mut all_errors = Vec::new();
    let mut sequences = Vec::with_capacity(pairs.len());
    let mut matched = Vec::with_capacity(pairs.len());
    for (k, pair) in pairs.iter().enumerate() {
        check_poses(pair.gt, k, "ground truth")?;
        check_poses(pair.est, k, "estimate")?;
        let m = match_poses(pair, config, k)?;
        let errors = sequence_errors(&m.gt, &m.est, &config.kitti, k);
        let score = kitti_score(&errors, lengths);
        let path_length_m = crate::kitti::trajectory_distances(&m.gt)
            .last()
            .map_or(0.0, |d| f64::from(*d));
        sequences.push(SequenceReport {
            sequence: k,
            gt_poses: pair.gt.len(),
            est_poses: pair.est.len(),
            scored_poses: m.gt.len(),
            association: m.association,
            path_length_m,
            t_err_percent: score.t_err_percent,
            r_err_deg_per_100m: score.r_err_deg_per_100m,
            segments: score.segments,
            per_length: score.per_length,
            per_speed: score.per_speed,
            ate_se3: ate(&m.gt, &m.est, false),
            ate_sim3: ate(&m.gt, &m.est, true),
            rpe: rpe(&m.gt, &m.est, 1),
            rpe_delta: config.rpe_delta_frames.and_then(|d| rpe(&m.gt, &m.est, d)),
        });
        all_errors.extend(errors);
        matched.push(m);
    }
    if all_errors.is_empty() {
        log::warn!(
            "no KITTI segment fits: every trajectory is shorter than the shortest length {:?} m",
            lengths.iter().copied().fold(f64::INFINITY, f64::min)
        );
    }
    let total = kitti_score(&all_errors, lengths);
    let se3: Vec<_> = sequences.iter().map(|s| s.ate_se3).collect();
    let sim3: Vec<_> = sequences.iter().map(|s| s.ate_sim3).collect();
    let rpes: Option<Vec<RpeResult>> = sequences.iter().map(|s| s.rpe).collect();
    let rpes_delta: Option<Vec<RpeResult>> = sequences.iter().map(|s| s.rpe_delta).collect();
    // t_err and r_err are NaN by design when no segment fits (warned above)
    let segmented = total.segments > 0;
    let figures = [
        ("t_err", Some(total.t_err_percent).filter(|_| segmented)),
        (
            "r_err",
            Some(total.r_err_deg_per_100m).filter(|_| segmented),
        ),
        ("ATE SE(3)", pooled_ate(&se3)),
        ("ATE Sim(3)", pooled_ate(&sim3)),
    ];
    if let Some((what, value)) = figures
        .into_iter()
        .find_map(|(w, v)| v.filter(|v| !v.is_finite()).map(|v| (w, v)))
    {
        return Err(EvalError::NonFinite { what, value });
    }
    Ok(EvalReport {
        t_err_percent: total.t_err_percent,
        r_err_deg_per_100m: total.r_err_deg_per_100m,
        segments: total.segments,
        lengths_m: lengths.clone(),
        per_length: total.per_length,
        per_speed: total.per_speed,
        ate_se3_m: pooled_ate(&se3),
        ate_sim3_m: pooled_ate(&sim3),
        rpe: rpes.as_deref().and_then(pool),
        rpe_delta: rpes_delta.as_deref().and_then(pool),
        sequences,
        segment_errors: all_errors,
        matched,
    })
}

/// Checks every pose of a trajectory before it is scored: finite, a rotation block, a position
/// within [`visnav_core::se3::MAX_COORDINATE_M`] (squares of 1e308 overflow to inf and the
/// scores to NaN).
fn check_poses(poses: &[PoseMatrix], sequence: usize, which: &'static str) -> Result<()> {
    for (index, m) in poses.iter().enumerate() {
        let message = if m.iter().any(|v| !v.is_finite()) {
            Some("not finite".to_string())
        } else {
            visnav_core::se3::check_pose_matrix(&m.fixed_view::<3, 4>(0, 0).into_owned()).err()
        };
        if let Some(message) = message {
            return Err(EvalError::InvalidPose {
                sequence,
                which,
                index,
                message,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use visnav_core::Pose;

    fn drive(n: usize, step_m: f64, yaw: f64) -> Vec<PoseMatrix> {
        let step = Pose::from_parts(
            Translation3::new(0.0, 0.0, step_m),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.0, yaw, 0.0)),
        );
        let mut out = vec![Pose::identity()];
        for _ in 1..n {
            out.push(out[out.len() - 1] * step);
        }
        crate::pose_matrices(&out)
    }

    #[test]
    fn shorter_estimate_is_scored_on_prefix_or_rejected_when_strict() {
        let gt = drive(200, 1.0, 0.01);
        let est = drive(150, 1.0, 0.01);
        let config = EvalConfig {
            kitti: KittiMetricConfig {
                lengths_m: vec![50.0],
                ..KittiMetricConfig::default()
            },
            ..EvalConfig::default()
        };
        let r = evaluate(&[TrajectoryPair::by_index(&gt, &est)], &config).unwrap();
        assert_eq!(r.sequences[0].scored_poses, 150);
        assert!(r.segments > 0 && r.t_err_percent < 1e-9);
        assert!(r.ate_se3_m.unwrap() < 1e-9);
        let strict = EvalConfig {
            strict: true,
            ..config
        };
        let e = evaluate(&[TrajectoryPair::by_index(&gt, &est)], &strict).unwrap_err();
        assert!(matches!(
            e,
            EvalError::LengthMismatch {
                estimate: 150,
                ground_truth: 200,
                ..
            }
        ));
        assert!(
            evaluate(
                &[TrajectoryPair::by_index(&gt, &[])],
                &EvalConfig::default()
            )
            .is_err()
        );
    }

    #[test]
    fn config_from_json_with_defaults_and_unknown_fields_rejected() {
        let c: EvalConfig =
            serde_json::from_str(r#"{"kitti": {"lengths_m": [10, 20]}, "strict": true}"#).unwrap();
        assert_eq!(c.kitti.lengths_m, vec![10.0, 20.0]);
        assert_eq!(c.kitti.step_frames, 10);
        assert!(c.strict && c.validate().is_ok());
        assert!(serde_json::from_str::<EvalConfig>(r#"{"lenghts": [1]}"#).is_err());
        let bad = EvalConfig {
            rpe_delta_frames: Some(0),
            ..EvalConfig::default()
        };
        assert!(bad.validate().is_err());
        let bad = EvalConfig {
            max_time_diff_s: f64::NAN,
            ..EvalConfig::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn timestamps_match_frames() {
        let gt = drive(100, 1.0, 0.0);
        let gt_t: Vec<f64> = (0..100).map(|i| 0.1 * f64::from(i)).collect();
        // the estimate has every second frame, with a 3 ms clock offset
        let est: Vec<PoseMatrix> = gt.iter().step_by(2).copied().collect();
        let est_t: Vec<f64> = gt_t.iter().step_by(2).map(|t| t + 0.003).collect();
        let pair = TrajectoryPair {
            gt: &gt,
            est: &est,
            gt_timestamps: Some(&gt_t),
            est_timestamps: Some(&est_t),
        };
        let m = match_poses(&pair, &EvalConfig::default(), 0).unwrap();
        assert_eq!(m.association, Association::Timestamp);
        assert_eq!(m.gt.len(), 50);
        assert_eq!(m.gt[10], gt[20]);
        let r = evaluate(&[pair], &EvalConfig::default()).unwrap();
        assert!(r.rpe.unwrap().trans_rmse_m < 1e-12);
        let far: Vec<f64> = est_t.iter().map(|t| t + 0.05).collect();
        let pair = TrajectoryPair {
            est_timestamps: Some(&far),
            ..pair
        };
        assert!(match_poses(&pair, &EvalConfig::default(), 0).is_err());
    }
}

#[cfg(test)]
mod input_tests {
    use super::*;

    fn line(n: usize) -> Vec<PoseMatrix> {
        (0..n)
            .map(|i| {
                let mut m = PoseMatrix::identity();
                m[(2, 3)] = i as f64;
                m
            })
            .collect()
    }

    /// A rotation block scaled by 2 or all zeros, and positions of 1e200 m, were scored (inf/NaN
    /// printed, exit code 0): they are errors naming the pose (issue 21).
    #[test]
    fn poses_that_are_not_rigid_or_overflow_are_errors() {
        let gt = line(30);
        let config = EvalConfig::default();
        let mut scaled = line(30);
        scaled[7].fixed_view_mut::<3, 3>(0, 0).scale_mut(2.0);
        let mut zeros = line(30);
        zeros[3].fixed_view_mut::<3, 3>(0, 0).fill(0.0);
        let mut far = line(30);
        far[5][(0, 3)] = 1e200;
        for (est, index) in [(&scaled, 7), (&zeros, 3), (&far, 5)] {
            let e = evaluate(&[TrajectoryPair::by_index(&gt, est)], &config).unwrap_err();
            assert!(
                matches!(e, EvalError::InvalidPose { index: i, which: "estimate", .. } if i == index),
                "{e}"
            );
        }
        assert!(evaluate(&[TrajectoryPair::by_index(&gt, &line(30))], &config).is_ok());
    }
}
