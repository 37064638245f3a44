//! Video input: a video file plus a camera file, decoded by the `ffmpeg` command-line tool
//! (Debian package `ffmpeg`, installed by `scripts/setup.sh`).
//!
//! At opening, `ffprobe` reads the frame size and rate, and `ffmpeg -f rawvideo -pix_fmt gray`
//! streams the frames into an 8-bit raw file in a temporary directory (removed when the last
//! clone of the sequence is dropped). Frames are then read from that file on demand, so the
//! sequence is never held in memory and frames can be revisited (palindrome runs). Timestamps are
//! `index / frame rate`.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;

use visnav_core::GrayImage;

use crate::calibration::{Rectifier, read_camera_file};
use crate::error::{IoError, Result};
use crate::kitti::{Sequence, SequenceLayout};

/// Decoded 8-bit gray frames of a video, stored in a temporary raw file.
#[derive(Debug)]
pub struct VideoFrames {
    video: PathBuf,
    raw: PathBuf,
    width: usize,
    height: usize,
    count: usize,
    _dir: tempfile::TempDir,
}

impl VideoFrames {
    /// Number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether the video has no frames (never true for an opened video).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Frame `i` as a gray image (intensities 0..=255).
    ///
    /// # Errors
    /// An index past the end or a read error of the decoded frames.
    pub fn frame(&self, i: usize) -> Result<GrayImage> {
        if i >= self.count {
            return Err(IoError::Format {
                path: self.video.clone(),
                message: format!("frame {i} of a {}-frame video", self.count),
            });
        }
        let n = self.width * self.height;
        let mut buf = vec![0u8; n];
        let mut f = std::fs::File::open(&self.raw).map_err(|e| IoError::io(&self.raw, e))?;
        f.seek(SeekFrom::Start((i * n) as u64))
            .and_then(|_| f.read_exact(&mut buf))
            .map_err(|e| IoError::io(&self.raw, e))?;
        let data = buf.into_iter().map(f32::from).collect();
        GrayImage::from_vec(self.width, self.height, data).ok_or_else(|| IoError::Format {
            path: self.video.clone(),
            message: "decoded frame has the wrong size".into(),
        })
    }
}

fn tool_missing(video: &Path, tool: &str, e: &std::io::Error) -> IoError {
    IoError::Format {
        path: video.to_path_buf(),
        message: format!(
            "cannot run `{tool}` ({e}): video input needs ffmpeg; install it with scripts/setup.sh or `apt-get install ffmpeg`, or extract the frames to PNG files"
        ),
    }
}

/// Width, height and frame rate (Hz) of the first video stream, from `ffprobe`.
fn probe(video: &Path) -> Result<(usize, usize, f64)> {
    let out = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=width,height,avg_frame_rate",
            "-of",
            "default=noprint_wrappers=1",
        ])
        .arg(video)
        .output()
        .map_err(|e| tool_missing(video, "ffprobe", &e))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let bad = |message: String| IoError::Format {
        path: video.to_path_buf(),
        message,
    };
    if !out.status.success() {
        return Err(bad(format!(
            "ffprobe cannot read this file: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    let field = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
            .map(str::trim)
    };
    let (Some(w), Some(h)) = (
        field("width").and_then(|w| w.parse::<usize>().ok()),
        field("height").and_then(|h| h.parse::<usize>().ok()),
    ) else {
        return Err(bad("no video stream (ffprobe found no width/height)".into()));
    };
    let rate_hz = field("avg_frame_rate")
        .and_then(|r| {
            let (n, d) = r.split_once('/')?;
            let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
            (d > 0.0 && n > 0.0).then_some(n / d)
        })
        .unwrap_or(crate::layouts::DEFAULT_RATE_HZ);
    Ok((w, h, rate_hz))
}

/// Opens a video file with its camera file as a [`Sequence`] (module doc).
pub(crate) fn open_video(video: &Path, camera: Option<&Path>) -> Result<Sequence> {
    let Some(calib_path) = camera else {
        return Err(IoError::NotFound {
            path: video.to_path_buf(),
            what: "a camera file for this video: pass --camera camera.yaml".into(),
        });
    };
    let calib = read_camera_file(calib_path)?;
    let (width, height, probed_rate_hz) = probe(video)?;
    crate::layouts::check_size(video, (width, height), &calib.left, calib_path)?;
    let dir = tempfile::Builder::new()
        .prefix("visnav-video-")
        .tempdir()
        .map_err(|e| IoError::io(std::env::temp_dir(), e))?;
    let raw = dir.path().join("frames.gray");
    let raw_file = std::fs::File::create(&raw).map_err(|e| IoError::io(&raw, e))?;
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-i"])
        .arg(video)
        .args(["-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", "gray", "-"])
        .stdout(Stdio::from(raw_file))
        .stderr(Stdio::piped())
        .output()
        .map_err(|e| tool_missing(video, "ffmpeg", &e))?;
    if !status.status.success() {
        return Err(IoError::Format {
            path: video.to_path_buf(),
            message: format!(
                "ffmpeg cannot decode this file: {}",
                String::from_utf8_lossy(&status.stderr).trim()
            ),
        });
    }
    let bytes = std::fs::metadata(&raw)
        .map_err(|e| IoError::io(&raw, e))?
        .len() as usize;
    let count = bytes / (width * height);
    if count == 0 {
        return Err(IoError::EmptySequence {
            path: video.to_path_buf(),
        });
    }
    let rate_hz = calib.rate_hz.unwrap_or(probed_rate_hz);
    let frames = Arc::new(VideoFrames {
        video: video.to_path_buf(),
        raw,
        width,
        height,
        count,
        _dir: dir,
    });
    let rectifier = Rectifier::new(&calib, false, calib_path)?;
    let timestamps = (0..count).map(|i| i as f64 / rate_hz).collect();
    Ok(Sequence::with_rectifier(
        video,
        SequenceLayout::Video,
        rectifier,
        (width, height),
        timestamps,
        false,
        vec![video.to_path_buf()],
        None,
        Some(frames),
    ))
}
