//! The sequence every input layout opens as ([`Sequence`]: frames read lazily, the rectified
//! camera, timestamps) and the one entry point that picks the layout by content
//! ([`Sequence::open_with_camera`]: a ROS 2 bag, a video file, KITTI odometry or raw, EuRoC,
//! TUM RGB-D, TUM monoVO, an image folder). Each layout's reader lives in its own module
//! (`kitti`, `layouts`, `tum_mono`, `video`, `bag`) and builds a `Sequence` through the
//! constructors here (`finish`, `with_rectifier`, `bare`).

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
    /// Decoded video frames (the `Video` layout; `left` then holds the video path only).
    video: Option<Arc<crate::video::VideoFrames>>,
    /// Image messages of a ROS 2 bag (the `RosBag` layout; `left` then holds the bag path only).
    bag: Option<Arc<crate::bag::BagFrames>>,
    /// Undistortion / rectification applied on load.
    rectifier: Option<Arc<Rectifier>>,
    /// Size of the raw images on disk, `(width, height)`.
    raw_size: (usize, usize),
}

impl Sequence {
    /// Opens a KITTI odometry sequence directory or a KITTI raw drive directory, detecting which.
    ///
    /// # Errors
    /// A missing directory, calibration or image folder, a malformed calibration line, an
    /// empty sequence, or a first image that cannot be decoded.
    pub fn open(root: &Path) -> Result<Self> {
        Self::open_with_camera(root, None)
    }

    /// Opens any supported input: a KITTI odometry or raw directory, an EuRoC (ASL) sequence, a
    /// TUM RGB-D folder (`rgb.txt`), a TUM monoVO sequence (`times.txt` + `camera.txt` +
    /// `images/`), a folder of PNG or JPEG images, or a video file. `camera` is a camera file
    /// (`crate::calibration`); it is required for TUM RGB-D, folders and video (unless the
    /// folder holds `camera.yaml` / `camera.toml`), overrides EuRoC's `sensor.yaml` and monoVO's
    /// `camera.txt`, and is an error for KITTI, which carries its own rectified calibration.
    ///
    /// # Errors
    /// As [`Self::open`], plus calibration that is missing, malformed, does not fit the images
    /// (size), or cannot be rectified; every message names the file.
    pub fn open_with_camera(root: &Path, camera: Option<&Path>) -> Result<Self> {
        let meta = match std::fs::metadata(root) {
            Ok(m) => m,
            Err(e)
                if e.kind() == std::io::ErrorKind::NotFound && root.symlink_metadata().is_err() =>
            {
                return Err(IoError::NotFound {
                    path: root.to_path_buf(),
                    what: "sequence directory or video file".into(),
                });
            }
            // a dangling link, a symlink loop, no permission: say so, not "not found"
            Err(e) => return Err(IoError::io(root, e)),
        };
        if crate::bag::is_bag(root) {
            let options = crate::bag::BagOptions {
                camera: camera.map(Path::to_path_buf),
                ..crate::bag::BagOptions::default()
            };
            return crate::bag::open_bag_sequence(root, &options);
        }
        if meta.is_file() {
            if looks_like_text(root) {
                return Err(IoError::Format {
                    path: root.to_path_buf(),
                    message: "is a text file, not a sequence: give the sequence directory (KITTI, EuRoC, TUM, an image folder) or a video file".into(),
                });
            }
            return crate::video::open_video(root, camera);
        }
        if !meta.is_dir() {
            return Err(IoError::Format {
                path: root.to_path_buf(),
                message: "is neither a directory nor a regular file (expected a sequence directory or a video file)".into(),
            });
        }
        let kitti = root.join("calib.txt").exists()
            || root.join("image_0").is_dir()
            || root.join("image_00").is_dir();
        if !kitti {
            return crate::layouts::open_calibrated(root, camera);
        }
        if let Some(c) = camera {
            return Err(IoError::Format {
                path: c.to_path_buf(),
                message: format!(
                    "{} is a KITTI sequence with its own rectified calibration: drop --camera",
                    root.display()
                ),
            });
        }
        if root.join("calib.txt").exists()
            || root.join("image_0").is_dir() && !root.join("image_00").is_dir()
        {
            crate::kitti::open_odometry(root)
        } else if root.join("image_00").is_dir() {
            crate::kitti::raw::open_raw(root)
        } else {
            Err(IoError::NotFound {
                path: root.to_path_buf(),
                what: "a KITTI sequence (expected image_0/ + calib.txt, or a raw drive with image_00/data/)".into(),
            })
        }
    }

