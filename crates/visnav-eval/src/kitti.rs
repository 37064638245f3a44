//! The KITTI odometry metric, computed as the official devkit (`evaluate_odometry.cpp`) does.
//!
//! * `trajectoryDistances`: the ground-truth path length `dist[i]` up to frame `i`, accumulated
//!   in `f32` exactly as the devkit does (so that segment ends match it bit for bit).
//! * `lastFrameFromSegmentLength`: a segment of length `L` starting at frame `f` ends at the first
//!   frame `l` with `dist[l] > dist[f] + L`; no such frame, no segment.
//! * `calcSequenceErrors`: segments start every 10 frames (`step_frames`); for each, the error pose
//!   `E = inv(inv(est_f) est_l) (inv(gt_f) gt_l)`, `r_err = angle(E) / L` (rad/m) with
//!   `angle = acos(max(min((trace(R) - 1) / 2, 1), -1))`, `t_err = |t(E)| / L`, and
//!   `speed = L / (0.1 s · (l - f + 1))`.
//! * Poses are the 4x4 matrices as read from the files, not re-orthonormalised, and inverted as
//!   general matrices, as the devkit does (re-orthonormalising the 7-digit rotations of KITTI
//!   files moves short-segment rotation errors by ~1e-3 relative).
//! * The score is the plain mean of `t_err` and `r_err` over all segments (pooled over every
//!   sequence when several are scored), reported as t_err in % and r_err in deg/100 m
//!   (`r_err · 180/π · 100`).
//! * Breakdowns as the devkit's `saveErrorPlots`: per length (segments with `|len - L| < 1`) and
//!   per speed (2, 4, …, 24 m/s, segments with `|speed - v| < 2`, overlapping bins); like the
//!   devkit, a bin is reported only when it holds at least 3 segments.

use serde::{Deserialize, Serialize};

use crate::PoseMatrix;

use crate::error::{EvalError, Result};

/// The devkit's segment lengths in metres.
pub const DEVKIT_LENGTHS_M: [f64; 8] = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0];

/// Settings of the KITTI metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KittiMetricConfig {
    /// Segment lengths in metres (devkit: 100, 200, …, 800).
    pub lengths_m: Vec<f64>,
    /// Frames between segment starts (devkit: 10).
    pub step_frames: usize,
    /// Frame period in seconds used for a segment's speed (devkit: 0.1 s, KITTI's 10 Hz).
    pub frame_period_s: f64,
}

impl Default for KittiMetricConfig {
    fn default() -> Self {
        Self {
            lengths_m: DEVKIT_LENGTHS_M.to_vec(),
            step_frames: 10,
            frame_period_s: 0.1,
        }
    }
}

impl KittiMetricConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// No lengths, a length that is not finite and positive, a zero step, or a frame period that
    /// is not finite and positive.
    pub fn validate(&self) -> Result<()> {
        if self.lengths_m.is_empty() || self.lengths_m.iter().any(|l| !(l.is_finite() && *l > 0.0))
        {
            return Err(EvalError::InvalidConfig {
                field: "lengths_m",
                value: format!("{:?}", self.lengths_m),
                expected: "at least one finite positive length in metres",
            });
        }
        if self.step_frames == 0 {
            return Err(EvalError::InvalidConfig {
                field: "step_frames",
                value: "0".into(),
                expected: "at least 1",
            });
        }
        if !(self.frame_period_s.is_finite() && self.frame_period_s > 0.0) {
            return Err(EvalError::InvalidConfig {
                field: "frame_period_s",
                value: self.frame_period_s.to_string(),
                expected: "a finite positive period in seconds",
            });
        }
        Ok(())
    }
}

/// The error of one segment (the devkit's `errors` struct).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SegmentError {
    /// Index of the (ground truth, estimate) pair the segment belongs to.
    pub sequence: usize,
    /// First frame of the segment.
    pub first_frame: usize,
    /// Last frame of the segment.
    pub last_frame: usize,
    /// Nominal segment length in metres.
    pub length_m: f64,
    /// Rotation error per metre, rad/m.
    pub r_err_rad_per_m: f64,
    /// Translation error per metre (a ratio; ×100 for %).
    pub t_err_per_m: f64,
    /// Speed over the segment, m/s.
    pub speed_m_per_s: f64,
}

/// Mean errors of a group of segments.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BinScore {
    /// Segment length in metres (per-length bins) or speed in m/s (per-speed bins).
    pub key: f64,
    /// Mean translation error, %.
    pub t_err_percent: f64,
    /// Mean rotation error, deg/100 m.
    pub r_err_deg_per_100m: f64,
    /// Segments in the bin.
    pub segments: usize,
}

