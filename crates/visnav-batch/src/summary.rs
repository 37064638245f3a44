//! `visnav summarize DIR...`: one row per batch run directory (its `status.json`), with the
//! KITTI scores of `poses.txt` when the run's sequence has ground truth beside it
//! (`visnav_report::find_ground_truth`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::{EvalConfig, TrajectoryPair, evaluate};

use crate::LineStatus;

/// One run of the summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SummaryRow {
    /// The run directory.
    pub dir: PathBuf,
    /// `"ok"`, `"failed"` or `"missing"` (no readable `status.json`).
    pub status: String,
    /// The sequence.
    pub sequence: Option<PathBuf>,
    /// `"stereo"` or `"mono"`.
    pub mode: Option<String>,
    /// Poses written.
    pub frames: Option<usize>,
    /// Wall time, seconds.
    pub wall_s: Option<f64>,
    /// CPU time, seconds.
    pub cpu_s: Option<f64>,
    /// KITTI translation error, % (with ground truth).
    pub t_err_percent: Option<f64>,
    /// KITTI rotation error, deg/100 m (with ground truth).
    pub r_err_deg_per_100m: Option<f64>,
    /// Segments scored.
    pub segments: Option<usize>,
    /// Segment lengths used, metres: the devkit's 100..800 m when the ground-truth path of the
    /// run is at least 100 m long, else 10..50 m (short clips).
    pub lengths_m: Option<Vec<f64>>,
    /// ATE after SE(3) alignment, metres.
    pub ate_se3_m: Option<f64>,
    /// The ground-truth file used.
    pub ground_truth: Option<PathBuf>,
    /// The run's error, or why it could not be scored.
    pub error: Option<String>,
}

impl SummaryRow {
    fn missing(dir: &Path, error: String) -> Self {
        Self {
            dir: dir.to_path_buf(),
            status: "missing".into(),
            sequence: None,
            mode: None,
            frames: None,
            wall_s: None,
            cpu_s: None,
            t_err_percent: None,
            r_err_deg_per_100m: None,
            segments: None,
            lengths_m: None,
            ate_se3_m: None,
            ground_truth: None,
            error: Some(error),
        }
    }
}

/// One row per directory, in the order given.
#[must_use]
pub fn summarize(dirs: &[PathBuf]) -> Vec<SummaryRow> {
    dirs.iter().map(|d| row(d)).collect()
}

fn row(dir: &Path) -> SummaryRow {
    let path = dir.join("status.json");
    let status: LineStatus = match visnav_io::text::read_text(&path)
        .map_err(|e| e.to_string())
        .and_then(|t| {
            serde_json::from_str(&t)
                .map_err(|e| format!("{}: not a visnav status file: {e}", path.display()))
        }) {
        Ok(s) => s,
        Err(e) => return SummaryRow::missing(dir, e),
    };
    let mut r = SummaryRow::missing(dir, String::new());
    r.status.clone_from(&status.status);
    r.sequence = Some(status.sequence.clone());
    r.mode = Some(status.mode.clone());
    r.frames = Some(status.frames);
    r.wall_s = Some(status.wall_s);
    r.cpu_s = status.cpu_s;
    r.error = status.error.clone();
    if status.status == "ok"
        && let Some(gt) = visnav_report::find_ground_truth(&status.sequence)
    {
        if let Err(e) = score(&mut r, &dir.join("poses.txt"), &gt) {
            r.error = Some(e);
        }
        r.ground_truth = Some(gt);
    }
    r
}

/// KITTI errors and ATE of `poses` against the first lines of `gt`.
fn score(r: &mut SummaryRow, poses: &Path, gt: &Path) -> Result<(), String> {
    let est = visnav_io::trajectory::read_pose_matrices(poses).map_err(|e| e.to_string())?;
    let gt = visnav_io::trajectory::read_pose_matrices(gt).map_err(|e| e.to_string())?;
    let n = est.poses.len().min(gt.poses.len());
    let gt = &gt.poses[..n];
    let path_m: f64 = gt
        .windows(2)
        .map(|w| (w[1].fixed_view::<3, 1>(0, 3) - w[0].fixed_view::<3, 1>(0, 3)).norm())
        .sum();
    let lengths_m = if path_m >= 100.0 {
        KittiMetricConfig::default().lengths_m
    } else {
        vec![10.0, 20.0, 30.0, 40.0, 50.0]
    };
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths_m.clone(),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    };
    let pair = TrajectoryPair {
        gt,
        est: &est.poses[..n],
        gt_timestamps: None,
        est_timestamps: None,
    };
    let report = evaluate(&[pair], &config).map_err(|e| e.to_string())?;
    r.t_err_percent = Some(report.t_err_percent).filter(|v| v.is_finite());
    r.r_err_deg_per_100m = Some(report.r_err_deg_per_100m).filter(|v| v.is_finite());
    r.segments = Some(report.segments);
    r.lengths_m = Some(lengths_m);
    r.ate_se3_m = report.ate_se3_m;
    Ok(())
}

/// The rows as CSV (header line first; empty fields for unknown values).
#[must_use]
pub fn summary_csv(rows: &[SummaryRow]) -> String {
    let mut out = String::from(
        "dir,status,mode,frames,wall_s,cpu_s,t_err_percent,r_err_deg_per_100m,segments,ate_se3_m,sequence,error\n",
    );
    let f = |v: Option<f64>| v.map_or_else(String::new, |x| format!("{x:.6}"));
    let quote = |s: &str| {
        if s.contains([',', '"', '\n']) {
            format!("\"{}\"", s.replace('"', "\"\"").replace('\n', " "))
        } else {
            s.to_owned()
        }
    };
    for r in rows {
        let fields = [
            quote(&r.dir.display().to_string()),
            r.status.clone(),
            r.mode.clone().unwrap_or_default(),
            r.frames.map_or_else(String::new, |n| n.to_string()),
            f(r.wall_s),
            f(r.cpu_s),
            f(r.t_err_percent),
            f(r.r_err_deg_per_100m),
            r.segments.map_or_else(String::new, |n| n.to_string()),
            f(r.ate_se3_m),
            quote(
                &r.sequence
                    .as_ref()
                    .map_or_else(String::new, |p| p.display().to_string()),
            ),
            quote(r.error.as_deref().unwrap_or("")),
        ];
        out.push_str(&fields.join(","));
        out.push('\n');
    }
    out
}
