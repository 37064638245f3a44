//! Opening an input by its content: the one module that knows every layout, on top of the
//! crate. It picks the reader ([`Sequence::open_with_camera`], [`open_input`]): a ROS 2 bag
//! (`crate::bag`, the `bag` feature), a video file (`crate::video`, the `video` feature), KITTI
//! odometry or raw ([`crate::kitti`]), EuRoC, TUM RGB-D or an image folder
//! ([`crate::layouts`]), TUM monoVO ([`crate::tum_mono`]). The layouts are peers below it that
//! know nothing of each other; each builds a [`Sequence`] (`crate::sequence`, at the bottom).
//!
//! A build without the `bag` or `video` feature still recognises a bag or a video file and says
//! which feature reads it (an error, not a panic).

use std::path::Path;

use crate::error::{IoError, Result};
use crate::sequence::Sequence;

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
    /// `images/`), a folder of PNG or JPEG images, a video file or a ROS 2 bag. `camera` is a
    /// camera file (`crate::calibration`); it is required for TUM RGB-D, folders and video
    /// (unless the folder holds `camera.yaml` / `camera.toml`), overrides EuRoC's `sensor.yaml`
    /// and monoVO's `camera.txt`, and is an error for KITTI, which carries its own rectified
    /// calibration.
    ///
    /// # Errors
    /// As [`Self::open`], plus calibration that is missing, malformed, does not fit the images
    /// (size), or cannot be rectified; every message names the file. A bag or a video file in
    /// a build without the `bag` / `video` feature is an error naming the feature.
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
        if is_bag(root) {
            return open_bag(root, camera, None, None);
        }
        if meta.is_file() {
            if looks_like_text(root) {
                return Err(IoError::Format {
                    path: root.to_path_buf(),
                    message: "is a text file, not a sequence: give the sequence directory (KITTI, EuRoC, TUM, an image folder) or a video file".into(),
                });
            }
            return open_video(root, camera);
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
            return open_calibrated(root, camera);
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
}

/// Opens any input: a ROS 2 bag (when `path` is one, or a topic is given) with its topics, or
/// every other layout ([`Sequence::open_with_camera`]).
///
/// # Errors
/// As `bag::open_bag_sequence` or [`Sequence::open_with_camera`]; a bag (or a topic) in a build
/// without the `bag` feature.
pub fn open_input(
    path: &Path,
    camera: Option<&Path>,
    topic: Option<&str>,
    right_topic: Option<&str>,
) -> Result<Sequence> {
    if topic.is_some() || right_topic.is_some() || is_bag(path) {
        open_bag(path, camera, topic, right_topic)
    } else {
        Sequence::open_with_camera(path, camera)
    }
}

/// Whether `path` looks like a ROS bag: an `.mcap` / `.db3` file or a directory with
/// `metadata.yaml` (known with or without the `bag` feature).
#[must_use]
pub fn is_bag(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("mcap" | "db3"))
        || (path.is_dir() && path.join("metadata.yaml").is_file())
}

/// A non-KITTI directory: EuRoC, TUM RGB-D, TUM monoVO, or an image folder.
fn open_calibrated(root: &Path, camera: Option<&Path>) -> Result<Sequence> {
    if let Some(mav0) = crate::layouts::euroc_root(root) {
        return crate::layouts::open_euroc(root, &mav0, camera);
    }
    if crate::layouts::is_tum_rgbd(root) {
        return crate::layouts::open_tum(root, camera);
    }
    if crate::tum_mono::is_tum_mono(root) {
        return crate::tum_mono::open_tum_mono(root, camera);
    }
    crate::layouts::open_folder(root, camera)
}

#[cfg(feature = "bag")]
fn open_bag(
    path: &Path,
    camera: Option<&Path>,
    topic: Option<&str>,
    right_topic: Option<&str>,
) -> Result<Sequence> {
    let options = crate::bag::BagOptions {
        topic: topic.map(str::to_owned),
        right_topic: right_topic.map(str::to_owned),
        camera: camera.map(Path::to_path_buf),
        ..crate::bag::BagOptions::default()
    };
    crate::bag::open_bag_sequence(path, &options)
}

#[cfg(not(feature = "bag"))]
fn open_bag(
    path: &Path,
    _camera: Option<&Path>,
    _topic: Option<&str>,
    _right_topic: Option<&str>,
) -> Result<Sequence> {
    Err(feature_missing(path, "a ROS 2 bag", "bag"))
}

#[cfg(feature = "video")]
fn open_video(path: &Path, camera: Option<&Path>) -> Result<Sequence> {
    crate::video::open_video(path, camera)
}

#[cfg(not(feature = "video"))]
fn open_video(path: &Path, _camera: Option<&Path>) -> Result<Sequence> {
    Err(feature_missing(path, "a video file", "video"))
}

/// The error for an input whose reader is compiled out.
#[cfg(not(all(feature = "bag", feature = "video")))]
fn feature_missing(path: &Path, what: &str, feature: &str) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        message: format!(
            "is {what}, which this build of visnav-io does not read: build it with the `{feature}` cargo feature (on by default)"
        ),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bag_is_known_by_its_name_or_metadata() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert!(is_bag(&dir.path().join("run.mcap")));
        assert!(is_bag(&dir.path().join("run.DB3")));
        assert!(!is_bag(dir.path()));
        std::fs::write(
            dir.path().join("metadata.yaml"),
            "rosbag2_bagfile_information:\n",
        )
        .expect("write");
        assert!(is_bag(dir.path()));
    }

    /// Without the `bag` feature a bag is an error that names the feature.
    #[cfg(not(feature = "bag"))]
    #[test]
    fn a_bag_without_the_feature_names_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let bag = dir.path().join("run.mcap");
        std::fs::write(&bag, b"\x89MCAP0\r\n").expect("write");
        for e in [
            Sequence::open(&bag).expect_err("no bag reader"),
            open_input(dir.path(), None, Some("/cam0/image_raw"), None).expect_err("a topic"),
        ] {
            let message = e.to_string();
            assert!(message.contains("`bag` cargo feature"), "{message}");
        }
    }

    /// Without the `video` feature a video file is an error that names the feature.
    #[cfg(not(feature = "video"))]
    #[test]
    fn a_video_without_the_feature_names_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let video = dir.path().join("clip.mp4");
        std::fs::write(&video, [0u8, 0, 0, 0x18, b'f', b't', b'y', b'p']).expect("write");
        let message = Sequence::open(&video)
            .expect_err("no video reader")
            .to_string();
        assert!(message.contains("`video` cargo feature"), "{message}");
    }
}
