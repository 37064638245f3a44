//! Rendering an indoor flight ([`crate::IndoorFlightConfig`]) into what a small drone's user
//! has: a folder of JPEG images with a camera file, readable by `visnav_io::Sequence::open` (and
//! `visnav odometry DIR`), which undistorts the images on load.
//!
//! | path | content |
//! | --- | --- |
//! | `NNNNNN.jpg` | the raw (distorted) 8-bit grey images: rendered through the lens, averaged over the exposure (motion blur), vignetted, sensor noise added, JPEG-compressed |
//! | `camera.yaml` | Kalibr-style: `intrinsics [fx, fy, cx, cy]`, `distortion_model: radtan`, `distortion_coeffs [k1, k2, 0, 0]`, `resolution`, `rate_hz` (the kept frames' rate) |
//! | `poses.txt` | exact ground truth (KITTI format, `world_from_cam`, the first camera at the origin) |
//! | `times.txt` | timestamps, seconds |
//! | `heights.txt` | the camera's height above the floor at each frame, metres |
//! | `depth/NNNNNN.pfm` | depth `z` (metres) of the ray through each raw pixel's centre, at the middle of the exposure |
//! | `synth.json` | the effective settings |

use std::path::Path;
use std::time::Instant;

use serde::Serialize;
use visnav_core::{GrayImage, Progress};
use visnav_io::IoError;
use visnav_io::pfm::{PfmImage, write_pfm};
use visnav_io::trajectory::{write_atomically, write_kitti};

use crate::noise::hash2;
use crate::render::{LensRays, render_view_through};
use crate::write::SynthSummary;
use crate::{IndoorFlightConfig, Scene, indoor_flight};

#[derive(Serialize)]
struct IndoorSettings<'a> {
    seed: u64,
    frames: usize,
    flight: &'a IndoorFlightConfig,
}

/// The Kalibr-style camera file of the flight's camera (module docs).
#[must_use]
pub fn camera_yaml(config: &IndoorFlightConfig) -> String {
    let c = &config.camera;
    let (cx, cy) = (
        0.5 * f64::from(c.width) - 0.5,
        0.5 * f64::from(c.height) - 0.5,
    );
    format!(
        "# visnav synth --flight indoor: a downward camera with radial distortion\n\
         cam0:\n  camera_model: pinhole\n  intrinsics: [{f}, {f}, {cx}, {cy}]\n  \
         distortion_model: radtan\n  distortion_coeffs: [{k1}, {k2}, 0.0, 0.0]\n  \
         resolution: [{w}, {h}]\nrate_hz: {rate}\n",
        f = c.focal_px,
        k1 = c.k1,
        k2 = c.k2,
        w = c.width,
        h = c.height,
        rate = 1.0 / config.frame_interval_s(),
    )
}

/// Sensor noise: a zero-mean value of standard deviation `sd` for pixel `i` of frame `frame`
/// (the sum of four hashed uniforms, scaled; deterministic).
fn noise(i: usize, frame: usize, seed: u32, sd: f64) -> f32 {
    let sum: f64 = (0..4u32)
        .map(|k| {
            f64::from(hash2(i as i64, frame as i64, seed ^ (0x6e6f_6973 + k))) / f64::from(u32::MAX)
        })
        .sum();
    // four uniforms: mean 2, variance 4/12
    ((sum - 2.0) * sd / (4.0f64 / 12.0).sqrt()) as f32
}

/// The brightness of each pixel relative to the image centre: `1 − (1 − corner) (r / r_corner)²`.
fn vignetting(w: usize, h: usize, corner: f64) -> Vec<f32> {
    let (cx, cy) = (0.5 * w as f64 - 0.5, 0.5 * h as f64 - 0.5);
    let r2_corner = (cx * cx + cy * cy).max(1e-9);
    (0..w * h)
        .map(|i| {
            let (dx, dy) = ((i % w) as f64 - cx, (i / w) as f64 - cy);
            (1.0 - (1.0 - corner) * (dx * dx + dy * dy) / r2_corner) as f32
        })
        .collect()
}

/// The JPEG bytes of an 8-bit grey image.
fn jpeg(image: &GrayImage, quality: u8, path: &Path) -> Result<Vec<u8>, IoError> {
    let bytes: Vec<u8> = image
        .data()
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
        .encode(
            &bytes,
            image.width() as u32,
            image.height() as u32,
            image::ExtendedColorType::L8,
        )
        .map_err(|e| IoError::Format {
            path: path.to_path_buf(),
            message: format!("JPEG encoding: {e}"),
        })?;
    Ok(out)
}

