//! `visnav info BAG`: the topics of a ROS 2 bag (`.mcap` file or rosbag2 directory) with their
//! message types, counts, image encodings and time spans, so that a user can find the topic
//! names `visnav odometry BAG --topic … [--right-topic …]` needs.

use std::path::PathBuf;

use anyhow::Context as _;
use visnav_io::bag::{Bag, is_image_type};

/// Arguments of `visnav info`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// ROS 2 bag: an `.mcap` file or a rosbag2 directory (`metadata.yaml` + `.mcap` files).
    pub bag: PathBuf,
    /// Print the topics as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs the subcommand.
///
/// # Errors
/// A missing, unreadable or malformed bag (a `.db3` bag: how to convert it).
pub fn run(args: &Args, _ctx: &super::Context) -> anyhow::Result<()> {
    let bag =
        Bag::open(&args.bag).with_context(|| format!("opening bag {}", args.bag.display()))?;
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
        args.bag.display()
    );
    Ok(())
}
