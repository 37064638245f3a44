//! Batch runs of the odometry on an existing distributed engine (Slurm array jobs, Kubernetes
//! indexed jobs, Ray tasks): one run per line of a JSON-lines manifest, each line independent,
//! so the engine only has to hand out line numbers.
//!
//! A manifest line is a [`RunSpec`] plus `"output"`:
//! `{"sequence": PATH, "mode": "stereo"|"mono", "output": DIR}` with the optional `"camera"`,
//! `"config"` (a TOML path or an inline table), `"camera_height"`, `"max_frames"`, ...; relative
//! paths are relative to the manifest's directory. [`run_line`] writes, each atomically:
//!
//! * `DIR/poses.txt`: KITTI, one `world_from_cam` line per frame (what `visnav odometry` writes;
//!   while the run lasts, each pose is journaled to `DIR/poses.txt.partial`);
//! * `DIR/report.json`: the [`RunReport`](visnav_pipeline::report::RunReport);
//! * `DIR/status.json`: a [`LineStatus`], last, also for a failed run and for a run stopped by
//!   a signal ([`run_line_until`]: the frames done are written, the status says
//!   `"interrupted"`).
//!
//! [`summarize`] gathers the status files of many runs and their KITTI scores when the sequence
//! has ground truth.

mod summary;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use visnav_io::atomic::write_atomic;
use visnav_io::journal::PoseJournal;
use visnav_pipeline::Outputs;
use visnav_pipeline::job::{ErrorKind, JobError, RunSpec, error_chain};

pub use summary::{SummaryRow, summarize, summary_csv};

/// Exit code of a run whose input is bad (manifest, sequence, configuration): do not retry.
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code of a run that failed on the file system (unwritable output, unreadable disk):
/// a retry may succeed.
pub const EXIT_IO: u8 = 3;
/// Exit code of a run stopped by a signal (SIGINT, SIGTERM, SIGHUP: a scheduler's preemption):
/// the frames done are written and `status.json` says `"interrupted"`; a rerun (also with
/// `--skip-existing`) does the run again.
pub const EXIT_INTERRUPTED: u8 = 4;

/// Why a batch line failed.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The manifest or one of its lines is malformed.
    #[error("{}:{line}: {message}", path.display())]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// 1-based line number (0: the file as a whole).
        line: usize,
        /// The problem.
        message: String,
    },
    /// The manifest could not be read.
    #[error("reading manifest {}", path.display())]
    ReadManifest {
        /// The manifest file.
        path: PathBuf,
        /// The reader's error.
        #[source]
        source: visnav_io::IoError,
    },
    /// The run could not be set up.
    #[error("{}:{line}: run into {}: {}", manifest.display(), output.display(), error_chain(error))]
    Job {
        /// The manifest file.
        manifest: PathBuf,
        /// 1-based line number of the run in the manifest.
        line: usize,
        /// The run's output directory.
        output: PathBuf,
        /// The setup error (its chain is part of the message).
        error: Box<JobError>,
    },
    /// An output could not be written.
    #[error("writing {}", path.display())]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// The writer's error.
        #[source]
        source: visnav_io::IoError,
    },
}

impl BatchError {
    /// Bad input (do not retry), a missing path, or an I/O failure (retry).
    #[must_use]
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Manifest { .. } => ErrorKind::BadInput,
            Self::ReadManifest { source, .. } => ErrorKind::of_io(source),
            Self::Job { error, .. } => error.kind(),
            Self::Write { .. } => ErrorKind::Io,
        }
    }

    /// The process exit code: [`EXIT_IO`] for an I/O failure, else [`EXIT_BAD_INPUT`].
    #[must_use]
    pub fn exit_code(&self) -> u8 {
        match self.kind() {
            ErrorKind::Io => EXIT_IO,
            ErrorKind::BadInput | ErrorKind::NotFound => EXIT_BAD_INPUT,
        }
    }
}

/// One line of a manifest, its paths resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestLine {
    /// 0-based index of the line among the manifest's runs (blank and `#` lines not counted).
    pub index: usize,
    /// 1-based line number in the file.
    pub line: usize,
    /// The run.
    pub spec: RunSpec,
    /// The output directory.
    pub output: PathBuf,
}