/// Renders `frames` frames of the indoor flight `config` over the floor of `seed` into `out`
/// (module docs), reporting each frame to `progress`.
///
/// # Errors
/// An invalid config, or a file that cannot be written (the error names it).
pub fn write_indoor_flight(
    config: &IndoorFlightConfig,
    frames: usize,
    seed: u64,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SynthSummary, IoError> {
    let start = Instant::now();
    let invalid = |e: crate::SynthError| IoError::Format {
        path: out.to_path_buf(),
        message: e.to_string(),
    };
    let flight = indoor_flight(frames, config).map_err(invalid)?;
    let cam = config.camera.calibrated().map_err(invalid)?;
    let poses = flight.frame_poses(frames);
    // the floor is laid out along the level path (a plane exactly takeoff_height_m below the
    // first camera), whatever the heights flown
    let level: Vec<_> = poses
        .iter()
        .map(|p| {
            let mut q = *p;
            q.translation.vector.y = 0.0;
            q
        })
        .collect();
    let scene = Scene::along_with(&level, seed, config.scene()).map_err(invalid)?;
    std::fs::create_dir_all(out.join("depth")).map_err(|e| IoError::io(out, e))?;
    let dt = config.frame_interval_s();
    let times: String = (0..frames)
        .map(|k| format!("{:.6}\n", k as f64 * dt))
        .collect();
    write_atomically(&out.join("times.txt"), times.as_bytes())?;
    let heights: String = (0..frames)
        .map(|k| format!("{:.9}\n", flight.height_at(k as f64 * dt)))
        .collect();
    write_atomically(&out.join("heights.txt"), heights.as_bytes())?;
    write_kitti(&out.join("poses.txt"), &poses)?;
    write_atomically(&out.join("camera.yaml"), camera_yaml(config).as_bytes())?;
    let settings = IndoorSettings {
        seed,
        frames,
        flight: config,
    };
    let json = serde_json::to_string_pretty(&settings).map_err(|e| IoError::Format {
        path: out.join("synth.json"),
        message: e.to_string(),
    })?;
    write_atomically(&out.join("synth.json"), json.as_bytes())?;

    let (w, h) = (cam.pinhole.width as usize, cam.pinhole.height as usize);
    let n = config.blur_samples.max(1) as usize;
    let lens = LensRays::new(&cam);
    let vignetting = vignetting(w, h, config.corner_brightness);
    let (mut render_s, mut write_s) = (0.0, 0.0);
    for k in 0..frames {
        let t0 = Instant::now();
        let t_s = k as f64 * dt;
        let mut sum = vec![0.0f32; w * h];
        let mut depth = None;
        for j in 0..n {
            // sample times spread evenly over the exposure, centred on the frame's time
            let offset = if n == 1 {
                0.0
            } else {
                config.exposure_s * (j as f64 / (n - 1) as f64 - 0.5)
            };
            let view = render_view_through(&scene, &lens, &flight.pose_at(t_s + offset));
            for (s, v) in sum.iter_mut().zip(view.image.data()) {
                *s += v;
            }
            if j == n / 2 {
                depth = Some(view.depth_m);
            }
        }
        let pixels: Vec<f32> = sum
            .iter()
            .zip(&vignetting)
            .enumerate()
            .map(|(i, (s, v))| s * v / n as f32 + noise(i, k, seed as u32, config.noise_sd))
            .collect();
        let image = GrayImage::from_vec(w, h, pixels).unwrap_or_else(|| GrayImage::new(w, h, 0.0));
        let t1 = Instant::now();
        let path = out.join(format!("{k:06}.jpg"));
        write_atomically(&path, &jpeg(&image, config.jpeg_quality, &path)?)?;
        let depth_path = out.join("depth").join(format!("{k:06}.pfm"));
        let pfm = PfmImage {
            width: w,
            height: h,
            channels: 1,
            data: depth.unwrap_or_default(),
        };
        write_pfm(&depth_path, &pfm)?;
        render_s += (t1 - t0).as_secs_f64();
        write_s += t1.elapsed().as_secs_f64();
        progress.step("synth", k as u64 + 1, frames as u64);
    }
    let nf = frames.max(1) as f64;
    Ok(SynthSummary {
        out: out.to_path_buf(),
        frames,
        width: cam.pinhole.width,
        height: cam.pinhole.height,
        stereo: false,
        seed,
        supersampling: scene.config().supersampling,
        path_length_m: visnav_core::se3::path_length_m(&poses),
        render_ms_per_frame: 1e3 * render_s / nf,
        flow_ms_per_frame: 0.0,
        write_ms_per_frame: 1e3 * write_s / nf,
        total_s: start.elapsed().as_secs_f64(),
        mean_flow_valid_fraction: 0.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::NoProgress;

    /// A short small flight: the folder opens as a calibrated sequence whose camera file carries
    /// the distortion, the images are the raw (distorted) renders, and the ground truth has a
    /// pose and a height for every image.
    #[test]
    fn an_indoor_flight_is_a_folder_the_reader_undistorts() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = IndoorFlightConfig {
            camera: crate::IndoorCamera::default().resized(160, 90),
            blur_samples: 2,
            ..IndoorFlightConfig::default()
        };
        let summary = write_indoor_flight(&cfg, 6, 3, dir.path(), &NoProgress).unwrap();
        assert_eq!(summary.frames, 6);
        let calib =
            visnav_io::calibration::read_camera_file(&dir.path().join("camera.yaml")).unwrap();
        assert_eq!(calib.left.distortion.coefficients()[..2], [0.19, -0.56]);
        assert_eq!(calib.rate_hz, Some(10.0));
        assert!((calib.left.pinhole.fx - 140.0).abs() < 1e-12);
        let seq = visnav_io::Sequence::open(dir.path()).unwrap();
        assert_eq!(seq.len(), 6);
        let poses = visnav_io::trajectory::read_kitti(&dir.path().join("poses.txt")).unwrap();
        assert_eq!(poses.len(), 6);
        let heights = std::fs::read_to_string(dir.path().join("heights.txt")).unwrap();
        let first: f64 = heights.lines().next().unwrap().parse().unwrap();
        assert!((first - 0.1).abs() < 1e-9);
        // the depth at the centre pixel of the first frame is the takeoff height
        let depth = visnav_io::pfm::read_pfm(&dir.path().join("depth/000000.pfm")).unwrap();
        let centre = depth.data[45 * 160 + 80];
        assert!((f64::from(centre) - 0.1).abs() < 1e-3, "{centre}");
    }
}
