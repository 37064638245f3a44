//! `visnav batch MANIFEST.jsonl --index N | --all [--skip-existing]`: runs lines of a batch
//! manifest (`visnav_batch`; one odometry run per line, for Slurm arrays, Kubernetes indexed
//! jobs or Ray) and `visnav summarize DIR...`: the table of many runs.
//!
//! Exit codes: 0 every run done (or skipped); 2 bad input (malformed manifest or line, missing
//! or unreadable sequence or configuration: retrying will not help); 3 an I/O failure (an
//! output that cannot be written: retry); with `--all`, 3 when any run failed on I/O, else 2
//! when any failed; 4 interrupted (SIGINT, SIGTERM, SIGHUP: the run in progress stops after its
//! frame in progress, writes its frames done and a status `"interrupted"`; `--all` starts no
//! further run).

use std::path::PathBuf;
use std::sync::atomic::Ordering;

use anyhow::Context as _;
use visnav_batch::{EXIT_INTERRUPTED, EXIT_IO, LineOutcome, summarize, summary_csv};

/// Arguments of `visnav batch`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
    Each non-blank line of MANIFEST (lines starting with # are comments) is a JSON object: \
    {\"sequence\": PATH, \"mode\": \"stereo\"|\"mono\", \"output\": DIR} with optional \"camera\", \
    \"config\" (a TOML path or an inline table), \"camera_height\", \"max_frames\"; relative paths \
    are relative to the manifest's directory. A run writes DIR/poses.txt (KITTI), DIR/report.json \
    and DIR/status.json, each atomically (status.json also for a failed run).\n\n\
    Exit codes: 0 done; 2 bad input (do not retry); 3 I/O failure (retry); 4 interrupted by \
    SIGINT, SIGTERM or SIGHUP (the frames done are written, status.json says \"interrupted\"; \
    rerun).\n\n\
    Slurm: visnav batch runs.jsonl --index $SLURM_ARRAY_TASK_ID (sbatch --array=0-N). \
    Kubernetes indexed job: --index $JOB_COMPLETION_INDEX.")]
pub struct Args {
    /// The manifest (JSON lines).
    pub manifest: PathBuf,
    /// The run to do: 0-based index among the manifest's runs.
    #[arg(long, required_unless_present = "all", conflicts_with = "all")]
    pub index: Option<usize>,
    /// Every run of the manifest, one after the other.
    #[arg(long)]
    pub all: bool,
    /// Skip a run whose status.json says "ok".
    #[arg(long)]
    pub skip_existing: bool,
}

/// A failure with its exit code (see the module docs).
#[derive(Debug)]
pub struct ExitWith {
    /// The process exit code.
    pub code: u8,
    /// The message.
    pub message: String,
}

impl std::fmt::Display for ExitWith {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for ExitWith {}

/// Runs the subcommand.
///
/// # Errors
/// [`ExitWith`] with the exit code of the worst failure.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let indices: Vec<usize> = match args.index {
        Some(i) => vec![i],
        None => (0..visnav_batch::read_manifest(&args.manifest)
            .map_err(|e| exit_with(&e))?
            .len())
            .collect(),
    };
    let interrupted = crate::interrupt::install_handler();
    let stop = || interrupted.load(Ordering::SeqCst);
    let mut worst: Option<ExitWith> = None;
    for i in indices {
        if stop() {
            worst = Some(ExitWith {
                code: EXIT_INTERRUPTED,
                message: format!("interrupted before run {i} started"),
            });
            break;
        }
        match visnav_batch::run_line_until(&args.manifest, i, args.skip_existing, &stop) {
            Ok(LineOutcome::Done(s)) => {
                if !ctx.quiet {
                    println!(
                        "run {i}: {} frames in {:.2} s ({})",
                        s.frames,
                        s.wall_s,
                        s.sequence.display()
                    );
                }
            }
            Ok(LineOutcome::Skipped(p)) => {
                if !ctx.quiet {
                    println!("run {i}: skipped ({} says ok)", p.display());
                }
            }
            Ok(LineOutcome::Interrupted(s)) => {
                worst = Some(ExitWith {
                    code: EXIT_INTERRUPTED,
                    message: format!("run {i}: {}", s.error.as_deref().unwrap_or("interrupted")),
                });
                break;
            }
            Err(e) => {
                let e = exit_with(&e);
                eprintln!("error: run {i}: {e}");
                if worst
                    .as_ref()
                    .is_none_or(|w| e.code == EXIT_IO && w.code != EXIT_IO)
                {
                    worst = Some(e);
                }
            }
        }
    }
    match worst {
        Some(w) => Err(w.into()),
        None => Ok(()),
    }
}

fn exit_with(e: &visnav_batch::BatchError) -> ExitWith {
    ExitWith {
        code: e.exit_code(),
        message: visnav_pipeline::job::error_chain(e),
    }
}

/// Arguments of `visnav summarize`.
#[derive(Debug, clap::Args)]
pub struct SummarizeArgs {
    /// Run directories written by `visnav batch` (each with status.json).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Also write the table as CSV here.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the table as JSON here (one object per run).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// Runs `visnav summarize`: prints the CSV table, writes the files asked for.
///
/// # Errors
/// An output that cannot be written.
pub fn run_summarize(args: &SummarizeArgs, ctx: &super::Context) -> anyhow::Result<()> {
    let rows = summarize(&args.dirs);
    let csv = summary_csv(&rows);
    if let Some(p) = &args.csv {
        visnav_io::atomic::write_atomic(p, csv.as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&rows)? + "\n";
        visnav_io::atomic::write_atomic(p, text.as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if !ctx.quiet {
        print!("{csv}");
    }
    Ok(())
}