/// The runs of a manifest (blank lines and lines starting with `#` are skipped).
///
/// # Errors
/// An unreadable manifest, or the first malformed line (file and line named).
pub fn read_manifest(path: &Path) -> Result<Vec<ManifestLine>, BatchError> {
    let text = visnav_io::text::read_text(path).map_err(|source| BatchError::ReadManifest {
        path: path.to_path_buf(),
        source,
    })?;
    let base = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let bad = |message: String| BatchError::Manifest {
            path: path.to_path_buf(),
            line: k + 1,
            message,
        };
        let mut value: serde_json::Value =
            serde_json::from_str(trimmed).map_err(|e| bad(format!("not JSON: {e}")))?;
        let output = match value.as_object_mut().map(|o| o.remove("output")) {
            None => return Err(bad("expected a JSON object".into())),
            Some(Some(serde_json::Value::String(s))) if !s.is_empty() => PathBuf::from(s),
            Some(_) => return Err(bad("\"output\" must be a directory path".into())),
        };
        let spec: RunSpec = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
        let output = if output.is_relative() {
            base.join(output)
        } else {
            output
        };
        out.push(ManifestLine {
            index: out.len(),
            line: k + 1,
            spec: spec.relative_to(base),
            output,
        });
    }
    Ok(out)
}

/// The run at `index` of a manifest.
///
/// # Errors
/// As [`read_manifest`], and an index past the last run.
pub fn manifest_line(path: &Path, index: usize) -> Result<ManifestLine, BatchError> {
    let mut lines = read_manifest(path)?;
    if index >= lines.len() {
        return Err(BatchError::Manifest {
            path: path.to_path_buf(),
            line: 0,
            message: format!(
                "run index {index} out of range: the manifest has {} runs (0..{})",
                lines.len(),
                lines.len().saturating_sub(1)
            ),
        });
    }
    Ok(lines.swap_remove(index))
}

/// `DIR/status.json`: the outcome of one batch line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineStatus {
    /// `"ok"`, `"failed"` or `"interrupted"` (stopped by a signal after `frames` poses, which
    /// `poses.txt` and `report.json` hold).
    pub status: String,
    /// The error chain of a failed run; what an interrupted run did.
    pub error: Option<String>,
    /// `"bad_input"`, `"not_found"` or `"io"` for a failed run, `"interrupted"` for an
    /// interrupted one.
    pub error_kind: Option<String>,
    /// Poses written.
    pub frames: usize,
    /// Wall time of the run (setup and writing included), seconds.
    pub wall_s: f64,
    /// CPU time of the process during the run (all threads), seconds; None where unknown.
    pub cpu_s: Option<f64>,
    /// visnav version.
    pub version: String,
    /// FNV-1a 64-bit hash (hex) of the effective configuration as TOML; None when it could not
    /// be loaded.
    pub config_hash: Option<String>,
    /// The input sequence.
    pub sequence: PathBuf,
    /// `"stereo"` or `"mono"`.
    pub mode: String,
    /// The manifest.
    pub manifest: PathBuf,
    /// Index of the run in the manifest.
    pub index: usize,
}

/// What [`run_line`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum LineOutcome {
    /// The run finished; its status.
    Done(Box<LineStatus>),
    /// `skip_existing` and a successful `status.json` was there already.
    Skipped(PathBuf),
    /// The run was stopped (the `stop` of [`run_line_until`]) after some frames: its poses,
    /// report and status (`"interrupted"`) are written.
    Interrupted(Box<LineStatus>),
}

