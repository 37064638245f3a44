//! Matching the frames of two trajectories, by timestamp when both carry them, else by index.

use serde::Serialize;

/// How the frames of estimate and ground truth were matched.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Association {
    /// Frame `i` of the estimate with frame `i` of the ground truth (common prefix).
    Index,
    /// Each estimate frame with the ground-truth frame of nearest timestamp within tolerance.
    Timestamp,
}

/// Pairs `(gt_index, est_index)` of nearest timestamps with `|Δt| <= max_dt_s`, both indices
/// strictly increasing (a ground-truth frame is used once). Timestamps must be sorted.
#[must_use]
pub fn associate_by_timestamp(gt_s: &[f64], est_s: &[f64], max_dt_s: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(est_s.len().min(gt_s.len()));
    let mut next_gt = 0usize;
    for (ie, &te) in est_s.iter().enumerate() {
        if next_gt >= gt_s.len() {
            break;
        }
        // first gt index >= te among the unused ones
        let k = next_gt + gt_s[next_gt..].partition_point(|&t| t < te);
        let mut best: Option<usize> = None;
        for cand in [k.checked_sub(1), Some(k)].into_iter().flatten() {
            if cand < next_gt || cand >= gt_s.len() {
                continue;
            }
            let d = (gt_s[cand] - te).abs();
            if d <= max_dt_s && best.is_none_or(|b| d < (gt_s[b] - te).abs()) {
                best = Some(cand);
            }
        }
        if let Some(b) = best {
            out.push((b, ie));
            next_gt = b + 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_within_tolerance() {
        let gt = [0.0, 0.1, 0.2, 0.3, 0.4];
        let est = [0.004, 0.105, 0.25, 0.298, 0.5];
        let m = associate_by_timestamp(&gt, &est, 0.01);
        assert_eq!(m, vec![(0, 0), (1, 1), (3, 3)]);
        // a ground-truth frame is not used twice
        let m = associate_by_timestamp(&gt, &[0.1, 0.101], 0.01);
        assert_eq!(m, vec![(1, 0)]);
        assert!(associate_by_timestamp(&[], &est, 0.01).is_empty());
    }
}
