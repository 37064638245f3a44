//! Video input: a video file plus a camera file, decoded by the `ffmpeg` command-line tool
//! (Debian package `ffmpeg`, installed by `scripts/setup.sh`), streamed.
//!
//! At opening, `ffprobe` reads the frame size and the presentation time of every packet of the
//! first video stream (no decoding): the frame count and the timestamps (seconds from the
//! stream's first frame). Frames are then read from a running `ffmpeg … -f rawvideo -pix_fmt
//! gray pipe:1` as the decoder produces them: nothing is written to disk and memory holds only
//! the [`CACHE_FRAMES`] frames decoded last, whatever the video's length. A frame before the
//! decoder's position (a palindrome's way back, a loop-closure candidate) restarts the decoder
//! with an input seek (`-ss`) a cache's length earlier, so a backward walk costs one seek per
//! [`CACHE_FRAMES`] frames. `Prefetch` (`crate::source`) adds the bounded queue between the
//! decoding thread and the odometry.

use std::collections::VecDeque;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};

use visnav_core::GrayImage;

use crate::calibration::{Rectifier, read_camera_file};
use crate::error::{IoError, Result};
use crate::sequence::{DecodedFrames, FrameFiles, Sequence, SequenceLayout};

/// Frames kept after decoding (the backward-seek block).
pub const CACHE_FRAMES: usize = 32;

/// Frames read and dropped rather than seeking when a later frame is asked for.
const MAX_FORWARD_SKIP: usize = 64;

/// The frames of a video, decoded on demand by a streaming `ffmpeg`.
#[derive(Debug)]
pub struct VideoFrames {
    video: PathBuf,
    width: usize,
    height: usize,
    /// Presentation times, seconds from the first frame, in presentation order.
    times_s: Vec<f64>,
    decoder: Mutex<Decoder>,
}

/// The running decoder and the frames decoded last.
#[derive(Debug, Default)]
struct Decoder {
    process: Option<(Child, ChildStdout)>,
    /// Index of the frame the pipe yields next.
    next: usize,
    cache: VecDeque<(usize, Arc<Vec<u8>>)>,
}

