//! `visnav odometry` on a live input (`rtsp://…`, `udp://…`, `srt://…`, `/dev/video0`, `-`;
//! `visnav_io::live`), and the poses written as they happen (`--poses-out`, live or recorded).
//!
//! A live run journals every pose to `<output>.partial` like a recording, prints a progress
//! line (frames a second, dropped a second, latency), and ends when the stream ends (after
//! `--reconnect` attempts), after `--max-frames`, or at SIGINT/SIGTERM/SIGHUP: then every
//! output is written (poses, TUM poses with the stream's timestamps, configuration, `--json`
//! report, `--output-mcap`) and the exit status is 0.

use std::io::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use visnav_io::atomic::write_atomic;
use visnav_io::journal::PoseJournal;
use visnav_io::live::{FramePolicy, LiveConfig};
use visnav_pipeline::job::RunOutcome;
use visnav_pipeline::{Arrival, Control, Outputs};

use super::odometry::{Args, FramesPolicyArg};
use super::poses_out::PosesOut;

/// The progress line of a live run: frames processed and dropped a second, latency.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    quiet: bool,
    window: Instant,
    last_log: Instant,
    processed: usize,
    dropped: usize,
    latencies_ms: Vec<f64>,
}

impl Progress {
    fn new(quiet: bool) -> Self {
        use std::io::IsTerminal as _;
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let b = indicatif::ProgressBar::new_spinner();
            b.enable_steady_tick(Duration::from_millis(200));
            b
        });
        Self {
            bar,
            quiet,
            window: Instant::now(),
            last_log: Instant::now(),
            processed: 0,
            dropped: 0,
            latencies_ms: Vec::new(),
        }
    }

    fn frame(&mut self, step: usize, a: &Arrival) {
        self.processed += 1;
        self.dropped += a.dropped_before;
        self.latencies_ms.push(a.latency_ms);
        let s = self.window.elapsed().as_secs_f64();
        if s < 1.0 {
            return;
        }
        self.latencies_ms.sort_by(f64::total_cmp);
        let median = self.latencies_ms[self.latencies_ms.len() / 2];
        let line = format!(
            "live: {} poses, {:.1} frames/s processed, {:.1} dropped/s, latency {median:.0} ms",
            step + 1,
            self.processed as f64 / s,
            self.dropped as f64 / s
        );
        match &self.bar {
            Some(b) => b.set_message(line),
            // without a terminal: a log line every 10 s
            None if !self.quiet && self.last_log.elapsed() >= Duration::from_secs(10) => {
                log::info!("{line}");
                self.last_log = Instant::now();
            }
            None => {}
        }
        (self.window, self.processed, self.dropped) = (Instant::now(), 0, 0);
        self.latencies_ms.clear();
    }
}

/// Options a live input cannot take.
fn check_live_options(args: &Args) -> anyhow::Result<()> {
    let refused: &[(bool, &str)] = &[
        (args.report, "--report"),
        (args.save_flow.is_some(), "--save-flow"),
        (args.save_depth.is_some(), "--save-depth"),
        (args.save_tracks.is_some(), "--save-tracks"),
        (
            args.rerun_save.is_some() || args.rerun_connect,
            "--rerun-save/--rerun-connect",
        ),
    ];
    if let Some((_, name)) = refused.iter().find(|(set, _)| *set) {
        bail!(
            "{name} does not apply to a live input ({}): record the stream to a file and run on it",
            args.sequence.display()
        );
    }
    if args.camera.is_none() {
        bail!(
            "{}: a live input needs --camera FILE (its calibration and image size; see docs/guide/live.md)",
            args.sequence.display()
        );
    }
    Ok(())
}

