//! Writing a rendered sequence in the KITTI odometry layout, readable by
//! `visnav_io::Sequence::open` (`visnav synth`, `visnav demo`):
//!
//! ```text
//! DIR/image_0/NNNNNN.png   left camera (image_1/ for a stereo rig)
//! DIR/calib.txt            P0, P1 (P1[0][3] = -fx * baseline)
//! DIR/times.txt            seconds, 10 Hz
//! DIR/poses.txt            ground truth world_from_cam of the left camera (KITTI format)
//! DIR/flow/NNNNNN.flo      forward flow frame i -> i+1 of the left camera; 1e10 = occluded/out
//! DIR/depth/NNNNNN.pfm     depth z of the left camera, metres (inf = sky)
//! DIR/synth.json           the effective settings
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use visnav_core::{PinholeCamera, Pose, Progress, StereoCamera};
use visnav_io::IoError;
use visnav_io::flo::write_flo;
use visnav_io::image_io::save_gray_png;
use visnav_io::pfm::{PfmImage, write_pfm};
use visnav_io::trajectory::{write_atomically, write_kitti};

use crate::{Scene, SceneConfig, View, flow_between, render_stereo, render_view};

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
    let dirs: Vec<PathBuf> = ["image_0", "flow", "depth"]
        .iter()
        .chain(spec.baseline_m.map(|_| &"image_1"))
        .map(|d| out.join(d))
        .collect();
    for d in &dirs {
        std::fs::create_dir_all(d).map_err(|e| IoError::io(d, e))?;
    }
    let cam = &spec.camera;
    let rig = spec
        .baseline_m
        .map(|b| StereoCamera::new(*cam, b))
        .transpose()
        .map_err(|e| IoError::Format {
            path: out.to_path_buf(),
            message: format!("stereo rig: {e}"),
        })?;
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

/// Writes a KITTI `calib.txt`: `P0 = K [I | 0]`, `P1 = K [I | -b e_x]` (so `P1[0][3] = -fx b`).
fn write_calib(path: &Path, cam: &PinholeCamera, baseline_m: Option<f64>) -> Result<(), IoError> {
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