/// The KITTI score of a set of segments.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KittiScore {
    /// Mean translation error over all segments, %.
    pub t_err_percent: f64,
    /// Mean rotation error over all segments, deg/100 m.
    pub r_err_deg_per_100m: f64,
    /// Number of segments.
    pub segments: usize,
    /// Per segment length (`key` = length in m), bins with at least 3 segments.
    pub per_length: Vec<BinScore>,
    /// Per speed (`key` = speed in m/s; the devkit prints km/h = ×3.6), bins with at least 3
    /// segments.
    pub per_speed: Vec<BinScore>,
}

/// `trajectoryDistances`: cumulative ground-truth path length in metres, in `f32` as the devkit.
#[must_use]
pub fn trajectory_distances(gt: &[PoseMatrix]) -> Vec<f32> {
    let mut dist = Vec::with_capacity(gt.len());
    if gt.is_empty() {
        return dist;
    }
    dist.push(0.0f32);
    for w in gt.windows(2) {
        let dx = (w[0][(0, 3)] - w[1][(0, 3)]) as f32;
        let dy = (w[0][(1, 3)] - w[1][(1, 3)]) as f32;
        let dz = (w[0][(2, 3)] - w[1][(2, 3)]) as f32;
        let prev = dist[dist.len() - 1];
        dist.push(prev + (dx * dx + dy * dy + dz * dz).sqrt());
    }
    dist
}

/// The inverse of a pose matrix: the general inverse as the devkit's `Matrix::inv`, or the
/// rigid-body inverse `[Rᵀ | -Rᵀt]` should the matrix be singular (never for a valid pose).
#[must_use]
pub fn invert(m: &PoseMatrix) -> PoseMatrix {
    m.try_inverse().unwrap_or_else(|| {
        let r_t = m.fixed_view::<3, 3>(0, 0).transpose();
        let t = -(r_t * m.fixed_view::<3, 1>(0, 3));
        let mut out = PoseMatrix::identity();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_t);
        out.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
        out
    })
}

/// `lastFrameFromSegmentLength`: the first frame whose distance exceeds `dist[first] + len`.
#[must_use]
pub fn last_frame_from_segment_length(
    dist: &[f32],
    first_frame: usize,
    len_m: f32,
) -> Option<usize> {
    let start = *dist.get(first_frame)?;
    (first_frame..dist.len()).find(|&i| dist[i] > start + len_m)
}

/// `rotationError`: the rotation angle of a pose in radians,
/// `acos(max(min((a + b + c - 1) / 2, 1), -1))` with `a, b, c` the diagonal of its rotation.
#[must_use]
pub fn rotation_error(error_pose: &PoseMatrix) -> f64 {
    let d = 0.5 * (error_pose[(0, 0)] + error_pose[(1, 1)] + error_pose[(2, 2)] - 1.0);
    d.clamp(-1.0, 1.0).acos()
}

/// `translationError`: the norm of the translation of a pose, metres.
#[must_use]
pub fn translation_error(error_pose: &PoseMatrix) -> f64 {
    error_pose.fixed_view::<3, 1>(0, 3).norm()
}

/// `calcSequenceErrors`: the errors of every segment of one sequence. `gt` and `est` must have
/// the same length (frame `i` of one matches frame `i` of the other); extra frames of the
/// longer one are ignored.
#[must_use]
pub fn sequence_errors(
    gt: &[PoseMatrix],
    est: &[PoseMatrix],
    config: &KittiMetricConfig,
    sequence: usize,
) -> Vec<SegmentError> {
    let n = gt.len().min(est.len());
    let (gt, est) = (&gt[..n], &est[..n]);
    let dist = trajectory_distances(gt);
    let mut out = Vec::new();
    for first in (0..n).step_by(config.step_frames.max(1)) {
        for &len in &config.lengths_m {
            let Some(last) = last_frame_from_segment_length(&dist, first, len as f32) else {
                continue;
            };
            let gt_delta = invert(&gt[first]) * gt[last];
            let est_delta = invert(&est[first]) * est[last];
            let error_pose = invert(&est_delta) * gt_delta;
            let num_frames = (last - first + 1) as f64;
            let r_err = rotation_error(&error_pose) / len;
            let t_err = translation_error(&error_pose) / len;
            out.push(SegmentError {
                sequence,
                first_frame: first,
                last_frame: last,
                length_m: len,
                r_err_rad_per_m: r_err,
                t_err_per_m: t_err,
                speed_m_per_s: len / (config.frame_period_s * num_frames),
            });
        }
    }
    out
}

fn mean_bin(key: f64, errs: impl Iterator<Item = SegmentError>) -> BinScore {
    let (mut t, mut r, mut n) = (0.0, 0.0, 0usize);
    for e in errs {
        t += e.t_err_per_m;
        r += e.r_err_rad_per_m;
        n += 1;
    }
    let nf = n.max(1) as f64;
    BinScore {
        key,
        t_err_percent: 100.0 * t / nf,
        r_err_deg_per_100m: r / nf * 180.0 / std::f64::consts::PI * 100.0,
        segments: n,
    }
}

