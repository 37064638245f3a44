//! `visnav odometry --mode mono --loop-closure` on real data: a short KITTI 00 palindrome
//! (frames 0..3..0, 7 poses), with the candidate search tightened so that a short run has
//! candidates (every 3 frames, at least 3 frames apart; the paper's 10 / 50 need hundreds of
//! frames). The last frame is frame 0 again: its closure with the first frame must bring the end
//! point back to the start, closer than the odometry alone, and the report must list the closures.
#![allow(clippy::unwrap_used)]

mod common;
use common::{run_ok, visnav};
use visnav_core::testdata::shared_data;
use visnav_io::trajectory::read_kitti;

#[test]
fn kitti_00_short_palindrome_closes_the_loop() {
    let Some(seq) = shared_data("kitti/odometry/sequences/00") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("loop.toml");
    std::fs::write(
        &config,
        "[loop_closure.candidates]\nevery_n_frames = 3\nmin_index_gap = 3\n",
    )
    .unwrap();
    let out = dir.path().join("pal_lc.txt");
    let json = dir.path().join("pal_lc.json");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .args([
                "--max-frames",
                "4",
                "--palindrome",
                "--loop-closure",
                "--config",
            ])
            .arg(&config)
            .arg("--output")
            .arg(&out)
            .arg("--json")
            .arg(&json),
    );
    let corrected = read_kitti(&out).unwrap();
    let odometry = read_kitti(&dir.path().join("pal_lc.odometry.txt")).unwrap();
    assert_eq!(corrected.len(), 7);
    assert_eq!(odometry.len(), 7);
    let end = |p: &[visnav_core::Pose]| p[p.len() - 1].translation.vector.norm();
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let lc = &report["loop_closure"];
    let closures = lc["closures"].as_array().unwrap();
    assert!(!closures.is_empty(), "{lc}");
    for c in closures {
        assert!(c["ssim"].as_f64().unwrap() >= 0.38, "{c}");
        assert!(
            c["reliable_fraction"].is_number() || c["reason"].is_string(),
            "{c}"
        );
    }
    // the last frame (step 6, frame 0) closes with the first (step 0): identical images, the
    // relative pose is the identity
    let last = closures
        .iter()
        .find(|c| c["step"] == 6 && c["candidate"] == 0)
        .unwrap_or_else(|| panic!("no closure 0 -> 6: {lc}"));
    assert_eq!(last["accepted"], true, "{last}");
    assert!(last["reliable_fraction"].as_f64().unwrap() > 0.2, "{last}");
    let t = &last["relative_pose"]["translation_m"];
    let t_norm = (0..3)
        .map(|i| t[i].as_f64().unwrap().powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(t_norm < 0.05, "{last}");
    assert!(lc["accepted"].as_u64().unwrap() >= 1);
    assert!(lc["optimisations"].as_u64().unwrap() >= 1);
    // the report's palindrome drift is the corrected trajectory's
    let drift = report["palindrome"]["end_point_error_m"].as_f64().unwrap();
    assert!((drift - end(&corrected)).abs() < 1e-6);
    let (before, after) = (end(&odometry), end(&corrected));
    let travelled = report["palindrome"]["distance_travelled_m"]
        .as_f64()
        .unwrap();
    assert!(travelled > 3.0, "{travelled}");
    // measured: see `git show 0a7500f:docs/benchmarks.md`
    // ("Loop closure in the monocular pipeline")
    assert!(after < before, "end point {before} m -> {after} m");
    assert!(
        after < 0.005 * travelled,
        "end point {after} m of {travelled} m"
    );
}
