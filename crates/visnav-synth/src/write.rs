//! Rendering a sequence and handing each frame to the KITTI-layout writer of `visnav-io`
//! ([`visnav_io::kitti_writer::KittiSequenceWriter`], which owns the layout), readable by
//! `visnav_io::Sequence::open` (`visnav synth`, `visnav demo`). What this crate adds to that
//! layout: times at 10 Hz, the ground-truth flow (`flow/NNNNNN.flo`, frame i -> i+1 of the left
//! camera; 1e10 = occluded/out), the depth (`depth/NNNNNN.pfm`, metres, inf = sky) and
//! `synth.json` (the effective settings).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use visnav_core::{PinholeCamera, Pose, Progress, StereoCamera};
use visnav_io::IoError;
use visnav_io::kitti_writer::KittiSequenceWriter;
use visnav_io::trajectory::write_atomically;

use crate::{Scene, SceneConfig, View, flow_between, render_stereo, render_view};

/// Checks the image options of a rendering: width and height within 16..=8192 pixels,
/// supersampling within 1..=8.
///
/// # Errors
/// [`crate::SynthError::InvalidConfig`] naming the option.
pub fn check_image_options(
    width: u32,
    height: u32,
    supersampling: u32,
) -> Result<(), crate::SynthError> {
    let bad = |field: &str, message: String| {
        Err(crate::SynthError::InvalidConfig {
            field: field.into(),
            message,
        })
    };
    if !(16..=8192).contains(&width) || !(16..=8192).contains(&height) {
        return bad(
            "width/height",
            format!("must be within 16..=8192 pixels, got {width}x{height}"),
        );
    }
    if !(1..=8).contains(&supersampling) {
        return bad(
            "supersampling",
            format!("must be within 1..=8, got {supersampling}"),
        );
    }
    Ok(())
}

/// What to render: the scene, the camera(s) and the poses.
pub struct SynthSpec {
    /// The scene.
    pub scene: Scene,
    /// The (left) camera.
    pub camera: PinholeCamera,
    /// Stereo baseline in metres; `None` for mono.
    pub baseline_m: Option<f64>,
    /// Left-camera poses, `world_from_cam`.
    pub poses: Vec<Pose>,
    /// Where the poses came from (for synth.json).
    pub trajectory_source: String,
    /// Time between frames, seconds (`times.txt`; 0.1 for KITTI's 10 Hz).
    pub frame_interval_s: f64,
}

/// Figures of a rendered sequence.
#[derive(Debug, Clone, Serialize)]
pub struct SynthSummary {
    /// The sequence directory.
    pub out: PathBuf,
    /// Frames rendered.
    pub frames: usize,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Whether the right camera was rendered.
    pub stereo: bool,
    /// Seed of the scene.
    pub seed: u64,
    /// Supersampling factor of the renderer.
    pub supersampling: u32,
    /// Length of the camera path, metres.
    pub path_length_m: f64,
    /// Mean time to render one frame (both cameras with --stereo), ms.
    pub render_ms_per_frame: f64,
    /// Mean time of one ground-truth flow field, ms.
    pub flow_ms_per_frame: f64,
    /// Mean time to write one frame's files, ms.
    pub write_ms_per_frame: f64,
    /// Wall time of the whole rendering, seconds.
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

/// Renders `spec` into `out` (see the module docs), reporting each frame to `progress`.
///
/// # Errors
/// A file that cannot be written, or an invalid stereo baseline (the error names `out`).
pub fn write_sequence(
    spec: &SynthSpec,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SynthSummary, IoError> {
    let start = Instant::now();
    let cam = &spec.camera;
    let rig = spec
        .baseline_m
        .map(|b| StereoCamera::new(*cam, b))
        .transpose()
        .map_err(|e| IoError::Format {
            path: out.to_path_buf(),
            message: format!("stereo rig: {e}"),
        })?;
    if !(spec.frame_interval_s.is_finite() && spec.frame_interval_s > 0.0) {
        return Err(IoError::Format {
            path: out.to_path_buf(),
            message: format!(
                "the frame interval must be finite and positive, got {} s",
                spec.frame_interval_s
            ),
        });
    }
    let times_s: Vec<f64> = (0..spec.poses.len())
        .map(|i| i as f64 * spec.frame_interval_s)
        .collect();
    let writer = KittiSequenceWriter::create(out, cam, spec.baseline_m, &times_s, &spec.poses)?;
    let settings = SynthSettings {
        seed: spec.scene.seed(),
        frames: spec.poses.len(),
        camera: cam,
        baseline_m: spec.baseline_m,
        trajectory: &spec.trajectory_source,
        scene: spec.scene.config(),
    };
    let json = serde_json::to_string_pretty(&settings).map_err(|e| IoError::Format {
        path: out.join("synth.json"),
        message: e.to_string(),
    })?;
    write_atomically(&out.join("synth.json"), json.as_bytes())?;

    let total = spec.poses.len() as u64;
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
        writer.write_images(i, &left.image, right.as_ref().map(|r| &r.image))?;
        writer.write_depth_m(i, cam.width as usize, cam.height as usize, &left.depth_m)?;
        if let Some(gt) = &flow {
            valid_sum += gt.valid_fraction();
            writer.write_flow(i - 1, &gt.masked_flow())?;
        }
        let t3 = Instant::now();
        render_s += (t1 - t0).as_secs_f64();
        flow_s += (t2 - t1).as_secs_f64();
        write_s += (t3 - t2).as_secs_f64();
        previous = Some(left);
        progress.step("synth", i as u64 + 1, total);
    }
    let n = spec.poses.len() as f64;
    let pairs = (spec.poses.len().saturating_sub(1)).max(1) as f64;
    let path_length_m = visnav_core::se3::path_length_m(&spec.poses);
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