/// FNV-1a, 64 bits, as 16 hex digits (a stable fingerprint, not a cryptographic hash).
#[must_use]
pub fn fnv1a_hex(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// CPU time of this process (user + system, every thread), seconds; Linux `/proc/self/stat`
/// at the usual 100 ticks a second, None elsewhere.
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // fields after the command name (which may contain spaces) in parentheses
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Runs line `index` of the manifest and writes its outputs (see the crate docs). A run that
/// cannot be set up still writes `status.json` (`"failed"`, with the error) when its output
/// directory can be created.
///
/// # Errors
/// A malformed manifest or line, a run that cannot be set up (bad input or missing path), an
/// output that cannot be written.
pub fn run_line(
    manifest: &Path,
    index: usize,
    skip_existing: bool,
) -> Result<LineOutcome, BatchError> {
    run_line_until(manifest, index, skip_existing, &|| false)
}

/// [`run_line`], stopping after the frame in progress once `stop()` says so (a signal handler's
/// flag, checked after every frame): the frames done are written as a finished run's are, with
/// `status.json` saying `"interrupted"` ([`LineOutcome::Interrupted`]).
///
/// # Errors
/// As [`run_line`].
pub fn run_line_until(
    manifest: &Path,
    index: usize,
    skip_existing: bool,
    stop: &dyn Fn() -> bool,
) -> Result<LineOutcome, BatchError> {
    let line = manifest_line(manifest, index)?;
    let status_path = line.output.join("status.json");
    if skip_existing && previous_ok(&status_path) {
        return Ok(LineOutcome::Skipped(status_path));
    }
    std::fs::create_dir_all(&line.output).map_err(|e| BatchError::Write {
        path: line.output.clone(),
        source: visnav_io::IoError::io(&line.output, e),
    })?;
    let start = Instant::now();
    let cpu0 = process_cpu_s();
    let config_hash = line
        .spec
        .effective_config()
        .ok()
        .and_then(|c| c.to_toml().ok())
        .map(|t| fnv1a_hex(t.as_bytes()));
    let mut status = LineStatus {
        status: "ok".into(),
        error: None,
        error_kind: None,
        frames: 0,
        wall_s: 0.0,
        cpu_s: None,
        version: env!("CARGO_PKG_VERSION").into(),
        config_hash,
        sequence: line.spec.sequence.clone(),
        mode: line.spec.mode.name().into(),
        manifest: manifest.to_path_buf(),
        index,
    };
    let result = run_and_write(manifest, &line, stop);
    status.wall_s = start.elapsed().as_secs_f64();
    status.cpu_s = cpu0.zip(process_cpu_s()).map(|(a, b)| b - a);
    let failure = match result {
        Ok(Written {
            poses,
            expected,
            interrupted,
        }) => {
            status.frames = poses;
            if interrupted {
                status.status = "interrupted".into();
                status.error_kind = Some("interrupted".into());
                status.error = Some(format!(
                    "interrupted: {poses} of {expected} poses written to {} (the frames done); run it again to finish",
                    line.output.join("poses.txt").display()
                ));
            }
            None
        }
        Err(e) => {
            status.status = "failed".into();
            status.error = Some(error_chain(&e));
            status.error_kind = Some(
                match e.kind() {
                    ErrorKind::BadInput => "bad_input",
                    ErrorKind::NotFound => "not_found",
                    ErrorKind::Io => "io",
                }
                .into(),
            );
            Some(e)
        }
    };
    write_json(&status_path, &status)?;
    match failure {
        Some(e) => Err(e),
        None if status.status == "interrupted" => Ok(LineOutcome::Interrupted(Box::new(status))),
        None => Ok(LineOutcome::Done(Box::new(status))),
    }
}

/// `true` when `status.json` exists and says `"ok"`.
fn previous_ok(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<LineStatus>(&t).ok())
        .is_some_and(|s| s.status == "ok")
}

/// What [`run_and_write`] wrote.
struct Written {
    /// Poses written.
    poses: usize,
    /// Poses of the whole run (fewer were written when it was stopped).
    expected: usize,
    /// The run was stopped before its last frame.
    interrupted: bool,
}

