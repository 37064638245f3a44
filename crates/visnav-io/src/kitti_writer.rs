//! Writing a sequence in the KITTI odometry layout, readable by [`crate::Sequence::open`]
//! (`visnav synth` and `visnav demo` write their rendered drives with it):
//!
//! ```text
//! DIR/image_0/NNNNNN.png   left camera (image_1/ for a stereo rig)
//! DIR/calib.txt            P0, P1 (P1[0][3] = -fx * baseline)
//! DIR/times.txt            seconds
//! DIR/poses.txt            ground truth world_from_cam of the left camera (KITTI format)
//! DIR/flow/NNNNNN.flo      optional: forward flow frame i -> i+1 of the left camera
//! DIR/depth/NNNNNN.pfm     optional: depth z of the left camera, metres
//! ```
//!
//! Every file is written atomically ([`crate::atomic::write_atomic`]).

use std::path::{Path, PathBuf};

use visnav_core::{FlowField, GrayImage, PinholeCamera, Pose};

use crate::error::{IoError, Result};
use crate::flo::write_flo;
use crate::image_io::save_gray_png;
use crate::pfm::{PfmImage, write_pfm};
use crate::trajectory::{write_atomically, write_kitti};

/// A KITTI odometry sequence directory being written (module docs for the layout).
#[derive(Debug, Clone)]
pub struct KittiSequenceWriter {
    dir: PathBuf,
    stereo: bool,
}

impl KittiSequenceWriter {
    /// Creates `dir` with `image_0/` (and `image_1/` when `baseline_m` is given), `flow/` and
    /// `depth/`, and writes `calib.txt` (`P0 = K [I | 0]`, `P1 = K [I | -b e_x]`), `times.txt`
    /// (one line per entry of `times_s`) and `poses.txt` (`world_from_cam` of the left camera).
    ///
    /// # Errors
    /// A directory or file that cannot be written; a baseline that is not finite and positive, or
    /// as many times as poses not given (the error names `dir`).
    pub fn create(
        dir: &Path,
        camera: &PinholeCamera,
        baseline_m: Option<f64>,
        times_s: &[f64],
        world_from_cam: &[Pose],
    ) -> Result<Self> {
        let format_error = |message: String| IoError::Format {
            path: dir.to_path_buf(),
            message,
        };
        if let Some(b) = baseline_m.filter(|b| !(b.is_finite() && *b > 0.0)) {
            return Err(format_error(format!(
                "stereo baseline {b} m is not finite and positive"
            )));
        }
        if times_s.len() != world_from_cam.len() {
            return Err(format_error(format!(
                "{} timestamps for {} poses",
                times_s.len(),
                world_from_cam.len()
            )));
        }
        let stereo = baseline_m.is_some();
        for sub in ["image_0", "flow", "depth"]
            .into_iter()
            .chain(stereo.then_some("image_1"))
        {
            let d = dir.join(sub);
            std::fs::create_dir_all(&d).map_err(|e| IoError::io(&d, e))?;
        }
        write_atomically(
            &dir.join("calib.txt"),
            calib_text(camera, baseline_m).as_bytes(),
        )?;
        let times: String = times_s.iter().map(|t| format!("{t:.6e}\n")).collect();
        write_atomically(&dir.join("times.txt"), times.as_bytes())?;
        write_kitti(&dir.join("poses.txt"), world_from_cam)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            stereo,
        })
    }

    /// The sequence directory.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes frame `index`: `image_0/NNNNNN.png`, and `image_1/NNNNNN.png` for a stereo
    /// sequence (`right` is required then, and refused for a mono one).
    ///
    /// # Errors
    /// A file that cannot be written; a right image missing or unexpected.
    pub fn write_images(
        &self,
        index: usize,
        left: &GrayImage,
        right: Option<&GrayImage>,
    ) -> Result<()> {
        let name = format!("{index:06}.png");
        if self.stereo != right.is_some() {
            // checked before anything is written: a half-written frame would break the pairing
            return Err(IoError::Format {
                path: self.dir.join("image_1").join(name),
                message: if self.stereo {
                    "a stereo sequence needs a right image for every frame".into()
                } else {
                    "a right image for a mono sequence".into()
                },
            });
        }
        save_gray_png(left, &self.dir.join("image_0").join(&name))?;
        right.map_or(Ok(()), |r| {
            save_gray_png(r, &self.dir.join("image_1").join(&name))
        })
    }

    /// Writes the depth map of frame `index` (row-major, metres) as `depth/NNNNNN.pfm`.
    ///
    /// # Errors
    /// A file that cannot be written or a buffer of the wrong size.
    pub fn write_depth_m(
        &self,
        index: usize,
        width: usize,
        height: usize,
        depth_m: &[f32],
    ) -> Result<()> {
        let depth = PfmImage {
            width,
            height,
            channels: 1,
            data: depth_m.to_vec(),
        };
        write_pfm(
            &self.dir.join("depth").join(format!("{index:06}.pfm")),
            &depth,
        )
    }

    /// Writes the forward flow frame `index` → `index + 1` as `flow/NNNNNN.flo`.
    ///
    /// # Errors
    /// A file that cannot be written.
    pub fn write_flow(&self, index: usize, flow: &FlowField) -> Result<()> {
        write_flo(&self.dir.join("flow").join(format!("{index:06}.flo")), flow)
    }
}

