//! Reading the run report of `visnav odometry --json` into per-frame rows, through the same type
//! the run wrote ([`visnav_pipeline::report::RunReport`]).

use std::path::{Path, PathBuf};

use visnav_pipeline::report::{FrameRecord, RunReport};
use visnav_pipeline::{Detail, Status};

/// One frame of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRow {
    /// Position in the run (pose line).
    pub step: usize,
    /// Frame of the sequence.
    pub index: usize,
    /// Outcome (`ok`, `low_parallax`, `fallback`, `skipped`).
    pub status: String,
    /// Anything else about the outcome (failure reason, pose and scale source).
    pub detail: String,
    /// Feature or inlier counts, by name.
    pub counts: Vec<(String, f64)>,
    /// Time per stage, milliseconds, by stage name.
    pub timings_ms: Vec<(String, f64)>,
}

/// The parts of an odometry report the HTML report shows.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// `stereo` or `mono`.
    pub mode: String,
    /// The sequence directory as the odometry run saw it.
    pub sequence: Option<PathBuf>,
    /// Pose lines of the run.
    pub frames: usize,
    /// Input frames (mono palindrome runs have `2N−1` pose lines for `N` input frames).
    pub input_frames: usize,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
    /// Scalar figures of the summary (frame counts, mean timings, palindrome drift), by name.
    pub figures: Vec<(String, String)>,
    /// The frames.
    pub per_frame: Vec<FrameRow>,
}

/// Reads an odometry JSON report.
///
/// # Errors
/// The file cannot be read or is not a run report (the message names the file).
pub fn read_run(path: &Path) -> anyhow::Result<RunSummary> {
    let report = RunReport::read(path).map_err(anyhow::Error::msg)?;
    Ok(summarise(&report))
}

/// The report's view of a run.
#[must_use]
pub fn summarise(r: &RunReport) -> RunSummary {
    let mut figures: Vec<(String, String)> = [
        ("ok_frames", r.ok_frames),
        ("low_parallax_frames", r.low_parallax_frames),
        ("failed_frames", r.failed_frames),
        ("skipped_frames", r.skipped_frames),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v.to_string()))
    .collect();
    if r.interrupted {
        figures.push(("interrupted".into(), "yes: the frames done".into()));
    }
    if let Some(s) = &r.sources {
        figures.push((
            "pose sources".into(),
            format!(
                "eight_point {}, pnp {}, fused {}, constant_velocity {}",
                s.eight_point, s.pnp, s.fused, s.constant_velocity
            ),
        ));
    }
    if let Some(p) = &r.palindrome {
        figures.extend([
            (
                "palindrome end_point_error_m".into(),
                format!("{:.4}", p.end_point_error_m),
            ),
            (
                "palindrome end_point_error_relative".into(),
                format!("{:.4}", p.end_point_error_relative),
            ),
            (
                "palindrome scale_drift_ratio".into(),
                format!("{:.4}", p.scale_drift_ratio),
            ),
            (
                "palindrome farthest_from_start_m".into(),
                format!(
                    "{:.3} (frame {})",
                    p.farthest_from_start_m, p.farthest_frame
                ),
            ),
        ]);
    }
    let m = &r.mean;
    for (k, v) in [
        ("flow_ms", m.flow_ms),
        ("odometry_ms", m.odometry_ms),
        ("frame_ms", m.frame_ms),
        ("wait_ms", m.wait_ms),
        ("wall_ms_per_frame", m.wall_ms_per_frame),
    ] {
        figures.push((format!("mean {k}"), format!("{v:.2}")));
    }
    RunSummary {
        mode: r.mode.name().to_owned(),
        sequence: Some(r.sequence.clone()),
        frames: r.frames,
        input_frames: r.input_frames,
        wall_s: r.wall_s,
        figures,
        per_frame: r.per_frame.iter().map(frame_row).collect(),
    }
}

fn frame_row(f: &FrameRecord) -> FrameRow {
    let mut detail = Vec::new();
    match &f.status {
        Status::Fallback { reason } => {
            detail.push(serde_json::to_string(reason).unwrap_or_else(|_| format!("{reason:?}")))
        }
        Status::Skipped { reason } => detail.push(reason.clone()),
        Status::Ok | Status::LowParallax => {}
    }
    let counts: Vec<(String, f64)> = match &f.detail {
        Detail::Mono(m) => {
            detail.push(format!("source: {:?}", m.source).to_lowercase());
            detail.push(format!("scale_source: {:?}", m.scale_source).to_lowercase());
            [
                ("correspondences", m.correspondences),
                ("eight_point_inliers", m.eight_point_inliers),
                ("pnp_correspondences", m.pnp_correspondences),
                ("pnp_inliers", m.pnp_inliers),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v as f64))
            .collect()
        }
        Detail::Stereo(s) => {
            let c = &s.counts;
            [
                ("detected", c.detected),
                ("stereo_matched", c.stereo_matched),
                ("tracked", c.tracked),
                ("circular", c.circular),
                ("rotation_inliers", c.rotation_inliers),
                ("translation_inliers", c.translation_inliers),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v as f64))
            .collect()
        }
        Detail::None => Vec::new(),
    };
    let mut timings_ms: Vec<(String, f64)> = f
        .timings
        .stages()
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect();
    timings_ms.extend([
        ("save_ms".to_owned(), f.save_ms),
        ("wait_ms".to_owned(), f.wait_ms),
    ]);
    FrameRow {
        step: f.step,
        index: f.index,
        status: f.status.name().to_owned(),
        detail: detail.join("; "),
        counts,
        timings_ms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_reports_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        std::fs::write(&p, "{not json").unwrap();
        let e = format!("{:#}", read_run(&p).unwrap_err());
        assert!(e.contains("r.json"), "{e}");
        std::fs::write(&p, r#"{"mode": "lidar", "per_frame": []}"#).unwrap();
        let e = format!("{:#}", read_run(&p).unwrap_err());
        assert!(e.contains("not a visnav run report"), "{e}");
    }
}
