//! Issue 53's fuzz campaign beyond `visnav-io`: the batch manifest (`visnav batch`), the TOML
//! configuration (`--config`, a manifest's `"config"` file) and the run report JSON (`visnav
//! report`'s input), mutated from real files (`tests/fixtures`: the outputs of `visnav odometry
//! --json` on KITTI 06, stereo, stereo with loop closure and mono, the configuration files written
//! beside them, and a manifest of the forms the docs show), with the properties of
//! `visnav-io`'s harness (`visnav-io/tests/fuzz_harness`): no panic, no hang, allocation bounded
//! by the input, a result or an error naming the file (and a line that exists), a BOM + CRLF
//! copy read as the original. A configuration must not hold a value that is not finite.
//!
//! Case counts: `VISNAV_FUZZ_CASES` cases per parser (default 48). A long campaign:
//! `VISNAV_FUZZ_CASES=100000 cargo test -p visnav-batch --test fuzz`.
#![allow(clippy::unwrap_used)]

#[path = "../../visnav-io/tests/fuzz_harness/mod.rs"]
mod fuzz_harness;

use std::path::{Path, PathBuf};

use fuzz_harness::{Failure, Outcome, campaign, outcome};
use visnav_batch::BatchError;
use visnav_pipeline::Mode;
use visnav_pipeline::job::{ConfigSource, RunSpec, error_chain};

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures")
            .join(name),
    )
    .unwrap()
}

/// The line a message names as `file:LINE:` or TOML's `at line LINE`.
fn line_in(message: &str, file: &str) -> Option<usize> {
    let digits = |s: &str| -> Option<usize> {
        let n: String = s.chars().take_while(char::is_ascii_digit).collect();
        n.parse().ok()
    };
    message
        .find(&format!("{file}:"))
        .and_then(|i| digits(&message[i + file.len() + 1..]))
        .or_else(|| {
            message
                .find("at line ")
                .and_then(|i| digits(&message[i + 8..]))
        })
}

fn failure(e: &(dyn std::error::Error + 'static), path: &Path) -> Failure {
    let message = error_chain(e);
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    Failure {
        line: line_in(&message, &name),
        message,
    }
}

/// A manifest as `visnav batch` reads it: every line, and each line's configuration (its setup
/// error named by the manifest's line, as `run_line` names it).
fn manifest(path: &Path) -> Outcome {
    let checked = visnav_batch::read_manifest(path).and_then(|lines| {
        for l in &lines {
            l.spec
                .check_mode_fields()
                .and_then(|()| l.spec.effective_config())
                .map_err(|error| BatchError::Job {
                    manifest: path.to_path_buf(),
                    line: l.line,
                    output: l.output.clone(),
                    error: Box::new(error),
                })?;
        }
        Ok(lines)
    });
    match checked {
        Ok(lines) => Outcome {
            size: lines.len(),
            result: Ok(format!("{lines:?}")),
        },
        Err(e) => Outcome {
            result: Err(failure(&e, path)),
            size: 0,
        },
    }
}

/// The effective configuration of a `--config` file in `mode` (stereo: with the loop closure's
/// table); a value that is not finite is a failure of the reader.
fn config(path: &Path, mode: Mode) -> Outcome {
    let mut spec = RunSpec::new(PathBuf::from("seq"), mode);
    spec.loop_closure = mode == Mode::Stereo;
    spec.config = Some(ConfigSource::File(path.to_path_buf()));
    match spec.effective_config() {
        Ok(c) => {
            let text = format!("{c:?}");
            let non_finite = text
                .split(|c: char| !c.is_ascii_alphanumeric())
                .any(|t| t == "NaN" || t == "inf");
            if non_finite {
                return Outcome {
                    result: Err(Failure {
                        message: format!("accepted a value that is not finite: {text}"),
                        line: None,
                    }),
                    size: 0,
                };
            }
            Outcome {
                size: 64,
                result: Ok(text),
            }
        }
        Err(e) => Outcome {
            result: Err(failure(&e, path)),
            size: 0,
        },
    }
}

#[test]
fn fuzz_batch_manifest() {
    campaign(
        "batch manifest",
        "runs.jsonl",
        manifest,
        &[fixture("runs.jsonl")],
        true,
    );
}

#[test]
fn fuzz_toml_config() {
    let stereo = [
        fixture("config_stereo.toml"),
        fixture("config_stereo_loop.toml"),
    ];
    campaign(
        "stereo config.toml",
        "config.toml",
        |p| config(p, Mode::Stereo),
        &stereo,
        true,
    );
    campaign(
        "mono config.toml",
        "config.toml",
        |p| config(p, Mode::Mono),
        &[fixture("config_mono.toml")],
        true,
    );
}

#[test]
fn fuzz_run_report_json() {
    let seeds = [
        fixture("report_stereo.json"),
        fixture("report_stereo_loop.json"),
        fixture("report_mono.json"),
    ];
    campaign(
        "run report JSON",
        "report.json",
        |p| {
            let r = visnav_report::run::read_run(p).map_err(|e| {
                let message = format!("{e:#}");
                Failure {
                    line: line_in(&message, "report.json"),
                    message,
                }
            });
            outcome(r, |s| s.per_frame.len() + s.figures.len())
        },
        &seeds,
        true,
    );
}