/// The run, `poses.txt` and `report.json` (checked writable before the run starts, so that no
/// work is lost on a read-only file); stops after the frame in progress once `stop()` says so.
fn run_and_write(
    manifest: &Path,
    line: &ManifestLine,
    stop: &dyn Fn() -> bool,
) -> Result<Written, BatchError> {
    let job = |error| BatchError::Job {
        manifest: manifest.to_path_buf(),
        line: line.line,
        output: line.output.clone(),
        error: Box::new(error),
    };
    let poses_path = line.output.join("poses.txt");
    let report_path = line.output.join("report.json");
    for path in [&poses_path, &report_path] {
        visnav_io::atomic::check_writable(path).map_err(|source| BatchError::Write {
            path: path.clone(),
            source,
        })?;
    }
    let mut prepared = line.spec.prepare(Outputs::default()).map_err(job)?;
    let write_err = |source| BatchError::Write {
        path: poses_path.clone(),
        source,
    };
    // each pose journaled as it is estimated, as `visnav odometry` does: a run killed outright
    // (SIGKILL after a scheduler's grace period) keeps its frames in `poses.txt.partial`
    let mut journal = PoseJournal::create(&poses_path).map_err(write_err)?;
    let driven = prepared.drive(|r| {
        journal.append(&r.world_from_cam)?;
        Ok::<_, visnav_io::IoError>(if stop() {
            visnav_pipeline::Control::Stop
        } else {
            visnav_pipeline::Control::Continue
        })
    });
    let driven = driven.map_err(|source| BatchError::Write {
        path: journal.path().to_path_buf(),
        source,
    })?;
    let expected = prepared.expected_poses();
    let interrupted = driven.interrupted;
    let outcome = prepared.finish(&line.spec, driven);
    journal.commit(&outcome.poses).map_err(write_err)?;
    write_json(&report_path, &outcome.report)?;
    Ok(Written {
        poses: outcome.poses.len(),
        expected,
        interrupted,
    })
}

/// Writes `value` as pretty JSON, atomically.
fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), BatchError> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| BatchError::Write {
        path: path.to_path_buf(),
        source: visnav_io::IoError::Format {
            path: path.to_path_buf(),
            message: e.to_string(),
        },
    })?;
    text.push('\n');
    write_atomic(path, text.as_bytes()).map_err(|source| BatchError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manifest_lines_resolve_paths_and_name_bad_lines() {
        let dir = tempfile::tempdir().unwrap();
        let m = dir.path().join("runs.jsonl");
        std::fs::write(
            &m,
            "# two runs\n{\"sequence\": \"seq\", \"mode\": \"stereo\", \"output\": \"out/a\"}\n\n{\"sequence\": \"/abs\", \"mode\": \"mono\", \"output\": \"/o\", \"camera_height\": 1.7, \"config\": {\"mono\": {}}}\n",
        )
        .unwrap();
        let lines = read_manifest(&m).unwrap();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].spec.sequence, dir.path().join("seq"));
        assert_eq!(lines[0].output, dir.path().join("out/a"));
        assert_eq!(lines[1].line, 4);
        assert_eq!(lines[1].spec.camera_height, Some(1.7));
        assert_eq!(lines[1].output, PathBuf::from("/o"));
        let e = manifest_line(&m, 2).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");

        std::fs::write(
            &m,
            "{\"sequence\": \"s\", \"mode\": \"stereo\", \"output\": \"o\"}\n{\"sequence\": \"s\", \"mode\": \"sideways\", \"output\": \"o\"}\n",
        )
        .unwrap();
        let e = read_manifest(&m).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with(&format!("{}:2: ", m.display())), "{text}");
        assert!(text.contains("sideways"), "{text}");
        assert_eq!(e.exit_code(), EXIT_BAD_INPUT);
        std::fs::write(
            &m,
            "{\"sequence\": \"s\", \"mode\": \"mono\", \"outptu\": \"o\"}\n",
        )
        .unwrap();
        assert!(read_manifest(&m).unwrap_err().to_string().contains(":1: "));
    }

    #[test]
    fn fnv1a_is_the_published_function() {
        // test vectors of the FNV reference (http://www.isthe.com/chongo/src/fnv/test_fnv.c)
        assert_eq!(fnv1a_hex(b""), "cbf29ce484222325");
        assert_eq!(fnv1a_hex(b"a"), "af63dc4c8601ec8c");
        assert_eq!(fnv1a_hex(b"foobar"), "85944171f73967e8");
    }
}
