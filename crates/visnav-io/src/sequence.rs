//! The sequence every input layout opens as ([`Sequence`]: frames read lazily, the rectified
//! camera, timestamps), at the bottom of the crate: it imports no layout. Each layout's reader
//! is a peer in its own module (`kitti`, `layouts`, `tum_mono`, `video`, `bag`) and builds a
//! `Sequence` through the constructors here (`finish`, `with_rectifier`, `bare`); a layout that
//! decodes its frames itself (a video, a bag's image messages) hands them over as
//! `DecodedFrames`. The one entry point that picks the layout by content
//! ([`Sequence::open_with_camera`]) is the module on top, [`crate::open`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::Matrix3x4;
use visnav_core::{GrayImage, PinholeCamera, StereoCamera};

use crate::calibration::Rectifier;
use crate::error::{IoError, Result};
use crate::image_io::load_gray;

/// Which on-disk layout a sequence uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SequenceLayout {
    /// KITTI odometry benchmark (`sequences/XX`).
    KittiOdometry,
    /// KITTI raw data (`YYYY_MM_DD_drive_NNNN_sync`).
    KittiRaw,
    /// EuRoC MAV / ASL (`mav0/cam0|cam1/data.csv`, `sensor.yaml`), rectified on load.
    Euroc,
    /// TUM RGB-D (`rgb.txt` + a camera file), undistorted on load.
    TumRgbd,
    /// TUM monoVO (`times.txt` + `camera.txt` + `images/`), undistorted on load.
    TumMono,
    /// A folder of PNG or JPEG images + a camera file, undistorted (or rectified) on load.
    ImageFolder,
    /// A video file decoded with ffmpeg + a camera file, undistorted on load.
    Video,
    /// A ROS 2 bag (MCAP file or rosbag2 directory): image topic(s) + `CameraInfo`
    /// (`crate::bag`).
    RosBag,
}

/// Frames a layout decodes itself rather than reading one image file per frame: a video's
/// (`crate::video`) or a ROS 2 bag's image messages (`crate::bag`). The layout implements it;
/// [`Sequence`] only calls it.
pub(crate) trait DecodedFrames: std::fmt::Debug + Send + Sync {
    /// Number of frames.
    fn len(&self) -> usize;
    /// Left (or only) frame `i`, before undistortion.
    ///
    /// # Errors
    /// An undecodable frame or one out of range.
    fn left(&self, i: usize) -> Result<GrayImage>;
    /// Right frame `i`, or `None` when the source has no right images.
    fn right(&self, i: usize) -> Option<Result<GrayImage>>;
    /// Whether right images exist.
    fn has_right(&self) -> bool;
}

/// What a sequence is: its layout, frames, camera and time span (`visnav info`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SequenceInfo {
    /// On-disk layout.
    pub layout: SequenceLayout,
    /// Frames.
    pub frames: usize,
    /// The (rectified) left camera the pipelines see.
    pub camera: PinholeCamera,
    /// Stereo baseline, metres, when the sequence is stereo.
    pub baseline_m: Option<f64>,
    /// Last timestamp minus the first, seconds.
    pub duration_s: f64,
}

/// A rectified (stereo) image sequence with calibration, frames loaded on demand. Layouts with
/// distorted or unrectified raw images (EuRoC, TUM, folders, video) are undistorted / rectified
/// on load with remap maps built once at opening; `camera` is then the rectified pinhole camera.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// Root directory of the sequence.
    pub root: PathBuf,
    /// On-disk layout.
    pub layout: SequenceLayout,
    /// Intrinsics of the left (reference) camera; `width`/`height` from the first frame.
    pub camera: PinholeCamera,
    /// Stereo baseline in metres, when a right camera with calibration exists.
    pub baseline_m: Option<f64>,
    /// The right rectified camera's principal-point column minus the left one's, pixels (`P1`'s
    /// `cx` minus `P0`'s; 0 when both are the same, as in KITTI's files, or after rectifying raw
    /// images): a constant of every disparity the stereo rig must know
    /// ([`StereoCamera::right_cx_offset_px`]).
    pub right_cx_offset_px: f64,
    /// Timestamps in seconds, one per frame (frame index times 0.1 s when the file is missing).
    pub timestamps: Vec<f64>,
    /// Whether `timestamps` are the dataset's own absolute times (EuRoC `data.csv`, TUM
    /// `rgb.txt`, monoVO `times.txt`) that a TUM-format trajectory should carry, rather than KITTI's relative
    /// `times.txt` or a frame rate.
    pub timestamped: bool,
    /// Calibrated layouts: `body_from_cam` of the rectified left camera (EuRoC `T_BS`).
    pub body_from_cam: Option<visnav_core::Pose>,
    left: Vec<PathBuf>,
    right: Option<Vec<PathBuf>>,
    /// Frames the layout decodes itself: a video's (the `Video` layout) or a ROS 2 bag's image
    /// messages (the `RosBag` layout); `left` then holds the file path only.
    decoded: Option<Arc<dyn DecodedFrames>>,
    /// Undistortion / rectification applied on load.
    rectifier: Option<Arc<Rectifier>>,
    /// Size of the raw images on disk, `(width, height)`.
    raw_size: (usize, usize),
}

