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
