//! `visnav batch` and `visnav summarize` on a rendered stereo sequence: the outputs of a line,
//! equal to `visnav odometry`'s; status files; exit codes; --skip-existing; the summary table.
#![allow(clippy::unwrap_used)]

use std::path::Path;

mod common;
use common::{run_ok, visnav};

fn render_stereo(out: &Path, frames: usize) {
    run_ok(
        visnav()
            .args(["-q", "synth", "--stereo", "--out"])
            .arg(out)
            .args([
                "--frames",
                &frames.to_string(),
                "--width",
                "320",
                "--height",
                "120",
            ]),
    );
}

fn status(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("status.json")).unwrap()).unwrap()
}

#[test]
fn batch_lines_write_what_odometry_writes_and_report_their_status() {
    let tmp = tempfile::tempdir().unwrap();
    render_stereo(&tmp.path().join("seq"), 6);
    let manifest = tmp.path().join("runs.jsonl");
    std::fs::write(
        &manifest,
        "# relative paths are relative to the manifest\n\
         {\"sequence\": \"seq\", \"mode\": \"stereo\", \"output\": \"out/a\", \"max_frames\": 5}\n\
         {\"sequence\": \"missing\", \"mode\": \"stereo\", \"output\": \"out/b\"}\n\
         {\"sequence\": \"seq\", \"mode\": \"stereo\", \"output\": \"out/c\", \"config\": {\"outlier\": \"re\"}}\n",
    )
    .unwrap();
    run_ok(
        visnav()
            .args(["-q", "batch"])
            .arg(&manifest)
            .args(["--index", "0"]),
    );
    let a = tmp.path().join("out/a");
    let s = status(&a);
    assert_eq!(s["status"], "ok");
    assert_eq!(s["frames"], 5);
    assert_eq!(s["index"], 0);
    assert!(s["wall_s"].as_f64().unwrap() > 0.0);
    assert_eq!(s["config_hash"].as_str().unwrap().len(), 16);
    // the same poses as visnav odometry, byte for byte
    let cli = tmp.path().join("cli.txt");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "stereo", "--max-frames", "5"])
            .arg(tmp.path().join("seq"))
            .arg("-o")
            .arg(&cli),
    );
    assert_eq!(
        std::fs::read(&cli).unwrap(),
        std::fs::read(a.join("poses.txt")).unwrap()
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["frames"], 5);

    // a missing sequence: bad input, exit code 2, a failed status naming the path
    let out = visnav()
        .args(["-q", "batch"])
        .arg(&manifest)
        .args(["--index", "1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let b = status(&tmp.path().join("out/b"));
    assert_eq!(b["status"], "failed");
    assert_eq!(b["error_kind"], "not_found");
    assert!(b["error"].as_str().unwrap().contains("missing"), "{b}");
    // the error names the manifest and the line of the run (line 3: the comment is line 1)
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("{}:3: ", manifest.display())),
        "{err}"
    );

    // --all with --skip-existing: line 0 skipped (its status file untouched), line 2 runs with
    // its inline configuration, line 1 fails again: exit 2
    let before = std::fs::read(a.join("status.json")).unwrap();
    let out = visnav()
        .arg("batch")
        .arg(&manifest)
        .args(["--all", "--skip-existing"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stdout).contains("run 0: skipped"));
    assert_eq!(before, std::fs::read(a.join("status.json")).unwrap());
    let c = tmp.path().join("out/c");
    assert_eq!(status(&c)["frames"], 6);
    assert_ne!(status(&c)["config_hash"], s["config_hash"]);

    // summarize: ground truth found in the rendered sequence (poses.txt)
    let json = tmp.path().join("summary.json");
    let csv = tmp.path().join("summary.csv");
    let out = run_ok(
        visnav()
            .arg("summarize")
            .args([&a, &tmp.path().join("out/b"), &c])
            .arg("--json")
            .arg(&json)
            .arg("--csv")
            .arg(&csv),
    );
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rows.as_array().unwrap().len(), 3);
    assert_eq!(rows[0]["status"], "ok");
    assert_eq!(rows[1]["status"], "failed");
    // the scores are visnav eval's (lengths 10..50 m for a short run)
    let eval = run_ok(
        visnav()
            .args(["eval", "--json", "--lengths", "10,20,30,40,50"])
            .arg(tmp.path().join("seq/poses.txt"))
            .arg(a.join("poses.txt")),
    );
    let eval: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(rows[0]["ate_se3_m"], eval["ate_se3_m"]);
    assert!(rows[0]["ate_se3_m"].as_f64().unwrap().is_finite());
    assert_eq!(rows[0]["segments"], eval["segments"]);
    assert!(
        rows[0]["ground_truth"]
            .as_str()
            .unwrap()
            .ends_with("poses.txt")
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 4);
    assert_eq!(String::from_utf8_lossy(&out.stdout), text);
}

#[test]
fn manifest_errors_name_the_line_and_io_failures_exit_3() {
    let tmp = tempfile::tempdir().unwrap();
    let manifest = tmp.path().join("runs.jsonl");
    std::fs::write(
        &manifest,
        "{\"sequence\": \"s\", \"mode\": \"stereo\", \"output\": \"o\"}\n{\"sequence\": \"s\", \"mode\": \"stereo\", \"output\": \"o\", \"colour\": 1}\n",
    )
    .unwrap();
    let out = visnav()
        .arg("batch")
        .arg(&manifest)
        .args(["--index", "0"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}:2:", manifest.display())), "{err}");
    assert!(err.contains("colour"), "{err}");

    // an output directory that cannot be created (a file is in the way): I/O, exit code 3
    std::fs::write(tmp.path().join("file"), "x").unwrap();
    std::fs::write(
        &manifest,
        "{\"sequence\": \"s\", \"mode\": \"stereo\", \"output\": \"file/run\"}\n",
    )
    .unwrap();
    let out = visnav()
        .arg("batch")
        .arg(&manifest)
        .args(["--index", "0"])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // an index past the end is bad input
    let out = visnav()
        .arg("batch")
        .arg(&manifest)
        .args(["--index", "5"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("out of range"));
}