/// The frames of a sequence as its layout lists them.
pub(crate) struct FrameFiles {
    /// Seconds of each left image.
    pub timestamps: Vec<f64>,
    /// Whether `timestamps` are the dataset's own absolute times (see `Sequence::timestamped`).
    pub timestamped: bool,
    /// The left (or only) camera's images.
    pub left: Vec<PathBuf>,
    /// The right camera's images, one per left image.
    pub right: Option<Vec<PathBuf>>,
}

impl Sequence {
    /// A sequence of `files` whose camera is `p0`'s (and the right camera `p1`'s), both read
    /// from `calib_path`.
    pub(crate) fn finish(
        root: &Path,
        layout: SequenceLayout,
        calib_path: &Path,
        (p0, p1): (Matrix3x4<f64>, Option<Matrix3x4<f64>>),
        files: FrameFiles,
    ) -> Result<Self> {
        let first = load_gray(&files.left[0])?;
        let camera = PinholeCamera::new(
            p0[(0, 0)],
            p0[(1, 1)],
            p0[(0, 2)],
            p0[(1, 2)],
            first.width() as u32,
            first.height() as u32,
        )
        .map_err(|e| IoError::Parse {
            path: calib_path.to_path_buf(),
            line: 1,
            message: e.to_string(),
        })?;
        let right_cx_offset_px = match (&files.right, p1) {
            (Some(_), Some(p1)) => crate::baseline::right_cx_offset(&p0, &p1, calib_path)?,
            _ => 0.0,
        };
        let field = match layout {
            SequenceLayout::KittiRaw => "P_rect_01",
            _ => "P1",
        };
        let baseline_m = match (&files.right, p1) {
            (Some(_), Some(p1)) => Some(crate::baseline::rectified_baseline(
                &p1, calib_path, field, &camera,
            )?),
            _ => None,
        };
        Ok(Self {
            root: root.to_path_buf(),
            layout,
            camera,
            baseline_m,
            right_cx_offset_px,
            timestamps: files.timestamps,
            timestamped: files.timestamped,
            body_from_cam: None,
            left: files.left,
            right: files.right,
            decoded: None,
            rectifier: None,
            raw_size: (first.width(), first.height()),
        })
    }

    /// A sequence whose raw images are undistorted / rectified by `rectifier` on load.
    pub(crate) fn with_rectifier(
        root: &Path,
        layout: SequenceLayout,
        rectifier: Arc<Rectifier>,
        raw_size: (usize, usize),
        files: FrameFiles,
        decoded: Option<Arc<dyn DecodedFrames>>,
    ) -> Self {
        Self {
            root: root.to_path_buf(),
            layout,
            camera: rectifier.camera,
            baseline_m: rectifier.baseline_m.filter(|_| files.right.is_some()),
            right_cx_offset_px: 0.0,
            timestamps: files.timestamps,
            timestamped: files.timestamped,
            body_from_cam: None,
            left: files.left,
            right: files.right,
            decoded,
            rectifier: Some(rectifier),
            raw_size,
        }
    }

