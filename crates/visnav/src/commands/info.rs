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
use visnav_io::bag::{Bag, is_bag, is_image_type};
use visnav_io::{FrameSource, Prefetch, Sequence};

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
    let seq = if is_bag(&args.input) {
        let options = visnav_io::bag::BagOptions {
            topic: args.topic.clone(),
            right_topic: args.right_topic.clone(),
            camera: args.camera.clone(),
            pair_tolerance_s: None,
        };
        visnav_io::bag::open_bag_sequence(&args.input, &options)
    } else {
        Sequence::open_with_camera(&args.input, args.camera.as_deref())
    }
    .with_context(|| format!("opening {}", args.input.display()))?;
    let summary = SequenceSummary::of(&seq);
    if args.json && !args.check {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else if !args.json {
        summary.print();
    }
    if args.check {
        return check_frames(args, ctx, seq, summary);
    }
    Ok(())
}

/// What a sequence is.
#[derive(Debug, serde::Serialize)]
struct SequenceSummary {
    layout: visnav_io::SequenceLayout,
    frames: usize,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    baseline_m: Option<f64>,
    duration_s: f64,
    /// With `--check`: frames that did not decode (index and error).
    failed: Vec<(usize, String)>,
    /// With `--check`: decoding rate, frames a second.
    frames_per_s: Option<f64>,
}

impl SequenceSummary {
    fn of(seq: &Sequence) -> Self {
        let c = seq.camera;
        Self {
            layout: seq.layout,
            frames: seq.len(),
            width: c.width,
            height: c.height,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
            baseline_m: seq.stereo_camera().map(|s| s.baseline_m),
            duration_s: seq.timestamps.last().unwrap_or(&0.0)
                - seq.timestamps.first().unwrap_or(&0.0),
            failed: Vec::new(),
            frames_per_s: None,
        }
    }

    fn print(&self) {
        println!("layout     {:?}", self.layout);
        println!("frames     {}  ({:.3} s)", self.frames, self.duration_s);
        println!("images     {}x{}", self.width, self.height);
        println!(
            "camera     fx {:.3}  fy {:.3}  cx {:.3}  cy {:.3}",
            self.fx, self.fy, self.cx, self.cy
        );
        match self.baseline_m {
            Some(b) => println!("stereo     baseline {b:.4} m"),
            None => println!("stereo     no (mono only)"),
        }
    }
}

/// `--check`: every frame through the prefetching source, as a run reads them.
fn check_frames(
    args: &Args,
    ctx: &super::Context,
    seq: Sequence,
    mut summary: SequenceSummary,
) -> anyhow::Result<()> {
    let stereo = seq.has_stereo();
    let n = seq.len();
    let source: Arc<dyn FrameSource> = Arc::new(seq);
    let bar = crate::progress::bar(n as u64, "decoding", ctx.quiet || args.json);
    let start = Instant::now();
    for item in Prefetch::new(source, stereo, 4) {
        if let Err(e) = item.frame {
            log::warn!("frame {}: {e}", item.position);
            summary.failed.push((item.position, e.to_string()));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    summary.frames_per_s = Some(n as f64 / start.elapsed().as_secs_f64().max(1e-9));
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "checked    {n} frames, {} failed, {:.1} frames/s",
            summary.failed.len(),
            summary.frames_per_s.unwrap_or(0.0)
        );
    }
    if summary.failed.is_empty() {
        Ok(())
    } else {
        anyhow::bail!(
            "{} of {n} frames of {} do not decode (first: frame {})",
            summary.failed.len(),
            args.input.display(),
            summary.failed[0].0
        )
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
