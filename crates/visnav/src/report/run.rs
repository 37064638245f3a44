//! Reading the JSON report of `visnav odometry --json` (stereo or mono) into per-frame rows.
//!
//! The two pipelines write different reports: stereo frames carry `status` (+ a failure reason),
//! `counts` (features per phase) and `timings` (ms per stage) with `wait_ms` beside them; mono
//! frames carry `status`, `source`, `scale_source`, `error`, inlier counts at the top level and
//! nested `timings` (`flow` and `vo` stages, `save_ms`, `wait_ms`). Both are read here into the
//! same [`FrameRow`]: timings are every `*_ms` leaf of `timings` (plus `wait_ms`) except the
//! totals, named by their path (`flow.matching_ms`).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use serde_json::Value;

/// One frame of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRow {
    /// Position in the run (pose line).
    pub step: usize,
    /// Frame of the sequence.
    pub index: usize,
    /// Outcome (`ok`, `first`, `low_speed`, `fallback`, `low_parallax`, `failed`).
    pub status: String,
    /// Anything else about the outcome (failure reason, pose and scale source, error).
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
    /// Scalar figures of the summary (`failed_frames`, mean timings, palindrome drift), by name.
    pub figures: Vec<(String, String)>,
    /// The frames.
    pub per_frame: Vec<FrameRow>,
}

/// Counts shown for a stereo frame (`counts` object); iterations are left out.
const STEREO_COUNTS: [&str; 6] = [
    "detected",
    "stereo_matched",
    "tracked",
    "circular",
    "rotation_inliers",
    "translation_inliers",
];

/// Counts shown for a mono frame (top-level fields).
const MONO_COUNTS: [&str; 4] = [
    "correspondences",
    "eight_point_inliers",
    "pnp_correspondences",
    "pnp_inliers",
];

/// Stage names that are totals of other stages (not stacked).
const TOTALS: [&str; 2] = ["total_ms", "frame_ms"];

/// Reads an odometry JSON report.
///
/// # Errors
/// The file cannot be read, is not JSON, or lacks `mode` / `per_frame`.
pub fn read_run(path: &Path) -> anyhow::Result<RunSummary> {
    let text = visnav_io::text::read_text(path)
        .with_context(|| format!("reading odometry report {}", path.display()))?;
    let json: Value = serde_json::from_str(&text)
        .with_context(|| format!("parsing odometry report {}", path.display()))?;
    parse_run(&json).with_context(|| format!("odometry report {}", path.display()))
}

/// Reads an odometry report from its JSON value.
///
/// # Errors
/// `mode` is not `stereo` or `mono`, or `per_frame` is not a list of frame objects.
pub fn parse_run(json: &Value) -> anyhow::Result<RunSummary> {
    let mode = json.get("mode").and_then(Value::as_str).unwrap_or_default();
    if mode != "stereo" && mode != "mono" {
        bail!(
            "`mode` is {:?}, expected \"stereo\" or \"mono\"",
            json.get("mode")
        );
    }
    let Some(frames_json) = json.get("per_frame").and_then(Value::as_array) else {
        bail!("no `per_frame` list");
    };
    let mut per_frame = Vec::with_capacity(frames_json.len());
    for (k, f) in frames_json.iter().enumerate() {
        if !f.is_object() {
            bail!("per_frame[{k}] is not an object");
        }
        per_frame.push(frame_row(mode, k, f));
    }
    let number = |key: &str| json.get(key).and_then(Value::as_f64);
    let frames = number("frames").map_or(per_frame.len(), |v| v as usize);
    let mut figures = Vec::new();
    for key in ["failed_frames", "low_speed_frames", "low_parallax_frames"] {
        if let Some(v) = json.get(key) {
            figures.push((key.to_owned(), v.to_string()));
        }
    }
    if let Some(sources) = json.get("sources").and_then(Value::as_object) {
        let text: Vec<String> = sources.iter().map(|(k, v)| format!("{k} {v}")).collect();
        figures.push(("pose sources".into(), text.join(", ")));
    }
    if let Some(p) = json.get("palindrome").filter(|p| p.is_object()) {
        for (k, v) in p.as_object().into_iter().flatten() {
            if let Some(x) = v.as_f64() {
                figures.push((format!("palindrome {k}"), format!("{x:.4}")));
            }
        }
    }
    if let Some(mean) = json.get("mean").and_then(Value::as_object) {
        for (k, v) in mean {
            if let Some(x) = v.as_f64() {
                figures.push((format!("mean {k}"), format!("{x:.2}")));
            }
        }
    }
    Ok(RunSummary {
        mode: mode.to_owned(),
        sequence: json
            .get("sequence")
            .and_then(Value::as_str)
            .map(PathBuf::from),
        frames,
        input_frames: number("input_frames").map_or(frames, |v| v as usize),
        wall_s: number("wall_s").unwrap_or(f64::NAN),
        figures,
        per_frame,
    })
}