    /// A sequence without image paths (frames come from `set_decoded`).
    #[cfg_attr(not(feature = "bag"), allow(dead_code))] // the bag layout's
    pub(crate) fn bare(
        root: &Path,
        layout: SequenceLayout,
        camera: PinholeCamera,
        baseline_m: Option<f64>,
        raw_size: (usize, usize),
    ) -> Self {
        Self {
            root: root.to_path_buf(),
            layout,
            camera,
            baseline_m,
            right_cx_offset_px: 0.0,
            timestamps: Vec::new(),
            timestamped: false,
            body_from_cam: None,
            left: vec![root.to_path_buf()],
            right: None,
            decoded: None,
            rectifier: None,
            raw_size,
        }
    }

    /// Undistorts / rectifies the frames on load with `rectifier`.
    #[cfg_attr(not(feature = "bag"), allow(dead_code))] // the bag layout's
    pub(crate) fn set_rectifier(&mut self, rectifier: Arc<Rectifier>) {
        self.rectifier = Some(rectifier);
    }

    /// Reads the frames from `frames` (a bag's image messages).
    #[cfg_attr(not(feature = "bag"), allow(dead_code))] // the bag layout's
    pub(crate) fn set_decoded(&mut self, frames: Arc<dyn DecodedFrames>) {
        self.decoded = Some(frames);
    }

    /// Whether right images exist (files or a paired bag topic).
    fn has_right_images(&self) -> bool {
        self.right.is_some() || self.decoded.as_ref().is_some_and(|d| d.has_right())
    }

    /// Layout, frames, camera, baseline and time span.
    #[must_use]
    pub fn info(&self) -> SequenceInfo {
        SequenceInfo {
            layout: self.layout,
            frames: self.len(),
            camera: self.camera,
            baseline_m: self.stereo_camera().map(|s| s.baseline_m),
            duration_s: self.timestamps.last().unwrap_or(&0.0)
                - self.timestamps.first().unwrap_or(&0.0),
        }
    }

    /// Number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        match &self.decoded {
            Some(d) => d.len(),
            None => self.left.len(),
        }
    }

    /// Whether the sequence has no frames (never true for an opened sequence).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether right images and a baseline are available.
    #[must_use]
    pub fn has_stereo(&self) -> bool {
        self.has_right_images() && self.baseline_m.is_some()
    }

    /// The stereo rig, when the sequence has a right camera.
    #[must_use]
    pub fn stereo_camera(&self) -> Option<StereoCamera> {
        self.baseline_m
            .and_then(|b| StereoCamera::new(self.camera, b).ok())
            .map(|rig| rig.with_right_cx_offset(self.right_cx_offset_px))
            .filter(|_| self.has_right_images())
    }

    /// Path of left frame `i` (the video file for the `Video` layout).
    #[must_use]
    pub fn left_path(&self, i: usize) -> &Path {
        if self.decoded.is_some() {
            return &self.left[0];
        }
        &self.left[i]
    }

    /// Path of right frame `i`, if the sequence is stereo.
    #[must_use]
    pub fn right_path(&self, i: usize) -> Option<&Path> {
        self.right.as_ref().map(|r| r[i].as_path())
    }

    /// Loads left frame `i`, checking its size against the sequence's.
    ///
    /// # Errors
    /// An undecodable image or one whose size differs from the first frame.
    pub fn load_left(&self, i: usize) -> Result<GrayImage> {
        let raw = match &self.decoded {
            Some(d) => d.left(i)?,
            None => self.load_checked(&self.left[i])?,
        };
        Ok(match &self.rectifier {
            Some(r) => r.left(raw),
            None => raw,
        })
    }

    /// Loads right frame `i`.
    ///
    /// # Errors
    /// No right camera, an undecodable image, or a size mismatch.
    pub fn load_right(&self, i: usize) -> Result<GrayImage> {
        let decoded = self.decoded.as_ref().and_then(|d| d.right(i));
        let raw = match (decoded, &self.right) {
            (Some(image), _) => image?,
            (None, Some(r)) => self.load_checked(&r[i])?,
            (None, None) => {
                return Err(IoError::NotFound {
                    path: self.root.clone(),
                    what: "right camera images".into(),
                });
            }
        };
        Ok(match &self.rectifier {
            Some(rect) => rect.right(raw),
            None => raw,
        })
    }

    fn load_checked(&self, path: &Path) -> Result<GrayImage> {
        crate::image_io::check_size(load_gray(path)?, path, self.raw_size)
    }
}