/// Runs the odometry on a live input.
///
/// # Errors
/// Options a live input cannot take, no camera file, a stream that gives no frame, an output
/// that cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    check_live_options(args)?;
    super::odometry::check_outputs(args)?;
    let spec = super::odometry::run_spec(args);
    let mut poses_out = args.poses_out.as_deref().map(PosesOut::open).transpose()?;
    let config = LiveConfig {
        policy: match args.frames_policy {
            Some(FramesPolicyArg::All) => FramePolicy::All,
            Some(FramesPolicyArg::Newest) | None => FramePolicy::Newest,
        },
        reconnect: args.reconnect,
        timeout_s: args.stream_timeout,
        ..LiveConfig::default()
    };
    let stop = crate::interrupt::install_handler();
    log::info!(
        "live {}: waiting for the first frame (frame policy {}, --reconnect {})",
        args.sequence.display(),
        config.policy.name(),
        config.reconnect
    );
    let mut run = spec.prepare_live(&config, Arc::clone(&stop), Outputs::default())?;
    log::info!("live: running; Ctrl-C ends the run and writes every output");
    let mut journal = PoseJournal::create(&args.output)?;
    let mut progress = Progress::new(ctx.quiet);
    let driven = run.drive_with(args.max_frames, |r, a| -> anyhow::Result<Control> {
        journal.append(&r.world_from_cam)?;
        if let Some(p) = &mut poses_out {
            p.send(r, a);
        }
        progress.frame(r.position, a);
        Ok(if stop.load(Ordering::SeqCst) {
            Control::Stop
        } else {
            Control::Continue
        })
    });
    if let Some(b) = &progress.bar {
        b.finish_and_clear();
    }
    let driven = driven.with_context(|| {
        format!(
            "the run stopped; the poses of the frames done are in {}",
            journal.path().display()
        )
    })?;
    let outcome = run.finish(&spec, driven);
    drop(run);
    write_outputs(args, ctx, outcome, journal)
}

/// Writes the poses, the TUM poses (the stream's timestamps), the configuration, the report and
/// the MCAP file, and prints the summary.
fn write_outputs(
    args: &Args,
    ctx: &super::Context,
    outcome: RunOutcome,
    journal: PoseJournal,
) -> anyhow::Result<()> {
    let RunOutcome { poses, report, .. } = outcome;
    journal
        .commit(&poses)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let times: Option<Vec<f64>> = report.per_frame.iter().map(|r| r.timestamp_s).collect();
    let tum_path = match &times {
        Some(t) if !poses.is_empty() => {
            let path = super::odometry::sibling(&args.output, "tum.txt");
            visnav_io::trajectory::write_tum(&path, &poses, t)
                .with_context(|| format!("writing {}", path.display()))?;
            Some(path)
        }
        _ => None,
    };
    if let (Some(path), Some(t)) = (&args.output_mcap, &times) {
        visnav_io::bag::writer::write_pose_mcap(path, &poses, t)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let config_path = super::odometry::sibling(&args.output, "config.toml");
    let toml = report.config.to_toml().map_err(anyhow::Error::msg)?;
    write_atomic(&config_path, toml.as_bytes())?;
    if let Some(json) = &args.json {
        write_atomic(
            json,
            report.to_json().map_err(anyhow::Error::msg)?.as_bytes(),
        )?;
    }
    if !ctx.quiet {
        let mut out = super::odometry::human_output(args);
        super::odometry::print_summary(&mut out, &report)?;
        if let Some(live) = &report.live {
            let latency = report.latency.map_or_else(String::new, |l| {
                format!(
                    ", latency median {:.0} ms, p95 {:.0} ms",
                    l.median_ms, l.p95_ms
                )
            });
            writeln!(
                out,
                "live: {} frames received, {} dropped (policy {}), {} reconnections{latency}; {}",
                live.frames_received,
                live.frames_dropped,
                live.policy.name(),
                live.reconnects,
                live.end
                    .as_deref()
                    .unwrap_or("stopped (signal or --max-frames)")
            )?;
        }
        let tum: Option<PathBuf> = tum_path;
        super::odometry::print_output_paths(&mut out, &args.output, &config_path, tum.as_deref())?;
    }
    Ok(())
}