    #[allow(clippy::too_many_arguments)]
    pub(crate) fn finish(
        root: &Path,
        layout: SequenceLayout,
        calib_path: &Path,
        p0: Matrix3x4<f64>,
        p1: Option<Matrix3x4<f64>>,
        timestamps: Vec<f64>,
        left: Vec<PathBuf>,
        right: Option<Vec<PathBuf>>,
    ) -> Result<Self> {
        let first = load_gray(&left[0])?;
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
        let right_cx_offset_px = match (&right, p1) {
            (Some(_), Some(p1)) => crate::kitti::right_cx_offset(&p0, &p1, calib_path)?,
            _ => 0.0,
        };
        let baseline_m = match (&right, p1) {
            (Some(_), Some(p1)) => Some(crate::baseline::rectified_baseline(
                &p1, calib_path, layout, &camera,
            )?),
            _ => None,
        };
        Ok(Self {
            root: root.to_path_buf(),
            layout,
            camera,
            baseline_m,
            right_cx_offset_px,
            timestamps,
            timestamped: false,
            body_from_cam: None,
            left,
            right,
            video: None,
            bag: None,
            rectifier: None,
            raw_size: (first.width(), first.height()),
        })
    }

    /// A sequence whose raw images are undistorted / rectified by `rectifier` on load.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn with_rectifier(
        root: &Path,
        layout: SequenceLayout,
        rectifier: Arc<Rectifier>,
        raw_size: (usize, usize),
        timestamps: Vec<f64>,
        timestamped: bool,
        left: Vec<PathBuf>,
        right: Option<Vec<PathBuf>>,
        video: Option<Arc<crate::video::VideoFrames>>,
    ) -> Self {
        Self {
            root: root.to_path_buf(),
            layout,
            camera: rectifier.camera,
            baseline_m: rectifier.baseline_m.filter(|_| right.is_some()),
            right_cx_offset_px: 0.0,
            timestamps,
            timestamped,
            body_from_cam: None,
            left,
            right,
            video,
            bag: None,
            rectifier: Some(rectifier),
            raw_size,
        }
    }

    /// A sequence without image paths (frames come from `set_bag`).
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
            video: None,
            bag: None,
            rectifier: None,
            raw_size,
        }
    }

    /// Undistorts / rectifies the frames on load with `rectifier`.
    pub(crate) fn set_rectifier(&mut self, rectifier: Arc<Rectifier>) {
        self.rectifier = Some(rectifier);
    }

    /// Reads the frames from a bag's image messages.
    pub(crate) fn set_bag(&mut self, frames: Arc<crate::bag::BagFrames>) {
        self.bag = Some(frames);
    }

    /// Whether right images exist (files or a paired bag topic).
    fn has_right_images(&self) -> bool {
        self.right.is_some() || self.bag.as_ref().is_some_and(|b| b.has_right())
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
        match (&self.video, &self.bag) {
            (Some(v), _) => v.len(),
            (None, Some(b)) => b.len(),
            (None, None) => self.left.len(),
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
        if self.video.is_some() || self.bag.is_some() {
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
        let raw = match (&self.video, &self.bag) {
            (Some(v), _) => v.frame(i)?,
            (None, Some(b)) => b.left(i)?,
            (None, None) => self.load_checked(&self.left[i])?,
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
        let raw = match (&self.right, &self.bag) {
            (_, Some(b)) => b.right(i)?,
            (Some(r), None) => self.load_checked(&r[i])?,
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

/// Whether the first bytes of a file are text (UTF-8 without control bytes): a text file given where a
/// video or a sequence is expected.
fn looks_like_text(path: &Path) -> bool {
    use std::io::Read as _;
    // a Y4M video starts with a text header and may hold ASCII-only pixels
    let video_ext = ["y4m", "yuv", "mp4", "mkv", "avi", "mov", "webm"];
    if path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| video_ext.iter().any(|v| e.eq_ignore_ascii_case(v)))
    {
        return false;
    }
    let mut head = Vec::new();
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    if f.take(4096).read_to_end(&mut head).is_err() || head.is_empty() {
        return false;
    }
    // control characters other than tab, line ends and form feed mean binary data
    if head
        .iter()
        .any(|&b| b < 0x20 && !matches!(b, b'\t' | b'\n' | b'\r' | 0x0c))
    {
        return false;
    }
    match std::str::from_utf8(&head) {
        Ok(_) => true,
        // a multi-byte character cut at the 4 KiB boundary is still text
        Err(e) => e.error_len().is_none(),
    }
}
