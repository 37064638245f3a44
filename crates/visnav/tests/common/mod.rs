//! Helpers shared by the CLI tests: the binary under test, and runs that must succeed or fail.
// each test binary uses a subset of these
#![allow(dead_code, clippy::unwrap_used)]

use std::path::Path;
use std::process::{Command, Output};

/// The `visnav` binary built for these tests, or the one `VISNAV_TEST_BIN` names (to check
/// that a regression test fails on an older build: `docs/robustness.md`).
pub fn visnav() -> Command {
    Command::new(
        std::env::var_os("VISNAV_TEST_BIN").unwrap_or_else(|| env!("CARGO_BIN_EXE_visnav").into()),
    )
}

/// Runs `cmd` and asserts that it succeeded (its stderr is the failure message).
pub fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `cmd`, asserts that it failed, and returns its stderr.
pub fn run_err(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(!out.status.success(), "{cmd:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Renders a synthetic sequence of `frames` frames at `width x height` into `out` with
/// `visnav -q synth`, asserting that it succeeded.
pub fn synth_sequence(out: &Path, frames: usize, width: usize, height: usize) {
    run_ok(visnav().args(["-q", "synth", "--out"]).arg(out).args([
        "--frames",
        &frames.to_string(),
        "--width",
        &width.to_string(),
        "--height",
        &height.to_string(),
    ]));
}

/// Renders `poses` as a stereo sequence in the KITTI odometry layout (`image_0`, `image_1`,
/// `calib.txt`) with a 480x144 KITTI-like rig, in the synthetic street laid along `street`.
pub fn write_stereo_sequence(
    dir: &Path,
    street: &[visnav_core::Pose],
    poses: &[visnav_core::Pose],
) {
    use visnav_synth::{KITTI_BASELINE_M, Scene, kitti_like_camera, render_stereo};
    let scene = Scene::along(street, 3).unwrap();
    let rig =
        visnav_core::StereoCamera::new(kitti_like_camera(480, 144), KITTI_BASELINE_M).unwrap();
    std::fs::create_dir_all(dir.join("image_0")).unwrap();
    std::fs::create_dir_all(dir.join("image_1")).unwrap();
    for (i, pose) in poses.iter().enumerate() {
        let (l, r) = render_stereo(&scene, &rig, pose);
        visnav_io::image_io::save_gray_png(&l.image, &dir.join(format!("image_0/{i:06}.png")))
            .unwrap();
        visnav_io::image_io::save_gray_png(&r.image, &dir.join(format!("image_1/{i:06}.png")))
            .unwrap();
    }
    let c = rig.left;
    let p = |tx: f64| format!("{} 0 {} {} 0 {} {} 0 0 0 1 0", c.fx, c.cx, tx, c.fy, c.cy);
    let calib = format!("P0: {}\nP1: {}\n", p(0.0), p(-c.fx * rig.baseline_m));
    std::fs::write(dir.join("calib.txt"), calib).unwrap();
}
