//! `visnav synth`: renders a synthetic sequence with exact ground truth in the KITTI odometry
//! layout, readable by `visnav_io::Sequence::open`:
//!
//! ```text
//! DIR/image_0/NNNNNN.png   left camera (image_1/ with --stereo)
//! DIR/calib.txt            P0, P1 (P1[0][3] = -fx * baseline)
//! DIR/times.txt            seconds, 10 Hz
//! DIR/poses.txt            ground truth world_from_cam of the left camera (KITTI format)
//! DIR/flow/NNNNNN.flo      forward flow frame i -> i+1 of the left camera; 1e10 = occluded/out
//! DIR/depth/NNNNNN.pfm     depth z of the left camera, metres (inf = sky)
//! DIR/synth.json           the effective settings
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;
use visnav_core::{PinholeCamera, Pose, StereoCamera};
use visnav_io::flo::write_flo;
use visnav_io::image_io::save_gray_png;
use visnav_io::pfm::{PfmImage, write_pfm};
use visnav_io::trajectory::{read_kitti, write_atomically, write_kitti};
use visnav_synth::{
    KITTI_BASELINE_M, Scene, SceneConfig, View, drive_trajectory, flow_between, kitti_like_camera,
    render_stereo, render_view,
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
    /// Seed of the city layout, textures and generated drive.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Image width in pixels (KITTI's field of view is kept at any size).
    #[arg(long, default_value_t = 1241)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 376)]
    pub height: u32,
    /// Supersampling: n x n samples on pixels across geometric edges (1..=8).
    #[arg(long, default_value_t = 3)]
    pub supersampling: u32,
    /// Print a JSON summary (frames, timings) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// What to render: the scene, the camera(s) and the poses.
pub(crate) struct SynthSpec {
    pub scene: Scene,
    pub camera: PinholeCamera,
    /// Stereo baseline in metres; `None` for mono.
    pub baseline_m: Option<f64>,
    /// Left-camera poses, `world_from_cam`.
    pub poses: Vec<Pose>,
    /// Where the poses came from (for synth.json).
    pub trajectory_source: String,
}

/// Figures of a rendered sequence.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct SynthSummary {
    pub out: PathBuf,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub stereo: bool,
    pub seed: u64,
    pub supersampling: u32,
    pub path_length_m: f64,
    /// Mean time to render one frame (both cameras with --stereo), ms.
    pub render_ms_per_frame: f64,
    /// Mean time of one ground-truth flow field, ms.
    pub flow_ms_per_frame: f64,
    /// Mean time to write one frame's files, ms.
    pub write_ms_per_frame: f64,
    pub total_s: f64,
    /// Mean fraction of non-occluded pixels of the flow fields.
    pub mean_flow_valid_fraction: f64,
}

#[derive(Serialize)]
struct SynthSettings<'a> {
    seed: u64,
    frames: usize,
    camera: &'a PinholeCamera,
    baseline_m: Option<f64>,
    trajectory: &'a str,
    scene: &'a SceneConfig,
}

/// Runs the subcommand.
///
/// # Errors
/// Bad arguments, an unreadable trajectory, or a file that cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if !(16..=8192).contains(&args.width) || !(16..=8192).contains(&args.height) {
        bail!(
            "--width/--height must be within 16..=8192 pixels, got {}x{}",
            args.width,
            args.height
        );
    }
    if !(1..=8).contains(&args.supersampling) {
        bail!(
            "--supersampling must be within 1..=8, got {}",
            args.supersampling
        );
    }
    if args.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
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
            (
                drive_trajectory(n, args.seed),
                format!("generated drive (seed {})", args.seed),
            )
        }
    };
    let scene = Scene::along(&poses, args.seed)
        .context("laying out the scene along the trajectory")?
        .with_supersampling(args.supersampling);
    let spec = SynthSpec {
        scene,
        camera: kitti_like_camera(args.width, args.height),
        baseline_m: args.stereo.then_some(KITTI_BASELINE_M),
        poses,
        trajectory_source: source,
    };
    let summary = write_sequence(&spec, &args.out, ctx.quiet)?;
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

