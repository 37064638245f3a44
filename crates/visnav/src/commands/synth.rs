//! `visnav synth`: renders a synthetic sequence with exact ground truth in the KITTI odometry
//! layout, readable by `visnav_io::Sequence::open` (the layout: `visnav_synth::write`).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use visnav_io::trajectory::read_kitti;
use visnav_synth::write::{SynthSpec, SynthSummary, check_image_options, write_sequence};
use visnav_synth::write_indoor::write_indoor_flight;
use visnav_synth::{
    FlightConfig, IndoorFlightConfig, KITTI_BASELINE_M, Scene, drive_trajectory, flight_trajectory,
    kitti_like_camera,
};

/// Arguments of `visnav synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory (created if missing), written in the KITTI odometry layout.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of frames [default: 100, or every pose of --trajectory].
    #[arg(long)]
    pub frames: Option<usize>,
    /// Render the right camera too (image_1/, baseline 0.537 m as KITTI).
    #[arg(long)]
    pub stereo: bool,
    /// Follow a KITTI ground-truth file (12 numbers a line, world_from_cam) instead of the
    /// generated drive.
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Fly a UAV instead of driving: `forward` or `down` (30 m above the ground, 15 m/s, 10 Hz,
    /// climbing and turning) or a TOML file of `visnav_synth::FlightConfig` fields; `indoor` (a
    /// small drone low over a floor mat: 640x360 JPEG images with radial distortion and a
    /// `camera.yaml`) or a TOML file with an `[indoor]` table of
    /// `visnav_synth::IndoorFlightConfig` fields.
    #[arg(long, conflicts_with = "trajectory")]
    pub flight: Option<String>,
    /// Seed of the city layout, textures and generated drive.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Image width in pixels (KITTI's field of view is kept at any size) [default: 1241, or the
    /// indoor flight's camera (640; its lens is kept at any size)].
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels [default: 376, or the indoor flight's camera (360)].
    #[arg(long)]
    pub height: Option<u32>,
    /// Supersampling: n x n samples on pixels across geometric edges (1..=8).
    #[arg(long, default_value_t = 3)]
    pub supersampling: u32,
    /// Print a JSON summary (frames, timings) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs the subcommand.
///
/// # Errors
/// Bad arguments, an unreadable trajectory, or a file that cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if args.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    if let Some(indoor) = args
        .flight
        .as_deref()
        .map(indoor_config)
        .transpose()?
        .flatten()
    {
        return run_indoor(args, ctx, indoor);
    }
    let (width, height) = (args.width.unwrap_or(1241), args.height.unwrap_or(376));
    check_image_options(width, height, args.supersampling)?;
    let flight = args.flight.as_deref().map(flight_config).transpose()?;
    let (poses, source) = match &args.trajectory {
        Some(path) => {
            let mut poses = read_kitti(path)
                .with_context(|| format!("reading the trajectory {}", path.display()))?;
            if poses.is_empty() {
                bail!("{}: the trajectory has no poses", path.display());
            }
            if let Some(n) = args.frames {
                if n > poses.len() {
                    log::warn!(
                        "{} has {} poses; rendering {} frames, not {n}",
                        path.display(),
                        poses.len(),
                        poses.len()
                    );
                }
                poses.truncate(n);
            }
            (poses, path.display().to_string())
        }
        None => {
            let n = args.frames.unwrap_or(100);
            match &flight {
                Some(f) => (flight_trajectory(n, f)?, format!("generated flight {f:?}")),
                None => (
                    drive_trajectory(n, args.seed),
                    format!("generated drive (seed {})", args.seed),
                ),
            }
        }
    };
    let scene_config = flight.as_ref().map(FlightConfig::scene).unwrap_or_default();
    let scene = Scene::along_with(&poses, args.seed, scene_config)
        .context("laying out the scene along the trajectory")?
        .with_supersampling(args.supersampling);
    let spec = SynthSpec {
        scene,
        camera: kitti_like_camera(width, height),
        baseline_m: args.stereo.then_some(KITTI_BASELINE_M),
        poses,
        trajectory_source: source,
        frame_interval_s: flight.as_ref().map_or(0.1, |f| 1.0 / f.rate_hz),
    };
    let bars = crate::progress::Bars::new(ctx.quiet);
    let summary = write_sequence(&spec, &args.out, &bars)?;
    report(args, ctx, &summary)
}

/// Renders an indoor flight (`visnav_synth::write_indoor`): an image folder with a camera file.
fn run_indoor(
    args: &Args,
    ctx: &super::Context,
    mut config: IndoorFlightConfig,
) -> anyhow::Result<()> {
    if args.stereo {
        bail!("--stereo: the indoor flight has one camera");
    }
    if args.width.is_some() || args.height.is_some() {
        let c = &config.camera;
        let width = args.width.unwrap_or(c.width);
        let height = args.height.unwrap_or(c.height);
        check_image_options(width, height, 1)?;
        config.camera = c.resized(width, height);
    }
    let frames = args.frames.unwrap_or(600);
    let bars = crate::progress::Bars::new(ctx.quiet);
    let summary = write_indoor_flight(&config, frames, args.seed, &args.out, &bars)?;
    report(args, ctx, &summary)
}

/// Prints the summary of a rendering.
fn report(args: &Args, ctx: &super::Context, summary: &SynthSummary) -> anyhow::Result<()> {
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else if !ctx.quiet {
        println!(
            "wrote {} {} frames ({}x{}, {:.0} m) to {}: {:.0} ms render + {:.0} ms flow + {:.0} ms write a frame, {:.1} s in all",
            summary.frames,
            if summary.stereo { "stereo" } else { "mono" },
            summary.width,
            summary.height,
            summary.path_length_m,
            summary.out.display(),
            summary.render_ms_per_frame,
            summary.flow_ms_per_frame,
            summary.write_ms_per_frame,
            summary.total_s
        );
    }
    Ok(())
}

/// The indoor flight of `--flight indoor` or of a TOML file with an `[indoor]` table; `None` for
/// another flight.
fn indoor_config(arg: &str) -> anyhow::Result<Option<IndoorFlightConfig>> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct IndoorFile {
        indoor: IndoorFlightConfig,
    }
    if arg == "indoor" {
        return Ok(Some(IndoorFlightConfig::default()));
    }
    if FlightConfig::preset(arg).is_some() {
        return Ok(None);
    }
    let Ok(text) = std::fs::read_to_string(arg) else {
        return Ok(None);
    };
    let Ok(table) = text.parse::<toml::Table>() else {
        return Ok(None);
    };
    if !table.contains_key("indoor") {
        return Ok(None);
    }
    let file: IndoorFile =
        toml::from_str(&text).with_context(|| format!("{arg}: not an indoor flight"))?;
    Ok(Some(file.indoor))
}

/// A flight preset (`forward`, `down`) or a TOML file of `FlightConfig` fields.
fn flight_config(arg: &str) -> anyhow::Result<FlightConfig> {
    if let Some(preset) = FlightConfig::preset(arg) {
        return Ok(preset);
    }
    let text = std::fs::read_to_string(arg).with_context(|| {
        format!("--flight {arg}: neither 'forward', 'down', 'indoor' nor a readable file")
    })?;
    toml::from_str(&text).with_context(|| format!("{arg}: not a flight configuration"))
}
