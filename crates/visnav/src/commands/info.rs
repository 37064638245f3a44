//! `visnav info INPUT`: what visnav sees in an input before a run.
//!
//! * A ROS 2 bag (`.mcap` file or rosbag2 directory): the topics with their message types,
//!   counts, image encodings and time spans, so that a user can find the topic names
//!   `visnav odometry BAG --topic … [--right-topic …]` needs.
//! * Any other sequence (KITTI, EuRoC, TUM, folders, video): its layout, frame count, image
//!   size, camera, stereo baseline and time span; `--check` decodes every frame (through the
//!   same prefetching source the odometry reads) and lists the ones that fail, with the
//!   decoding rate.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context as _;
use visnav_io::bag::{Bag, is_image_type};
use visnav_io::is_bag;
use visnav_io::{Prefetch, Sequence};

/// Arguments of `visnav info`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// A ROS 2 bag (`.mcap` file or rosbag2 directory), or any sequence `visnav odometry` reads.
    pub input: PathBuf,
    /// Camera file, for inputs without calibration (folders, video, TUM RGB-D).
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Image topic of a bag, with --check.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// Right image topic of a bag, with --check.
    #[arg(long, value_name = "TOPIC")]
    pub right_topic: Option<String>,
    /// Decode every frame (left and right) and report the ones that fail.
    #[arg(long)]
    pub check: bool,
    /// Print as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs the subcommand.
///
/// # Errors
/// A missing, unreadable or malformed input (a `.db3` bag: how to convert it); with `--check`,
/// a frame that does not decode.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if is_bag(&args.input) && !args.check {
        return bag_topics(args);
    }
    let seq = visnav_io::open_input(
        &args.input,
        args.camera.as_deref(),
        args.topic.as_deref(),
        args.right_topic.as_deref(),
    )
    .with_context(|| format!("opening {}", args.input.display()))?;
    let info = seq.info();
    if !args.json {
        let c = info.camera;
        println!("layout     {:?}", info.layout);
        println!("frames     {}  ({:.3} s)", info.frames, info.duration_s);
        println!("images     {}x{}", c.width, c.height);
        println!(
            "camera     fx {:.3}  fy {:.3}  cx {:.3}  cy {:.3}",
            c.fx, c.fy, c.cx, c.cy
        );
        match info.baseline_m {
            Some(b) => println!("stereo     baseline {b:.4} m"),
            None => println!("stereo     no (mono only)"),
        }
    }
    let check = if args.check {
        Some(check_frames(args, ctx, seq))
    } else {
        None
    };
    if args.json {
        let value = serde_json::json!({ "sequence": info, "check": check });
        println!("{}", serde_json::to_string_pretty(&value)?);
    }
    match check {
        Some(c) if !c.failed.is_empty() => anyhow::bail!(
            "{} of {} frames of {} do not decode (first: frame {})",
            c.failed.len(),
            info.frames,
            args.input.display(),
            c.failed[0].0
        ),
        _ => Ok(()),
    }
}

/// What `--check` found.
#[derive(Debug, serde::Serialize)]
struct Check {
    /// Frames that did not decode (position and error).
    failed: Vec<(usize, String)>,
    /// Decoding rate, frames a second.
    frames_per_s: f64,
}

/// `--check`: every frame through the prefetching source, as a run reads them.
fn check_frames(args: &Args, ctx: &super::Context, seq: Sequence) -> Check {
    let (stereo, n) = (seq.has_stereo(), seq.len());
    let bar = crate::progress::bar(n as u64, "decoding", ctx.quiet || args.json);
    let start = Instant::now();
    let mut failed = Vec::new();
    for item in Prefetch::new(Arc::new(seq), stereo, 4) {
        if let Err(e) = item.frame {
            log::warn!("frame {}: {e}", item.position);
            failed.push((item.position, e.to_string()));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let frames_per_s = n as f64 / start.elapsed().as_secs_f64().max(1e-9);
    if !args.json {
        println!(
            "checked    {n} frames, {} failed, {frames_per_s:.1} frames/s",
            failed.len()
        );
    }
    Check {
        failed,
        frames_per_s,
    }
}

/// The topics of a bag.
fn bag_topics(args: &Args) -> anyhow::Result<()> {
    let bag =
        Bag::open(&args.input).with_context(|| format!("opening bag {}", args.input.display()))?;
    let topics = bag.topics();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&topics)?);
        return Ok(());
    }
    let width = topics
        .iter()
        .map(|t| t.topic.len())
        .max()
        .unwrap_or(5)
        .max(5);
    let type_width = topics
        .iter()
        .map(|t| t.message_type.len())
        .max()
        .unwrap_or(4)
        .max(4);
    println!(
        "{:<width$}  {:<type_width$}  {:>7}  {:>9}  encodings",
        "topic", "type", "count", "span [s]"
    );
    for t in &topics {
        println!(
            "{:<width$}  {:<type_width$}  {:>7}  {:>9.3}  {}",
            t.topic,
            t.message_type,
            t.count,
            t.last_s - t.first_s,
            t.encodings.join(", ")
        );
    }
    let images = topics
        .iter()
        .filter(|t| is_image_type(&t.message_type))
        .count();
    println!(
        "{} topics, {images} of images; run `visnav odometry --mode mono|stereo {} --topic IMAGE_TOPIC [--right-topic RIGHT_TOPIC]`",
        topics.len(),
        args.input.display()
    );
    Ok(())
}
