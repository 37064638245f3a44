//! Interrupted runs keep what they finished: Ctrl-C (SIGINT), SIGTERM or SIGHUP halfway through a
//! run writes a complete, readable trajectory of the frames done (and says so); a killed writer (SIGKILL)
//! leaves the previous output intact and the frames done in the journal `<output>.partial`.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{run_ok, synth_sequence, visnav};

const FRAMES: usize = 120;

/// Starts a mono run of the sequence in `seq` writing `out`.
fn start_mono(seq: &Path, out: &Path, json: &Path) -> Child {
    visnav()
        .args(["-q", "odometry", "--mode", "mono"])
        .arg(seq)
        .arg("-o")
        .arg(out)
        .arg("--json")
        .arg(json)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until the journal of `out` holds at least `lines` poses (panics after 5 minutes).
fn wait_for_journal(child: &mut Child, out: &Path, lines: usize) {
    let partial = out.with_file_name(format!(
        "{}.partial",
        out.file_name().unwrap().to_string_lossy()
    ));
    let start = Instant::now();
    loop {
        let n = std::fs::read_to_string(&partial)
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if n >= lines {
            return;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it was interrupted"
        );
        assert!(start.elapsed() < Duration::from_secs(300), "no progress");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig} failed");
}

/// Sends `sig` to a mono run once 8 poses are journaled; checks that the frames done are written
/// (trajectory, report, configuration), with exit code 1 and the "interrupted" message.
fn interrupted_halfway_writes_the_frames_done(sig: &str) {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    synth_sequence(&seq, FRAMES, 320, 96);
    let out = dir.path().join("run/poses.txt");
    let json = dir.path().join("run/report.json");
    let mut child = start_mono(&seq, &out, &json);
    wait_for_journal(&mut child, &out, 8);
    signal(&child, sig);
    let result = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(
        result.status.code(),
        Some(1),
        "an interrupted run ({sig}) exits with 1: {stderr}"
    );
    assert!(stderr.contains("interrupted"), "{stderr}");
    let poses = visnav_io::trajectory::read_kitti(&out).unwrap();
    assert!(
        poses.len() >= 8 && poses.len() < FRAMES,
        "{} poses of {FRAMES}",
        poses.len()
    );
    assert!(
        stderr.contains(&format!("{} of {FRAMES}", poses.len())),
        "{stderr}"
    );
    let report = visnav_pipeline::report::RunReport::read(&json).unwrap();
    assert!(report.interrupted);
    assert_eq!(report.frames, poses.len());
    assert_eq!(report.per_frame.len(), poses.len());
    // the configuration beside the poses is this run's, and the journal is gone
    assert!(dir.path().join("run/poses.config.toml").exists());
    assert!(!dir.path().join("run/poses.txt.partial").exists());
}

#[test]
fn sigint_halfway_writes_a_complete_trajectory_of_the_frames_done() {
    interrupted_halfway_writes_the_frames_done("-INT");
}

/// Issue 53: SIGTERM (a job scheduler's stop, `kill`) killed the run without writing the frames
/// done; it is now handled as Ctrl-C is.
#[test]
fn sigterm_halfway_writes_the_frames_done_as_ctrl_c_does() {
    interrupted_halfway_writes_the_frames_done("-TERM");
}

/// Issue 53: SIGHUP (the terminal closed) is handled as Ctrl-C is.
#[test]
fn sighup_halfway_writes_the_frames_done_as_ctrl_c_does() {
    interrupted_halfway_writes_the_frames_done("-HUP");
}

#[test]
fn a_killed_writer_leaves_the_previous_output_intact_and_the_frames_done_in_the_journal() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    synth_sequence(&seq, FRAMES, 320, 96);
    let out = dir.path().join("poses.txt");
    // a complete earlier run
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--max-frames", "4"])
            .arg(&seq)
            .arg("-o")
            .arg(&out),
    );
    let previous = std::fs::read(&out).unwrap();
    assert_eq!(visnav_io::trajectory::read_kitti(&out).unwrap().len(), 4);
    let mut child = start_mono(&seq, &out, &dir.path().join("run.json"));
    wait_for_journal(&mut child, &out, 5);
    signal(&child, "-KILL");
    child.wait().unwrap();
    assert_eq!(
        std::fs::read(&out).unwrap(),
        previous,
        "the previous output was touched"
    );
    let journal = visnav_io::trajectory::read_kitti(&dir.path().join("poses.txt.partial")).unwrap();
    assert!(journal.len() >= 5, "{} poses in the journal", journal.len());
}