/// The devkit's statistics of a set of segments: plain means and the per-length and per-speed
/// breakdowns. With no segments, the means are NaN.
#[must_use]
pub fn kitti_score(errors: &[SegmentError], lengths_m: &[f64]) -> KittiScore {
    let all = mean_bin(0.0, errors.iter().copied());
    let (t, r) = if errors.is_empty() {
        (f64::NAN, f64::NAN)
    } else {
        (all.t_err_percent, all.r_err_deg_per_100m)
    };
    let per_length = lengths_m
        .iter()
        .map(|&len| {
            mean_bin(
                len,
                errors
                    .iter()
                    .copied()
                    .filter(|e| (e.length_m - len).abs() < 1.0),
            )
        })
        .filter(|b| b.segments > 2)
        .collect();
    let per_speed = (1..=12)
        .map(|k| {
            let speed = 2.0 * f64::from(k);
            mean_bin(
                speed,
                errors
                    .iter()
                    .copied()
                    .filter(|e| (e.speed_m_per_s - speed).abs() < 2.0),
            )
        })
        .filter(|b| b.segments > 2)
        .collect();
    KittiScore {
        t_err_percent: t,
        r_err_deg_per_100m: r,
        segments: errors.len(),
        per_length,
        per_speed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight(n: usize, step_m: f64) -> Vec<PoseMatrix> {
        (0..n)
            .map(|i| {
                let mut m = PoseMatrix::identity();
                m[(2, 3)] = step_m * i as f64;
                m
            })
            .collect()
    }

    #[test]
    fn segment_ends_at_first_frame_beyond_length() {
        let gt = straight(30, 1.0);
        let dist = trajectory_distances(&gt);
        assert_eq!(dist[29], 29.0);
        // dist[f] + 10 = 10 exactly at frame 10: the devkit needs '>' so frame 11
        assert_eq!(last_frame_from_segment_length(&dist, 0, 10.0), Some(11));
        assert_eq!(last_frame_from_segment_length(&dist, 20, 10.0), None);
        assert_eq!(last_frame_from_segment_length(&dist, 40, 1.0), None);
    }

    #[test]
    fn scaled_estimate_has_scale_error_and_speed() {
        let gt = straight(100, 1.0);
        let est = straight(100, 1.02);
        let config = KittiMetricConfig {
            lengths_m: vec![10.0, 20.0],
            ..KittiMetricConfig::default()
        };
        let errs = sequence_errors(&gt, &est, &config, 0);
        // starts 0,10,..,90: length 10 needs first <= 88 -> 9 starts, length 20 -> 8 starts
        assert_eq!(errs.len(), 9 + 8);
        let s = kitti_score(&errs, &config.lengths_m);
        // segment of 10 m spans 11 m of ground truth (frame 11), error 0.02 * 11 / 10
        let e10 = errs.iter().find(|e| e.length_m == 10.0).unwrap();
        assert!((e10.t_err_per_m - 0.022).abs() < 1e-12);
        assert!((e10.speed_m_per_s - 10.0 / (0.1 * 12.0)).abs() < 1e-12);
        assert!(s.r_err_deg_per_100m.abs() < 1e-9);
        assert_eq!(s.per_length.len(), 2);
        assert_eq!(s.per_length[1].segments, 8);
        assert!((s.per_length[1].t_err_percent - 2.0 * 21.0 / 20.0).abs() < 1e-9);
    }

    #[test]
    fn speed_bins_overlap_and_need_three_segments() {
        let seg = |speed: f64| SegmentError {
            sequence: 0,
            first_frame: 0,
            last_frame: 1,
            length_m: 100.0,
            r_err_rad_per_m: 0.0,
            t_err_per_m: 0.01,
            speed_m_per_s: speed,
        };
        // 5 m/s falls in the 4 and 6 m/s bins (|speed - v| < 2), 9 m/s in 8 and 10
        let errs = [seg(5.0), seg(5.5), seg(4.5), seg(9.0)];
        let s = kitti_score(&errs, &[100.0]);
        let keys: Vec<f64> = s.per_speed.iter().map(|b| b.key).collect();
        assert_eq!(keys, vec![4.0, 6.0]);
        assert_eq!(s.per_speed[0].segments, 3);
        assert!((s.t_err_percent - 1.0).abs() < 1e-12);
        assert_eq!(s.per_length[0].segments, 4);
        let empty = kitti_score(&[], &[100.0]);
        assert!(empty.t_err_percent.is_nan() && empty.per_length.is_empty());
    }

    #[test]
    fn config_validation() {
        assert!(KittiMetricConfig::default().validate().is_ok());
        let bad = KittiMetricConfig {
            lengths_m: vec![100.0, -1.0],
            ..KittiMetricConfig::default()
        };
        assert!(bad.validate().is_err());
        let bad = KittiMetricConfig {
            step_frames: 0,
            ..KittiMetricConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