fn frame_row(mode: &str, k: usize, f: &Value) -> FrameRow {
    let usize_of = |key: &str| f.get(key).and_then(Value::as_u64).map(|v| v as usize);
    let index = usize_of("index").unwrap_or(k);
    let status = f
        .get("status")
        .and_then(Value::as_str)
        .unwrap_or("unknown")
        .to_owned();
    let mut detail = Vec::new();
    let mut counts = Vec::new();
    let mut timings_ms = Vec::new();
    if let Some(t) = f.get("timings") {
        collect_ms(t, "", &mut timings_ms);
    }
    if mode == "stereo" {
        // the failure reason is flattened beside `status`
        if let Some(r) = f.get("reason") {
            detail.push(compact(r));
        }
        if let Some(w) = f.get("wait_ms").and_then(Value::as_f64) {
            timings_ms.push(("wait_ms".into(), w));
        }
        if let Some(c) = f.get("counts") {
            for key in STEREO_COUNTS {
                if let Some(v) = c.get(key).and_then(Value::as_f64) {
                    counts.push((key.to_owned(), v));
                }
            }
        }
    } else {
        for key in ["source", "scale_source", "error"] {
            if let Some(v) = f.get(key).and_then(Value::as_str) {
                detail.push(format!("{key}: {v}"));
            }
        }
        for key in MONO_COUNTS {
            if let Some(v) = f.get(key).and_then(Value::as_f64) {
                counts.push((key.to_owned(), v));
            }
        }
    }
    FrameRow {
        step: usize_of("step").unwrap_or(k),
        index,
        status,
        detail: detail.join("; "),
        counts,
        timings_ms,
    }
}

/// A JSON value on one line (strings without quotes).
fn compact(v: &Value) -> String {
    v.as_str().map_or_else(|| v.to_string(), str::to_owned)
}

/// Every numeric `*_ms` leaf below `v` except the totals, named by its path.
fn collect_ms(v: &Value, prefix: &str, out: &mut Vec<(String, f64)>) {
    let Some(map) = v.as_object() else {
        return;
    };
    for (k, x) in map {
        let name = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        if x.is_object() {
            collect_ms(x, &name, out);
        } else if let Some(ms) = x.as_f64()
            && k.ends_with("_ms")
            && !TOTALS.contains(&k.as_str())
        {
            out.push((name, ms));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn stereo_report_rows() {
        let j = json!({
            "sequence": "seq/06", "mode": "stereo", "frames": 2, "failed_frames": 1,
            "wall_s": 0.5, "mean": {"process_ms": 12.0},
            "per_frame": [
                {"index": 0, "status": "first", "counts": {"detected": 900, "stereo_matched": 700,
                 "tracked": 0, "circular": 0, "rotation_inliers": 0, "rotation_iterations": 0,
                 "translation_inliers": 0, "translation_iterations": 0},
                 "timings": {"pyramid_ms": 1.0, "corners_ms": 2.0, "total_ms": 3.0}, "wait_ms": 0.5},
                {"index": 1, "status": "fallback", "reason": {"too_few_tracks": {"found": 3, "needed": 10}},
                 "counts": {"detected": 800, "tracked": 3}, "timings": {"pyramid_ms": 1.5}, "wait_ms": 0.1}
            ]
        });
        let run = parse_run(&j).unwrap();
        assert_eq!(run.mode, "stereo");
        assert_eq!(run.frames, 2);
        assert_eq!(run.sequence.as_deref(), Some(Path::new("seq/06")));
        let f0 = &run.per_frame[0];
        assert_eq!(f0.status, "first");
        assert_eq!(f0.counts[0], ("detected".into(), 900.0));
        assert!(!f0.counts.iter().any(|(k, _)| k.contains("iterations")));
        assert_eq!(
            f0.timings_ms,
            vec![
                ("corners_ms".into(), 2.0),
                ("pyramid_ms".into(), 1.0),
                ("wait_ms".into(), 0.5)
            ]
        );
        assert!(run.per_frame[1].detail.contains("too_few_tracks"));
        assert!(
            run.figures
                .iter()
                .any(|(k, v)| k == "failed_frames" && v == "1")
        );
    }

    #[test]
    fn mono_report_rows() {
        let j = json!({
            "mode": "mono", "frames": 1, "input_frames": 1, "palindrome": null,
            "per_frame": [{"step": 0, "index": 4, "status": "low_parallax", "error": null,
                "source": "pnp", "scale_source": "none", "correspondences": 500,
                "eight_point_inliers": 0, "pnp_correspondences": 300, "pnp_inliers": 250,
                "timings": {"wait_ms": 1.0, "flow": {"matching_ms": 800.0, "total_ms": 900.0},
                            "vo": null, "save_ms": 2.0, "frame_ms": 950.0}}]
        });
        let run = parse_run(&j).unwrap();
        let f = &run.per_frame[0];
        assert_eq!((f.step, f.index), (0, 4));
        assert_eq!(f.status, "low_parallax");
        assert!(f.detail.contains("source: pnp"));
        assert!(f.counts.contains(&("pnp_inliers".into(), 250.0)));
        let names: Vec<&str> = f.timings_ms.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(names, ["flow.matching_ms", "save_ms", "wait_ms"]);
    }

    #[test]
    fn bad_reports_are_errors() {
        assert!(parse_run(&json!({"mode": "lidar", "per_frame": []})).is_err());
        assert!(parse_run(&json!({"mode": "mono"})).is_err());
        assert!(parse_run(&json!({"mode": "mono", "per_frame": [3]})).is_err());
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        std::fs::write(&p, "{not json").unwrap();
        let e = format!("{:#}", read_run(&p).unwrap_err());
        assert!(e.contains("r.json"), "{e}");
    }
}