/// Renders `spec` into `out` (see the module docs) with a progress bar.
pub(crate) fn write_sequence(
    spec: &SynthSpec,
    out: &Path,
    quiet: bool,
) -> anyhow::Result<SynthSummary> {
    let start = Instant::now();
    let dirs: Vec<PathBuf> = ["image_0", "flow", "depth"]
        .iter()
        .chain(spec.baseline_m.map(|_| &"image_1"))
        .map(|d| out.join(d))
        .collect();
    for d in &dirs {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let cam = &spec.camera;
    let rig = spec
        .baseline_m
        .map(|b| StereoCamera::new(*cam, b))
        .transpose()
        .context("stereo rig")?;
    write_calib(&out.join("calib.txt"), cam, spec.baseline_m)?;
    let times: String = (0..spec.poses.len())
        .map(|i| format!("{:.6e}\n", i as f64 * 0.1))
        .collect();
    write_atomically(&out.join("times.txt"), times.as_bytes())?;
    write_kitti(&out.join("poses.txt"), &spec.poses)?;
    let settings = SynthSettings {
        seed: spec.scene.seed(),
        frames: spec.poses.len(),
        camera: cam,
        baseline_m: spec.baseline_m,
        trajectory: &spec.trajectory_source,
        scene: spec.scene.config(),
    };
    write_atomically(
        &out.join("synth.json"),
        serde_json::to_string_pretty(&settings)?.as_bytes(),
    )?;

    let bar = crate::progress::bar(spec.poses.len() as u64, "synth", quiet);
    let (mut render_s, mut flow_s, mut write_s, mut valid_sum) = (0.0, 0.0, 0.0, 0.0);
    let mut previous: Option<View> = None;
    for (i, pose) in spec.poses.iter().enumerate() {
        let t0 = Instant::now();
        let (left, right) = match &rig {
            Some(rig) => {
                let (l, r) = render_stereo(&spec.scene, rig, pose);
                (l, Some(r))
            }
            None => (render_view(&spec.scene, cam, pose), None),
        };
        let t1 = Instant::now();
        let flow = previous
            .as_ref()
            .map(|prev| flow_between(&spec.scene, cam, &spec.poses[i - 1], prev, pose, &left));
        let t2 = Instant::now();
        let name = format!("{i:06}");
        save_gray_png(
            &left.image,
            &out.join("image_0").join(format!("{name}.png")),
        )?;
        if let Some(r) = &right {
            save_gray_png(&r.image, &out.join("image_1").join(format!("{name}.png")))?;
        }
        let depth = PfmImage {
            width: cam.width as usize,
            height: cam.height as usize,
            channels: 1,
            data: left.depth_m.clone(),
        };
        write_pfm(&out.join("depth").join(format!("{name}.pfm")), &depth)?;
        if let Some(gt) = &flow {
            valid_sum += gt.valid_fraction();
            let path = out.join("flow").join(format!("{:06}.flo", i - 1));
            write_flo(&path, &gt.masked_flow())?;
        }
        let t3 = Instant::now();
        render_s += (t1 - t0).as_secs_f64();
        flow_s += (t2 - t1).as_secs_f64();
        write_s += (t3 - t2).as_secs_f64();
        previous = Some(left);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let n = spec.poses.len() as f64;
    let pairs = (spec.poses.len().saturating_sub(1)).max(1) as f64;
    let path_length_m = spec
        .poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    Ok(SynthSummary {
        out: out.to_path_buf(),
        frames: spec.poses.len(),
        width: cam.width,
        height: cam.height,
        stereo: spec.baseline_m.is_some(),
        seed: spec.scene.seed(),
        supersampling: spec.scene.config().supersampling,
        path_length_m,
        render_ms_per_frame: 1e3 * render_s / n,
        flow_ms_per_frame: 1e3 * flow_s / pairs,
        write_ms_per_frame: 1e3 * write_s / n,
        total_s: start.elapsed().as_secs_f64(),
        mean_flow_valid_fraction: valid_sum / pairs,
    })
}

/// Writes a KITTI `calib.txt`: `P0 = K [I | 0]`, `P1 = K [I | -b e_x]` (so `P1[0][3] = -fx b`).
fn write_calib(path: &Path, cam: &PinholeCamera, baseline_m: Option<f64>) -> anyhow::Result<()> {
    let row = |tx: f64| {
        format!(
            "{:.12e} 0.000000000000e+00 {:.12e} {:.12e} 0.000000000000e+00 {:.12e} {:.12e} 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00",
            cam.fx, cam.cx, tx, cam.fy, cam.cy
        )
    };
    let mut text = format!("P0: {}\n", row(0.0));
    if let Some(b) = baseline_m {
        text.push_str(&format!("P1: {}\n", row(-cam.fx * b)));
    }
    write_atomically(path, text.as_bytes())?;
    Ok(())
}