impl Drop for Decoder {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Decoder {
    fn stop(&mut self) {
        if let Some((mut child, _)) = self.process.take() {
            // the pipe is dropped with it; ffmpeg may already have exited
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl VideoFrames {
    /// Number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        self.times_s.len()
    }

    /// Whether the video has no frames (never true for an opened video).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.times_s.is_empty()
    }

    /// Frame `i` as a gray image (intensities 0..=255).
    ///
    /// # Errors
    /// An index past the end, ffmpeg missing, or a decoder that stops before frame `i`.
    pub fn frame(&self, i: usize) -> Result<GrayImage> {
        if i >= self.len() {
            return Err(self.error(format!("frame {i} of a {}-frame video", self.len())));
        }
        let mut d = self
            .decoder
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let bytes = match d.cache.iter().find(|(k, _)| *k == i) {
            Some((_, b)) => Arc::clone(b),
            None => self.decode(&mut d, i)?,
        };
        let data = bytes.iter().copied().map(f32::from).collect();
        GrayImage::from_vec(self.width, self.height, data)
            .ok_or_else(|| self.error("decoded frame has the wrong size".into()))
    }

    /// Runs (or restarts) the decoder up to frame `i`, caching what it reads.
    fn decode(&self, d: &mut Decoder, i: usize) -> Result<Arc<Vec<u8>>> {
        let running = d.process.is_some() && d.next <= i && i - d.next <= MAX_FORWARD_SKIP;
        if !running {
            d.stop();
            // a backward step fills the cache with the block before `i`
            let start = if i < d.next {
                i.saturating_sub(CACHE_FRAMES - 1)
            } else {
                i
            };
            d.process = Some(self.spawn(start)?);
            d.next = start;
        }
        let n = self.width * self.height;
        loop {
            let mut buf = vec![0u8; n];
            let read = match d.process.as_mut() {
                Some((_, out)) => out.read_exact(&mut buf),
                None => return Err(self.error("no decoder".into())),
            };
            if let Err(e) = read {
                let k = d.next;
                d.stop();
                return Err(self.error(format!(
                    "ffmpeg stopped before frame {i} (after frame {k}: {e}); `ffmpeg -v error -i FILE -f null -` shows why"
                )));
            }
            let k = d.next;
            d.next += 1;
            let bytes = Arc::new(buf);
            if d.cache.len() == CACHE_FRAMES {
                d.cache.pop_front();
            }
            d.cache.push_back((k, Arc::clone(&bytes)));
            if k == i {
                return Ok(bytes);
            }
        }
    }

    /// Starts `ffmpeg` streaming gray frames from frame `start` on.
    fn spawn(&self, start: usize) -> Result<(Child, ChildStdout)> {
        let mut cmd = Command::new("ffmpeg");
        cmd.args(["-v", "error", "-nostdin"]);
        if start > 0 {
            // halfway between the frame before and this one: robust to rounding of the times
            let t = 0.5 * (self.times_s[start - 1] + self.times_s[start]);
            cmd.args(["-ss", &format!("{t:.6}")]);
        }
        cmd.arg("-i")
            .arg(&self.video)
            .args([
                "-map",
                "0:v:0",
                "-fps_mode",
                "passthrough",
                "-f",
                "rawvideo",
            ])
            .args(["-pix_fmt", "gray", "pipe:1"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            // not piped: an unread stderr pipe that fills would stall the decoder
            .stderr(Stdio::null());
        let mut child = cmd
            .spawn()
            .map_err(|e| tool_missing(&self.video, "ffmpeg", &e))?;
        let Some(out) = child.stdout.take() else {
            let _ = child.kill();
            return Err(self.error("ffmpeg has no output pipe".into()));
        };
        Ok((child, out))
    }

    fn error(&self, message: String) -> IoError {
        IoError::Format {
            path: self.video.clone(),
            message,
        }
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
        .unwrap_or(crate::calibration::DEFAULT_RATE_HZ);
    Ok((w, h, rate_hz))
}

/// Presentation times of the first video stream's packets, seconds from the first, sorted
/// (packets come in decoding order); `None` when the container gives none.
fn presentation_times(video: &Path) -> Result<Option<Vec<f64>>> {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries"])
        .args(["packet=pts_time", "-of", "csv=p=0"])
        .arg(video)
        .stderr(Stdio::null())
        .output()
        .map_err(|e| tool_missing(video, "ffprobe", &e))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let parsed: Option<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.trim()
                .trim_end_matches(',')
                .parse::<f64>()
                .ok()
                .filter(|t| t.is_finite())
        })
        .collect();
    Ok(parsed.filter(|t| !t.is_empty()).map(|mut t| {
        t.sort_by(f64::total_cmp);
        let t0 = t[0];
        t.iter().map(|x| x - t0).collect()
    }))
}

impl DecodedFrames for VideoFrames {
    fn len(&self) -> usize {
        VideoFrames::len(self)
    }
    fn left(&self, i: usize) -> Result<GrayImage> {
        self.frame(i)
    }
    fn right(&self, _: usize) -> Option<Result<GrayImage>> {
        None
    }
    fn has_right(&self) -> bool {
        false
    }
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
    crate::calibration::check_size(video, (width, height), &calib.left, calib_path)?;
    let times_s = match presentation_times(video)? {
        Some(t) => t,
        None => {
            return Err(IoError::Format {
                path: video.to_path_buf(),
                message: "ffprobe lists no video packets with presentation times".into(),
            });
        }
    };
    let timestamps = if times_s.windows(2).all(|w| w[1] > w[0]) {
        times_s.clone()
    } else {
        // repeated or missing presentation times: the frame rate instead
        let rate_hz = calib.rate_hz.unwrap_or(probed_rate_hz);
        (0..times_s.len()).map(|i| i as f64 / rate_hz).collect()
    };
    let frames = Arc::new(VideoFrames {
        video: video.to_path_buf(),
        width,
        height,
        times_s: timestamps.clone(),
        decoder: Mutex::new(Decoder::default()),
    });
    // the first frame must decode: a clear error at opening, not at frame 0 of the run
    frames.frame(0)?;
    let rectifier = Rectifier::new(&calib, false, calib_path)?;
    Ok(Sequence::with_rectifier(
        video,
        SequenceLayout::Video,
        rectifier,
        (width, height),
        FrameFiles {
            timestamps,
            timestamped: false,
            left: vec![video.to_path_buf()],
            right: None,
        },
        Some(frames),
    ))
}