/// The text of a KITTI `calib.txt`: `P0 = K [I | 0]` and, with a baseline,
/// `P1 = K [I | -b e_x]` (so `P1[0][3] = -fx b`).
#[must_use]
pub fn calib_text(camera: &PinholeCamera, baseline_m: Option<f64>) -> String {
    let row = |tx: f64| {
        format!(
            "{:.12e} 0.000000000000e+00 {:.12e} {:.12e} 0.000000000000e+00 {:.12e} {:.12e} 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00",
            camera.fx, camera.cx, tx, camera.fy, camera.cy
        )
    };
    let mut text = format!("P0: {}\n", row(0.0));
    if let Some(b) = baseline_m {
        text.push_str(&format!("P1: {}\n", row(-camera.fx * b)));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_sequence_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let cam = PinholeCamera::new(100.0, 100.0, 15.5, 11.5, 32, 24).unwrap();
        let poses: Vec<Pose> = (0..3)
            .map(|i| Pose::translation(0.0, 0.0, f64::from(i)))
            .collect();
        let w = KittiSequenceWriter::create(dir.path(), &cam, Some(0.5), &[0.0, 0.1, 0.2], &poses)
            .unwrap();
        let img = GrayImage::from_fn(32, 24, |x, y| (x * 7 + y * 3) as f32);
        for i in 0..3 {
            w.write_images(i, &img, Some(&img)).unwrap();
        }
        assert!(w.write_images(3, &img, None).is_err());
        let seq = crate::Sequence::open(dir.path()).unwrap();
        assert_eq!(seq.len(), 3);
        let rig = seq.stereo_camera().unwrap();
        assert!((rig.baseline_m - 0.5).abs() < 1e-12, "{}", rig.baseline_m);
        let read = crate::trajectory::read_kitti(&dir.path().join("poses.txt")).unwrap();
        assert!((read[2].translation.vector.z - 2.0).abs() < 1e-9);

        let err = KittiSequenceWriter::create(dir.path(), &cam, Some(-1.0), &[0.0], &poses[..1])
            .unwrap_err()
            .to_string();
        assert!(err.contains("baseline"), "{err}");
        let err = KittiSequenceWriter::create(dir.path(), &cam, None, &[0.0], &poses)
            .unwrap_err()
            .to_string();
        assert!(err.contains("1 timestamps for 3 poses"), "{err}");
    }
}