/// Issue 21: `--output X --json X` lost the poses, `--output` onto an input overwrote it, and a
/// bad output path was found only after the whole run. All are refused before the run starts.
#[test]
fn outputs_are_checked_before_the_run_starts() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    synth_sequence(&seq, 6, 160, 48);
    let run = |extra: &[&std::ffi::OsStr]| {
        let out = visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let same = dir.path().join("same.txt");
    let e = run(&[
        "-o".as_ref(),
        same.as_os_str(),
        "--json".as_ref(),
        same.as_os_str(),
    ]);
    assert!(e.contains("same file"), "{e}");
    assert!(!same.exists(), "nothing may be written");
    let calib = seq.join("calib.txt");
    let before = std::fs::read(&calib).unwrap();
    let e = run(&["-o".as_ref(), calib.as_os_str()]);
    assert!(e.contains("overwrite an input"), "{e}");
    assert_eq!(std::fs::read(&calib).unwrap(), before);
    let blocked = dir.path().join("a_file");
    std::fs::write(&blocked, "x").unwrap();
    let under = blocked.join("poses.txt");
    let e = run(&["-o".as_ref(), under.as_os_str()]);
    assert!(e.contains("a_file"), "{e}");
}

/// Issue 53: `visnav batch` had no stop handler: a job preempted with SIGTERM (Kubernetes,
/// Slurm) ended at once, with nothing written and no status. Now the run stops after the frame
/// in progress, writes the frames done (`poses.txt`, `report.json`) and a `status.json` that
/// says "interrupted" (as does `visnav summarize`), and exits with 4.
#[test]
fn sigterm_stops_a_batch_run_with_its_frames_done_and_an_interrupted_status() {
    let dir = tempfile::tempdir().unwrap();
    synth_sequence(&dir.path().join("seq"), FRAMES, 320, 96);
    let manifest = dir.path().join("runs.jsonl");
    std::fs::write(
        &manifest,
        "{\"sequence\": \"seq\", \"mode\": \"mono\", \"output\": \"out\"}\n",
    )
    .unwrap();
    let out_dir = dir.path().join("out");
    let poses_path = out_dir.join("poses.txt");
    let mut child = visnav()
        .args(["-q", "batch"])
        .arg(&manifest)
        .args(["--index", "0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_journal(&mut child, &poses_path, 8);
    signal(&child, "-TERM");
    let result = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(4), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    let poses = visnav_io::trajectory::read_kitti(&poses_path).unwrap();
    assert!(
        poses.len() >= 8 && poses.len() < FRAMES,
        "{} poses of {FRAMES}",
        poses.len()
    );
    let status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("status.json")).unwrap())
            .unwrap();
    assert_eq!(status["status"], "interrupted", "{status}");
    assert_eq!(status["error_kind"], "interrupted", "{status}");
    assert_eq!(status["frames"], poses.len(), "{status}");
    let message = status["error"].as_str().unwrap();
    assert!(
        message.contains(&format!("{} of {FRAMES} poses", poses.len())),
        "{message}"
    );
    let report = visnav_pipeline::report::RunReport::read(&out_dir.join("report.json")).unwrap();
    assert!(report.interrupted);
    assert_eq!(report.frames, poses.len());
    assert!(!out_dir.join("poses.txt.partial").exists());
    // the summary shows it as interrupted
    let csv = dir.path().join("summary.csv");
    run_ok(
        visnav()
            .args(["-q", "summarize", "--csv"])
            .arg(&csv)
            .arg(&out_dir),
    );
    assert!(
        std::fs::read_to_string(&csv)
            .unwrap()
            .contains(",interrupted,"),
        "{}",
        std::fs::read_to_string(&csv).unwrap()
    );
}
