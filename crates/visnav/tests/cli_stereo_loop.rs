//! `visnav odometry --mode stereo --loop-closure` on a short rendered stereo sequence that drives
//! 4 m down a street and back (frames 0..4..0, 9 pairs), with the candidate search tightened so that a short run has candidates (every 4 frames, at least 4 frames apart;
//! the defaults 10 / 50 need hundreds of frames). The last frame's closure with the first must
//! bring the end point back to the start, closer than the odometry alone; both trajectories and
//! the report's loop-closure summary must be written, as for the mono loop closure.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_io::trajectory::read_kitti;
use visnav_synth::loop_trajectory;

mod common;
use common::{run_ok, visnav, write_stereo_sequence};

/// Five frames 1 m apart down a straight street and back (9 pairs), in the KITTI odometry layout.
fn write_returning_sequence(dir: &Path) {
    let gt = loop_trajectory(5, 60.0, 40.0, 8.0, 1.0);
    let there_and_back: Vec<_> = gt.iter().chain(gt.iter().rev().skip(1)).copied().collect();
    write_stereo_sequence(dir, &gt, &there_and_back);
}

#[test]
fn stereo_loop_closure_writes_both_trajectories_and_the_loop_summary() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    write_returning_sequence(&seq);
    let config = dir.path().join("loop.toml");
    std::fs::write(
        &config,
        "[loop_closure.candidates]\nevery_n_frames = 4\nmin_index_gap = 4\n",
    )
    .unwrap();
    let out = dir.path().join("lc.txt");
    let json = dir.path().join("lc.json");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "stereo"])
            .arg(&seq)
            .args(["--loop-closure", "--config"])
            .arg(&config)
            .arg("--output")
            .arg(&out)
            .arg("--json")
            .arg(&json),
    );
    let corrected = read_kitti(&out).unwrap();
    let odometry = read_kitti(&dir.path().join("lc.odometry.txt")).unwrap();
    assert_eq!(corrected.len(), 9);
    assert_eq!(odometry.len(), 9);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // the effective configuration beside the output and in the report holds the loop table
    let written = std::fs::read_to_string(dir.path().join("lc.config.toml")).unwrap();
    assert!(written.contains("[loop_closure.candidates]"), "{written}");
    assert_eq!(
        report["config"]["loop_closure"]["candidates"]["min_index_gap"],
        4
    );
    let lc = &report["loop_closure"];
    assert!(
        lc["odometry_output"]
            .as_str()
            .unwrap()
            .ends_with("lc.odometry.txt")
    );
    assert!(lc["accepted"].as_u64().unwrap() >= 1, "{lc}");
    assert!(lc["optimisations"].as_u64().unwrap() >= 1, "{lc}");
    // the last frame (8, back at frame 0) closes with the first: identical images, the relative
    // pose is the identity, from the first frame's stereo points
    let closures = lc["closures"].as_array().unwrap();
    let last = closures
        .iter()
        .find(|c| c["step"] == 8 && c["candidate"] == 0)
        .unwrap_or_else(|| panic!("no closure 0 -> 8: {lc}"));
    assert_eq!(last["accepted"], true, "{last}");
    let pose = &last["relative_pose"];
    let t_m = (0..3)
        .map(|i| pose["translation_m"][i].as_f64().unwrap().powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(t_m < 0.05, "{last}");
    assert!(
        2 * pose["pnp_inliers"].as_u64().unwrap() >= pose["pnp_correspondences"].as_u64().unwrap(),
        "{last}"
    );
    // the corrected end point is back at the start, closer than the odometry's
    let end = |p: &[visnav_core::Pose]| p[8].translation.vector.norm();
    assert!(end(&corrected) < 0.05, "{}", end(&corrected));
    eprintln!(
        "end point: odometry {} m, corrected {} m",
        end(&odometry),
        end(&corrected)
    );
    assert!(end(&corrected) <= end(&odometry));
}
