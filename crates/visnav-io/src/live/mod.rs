//! Live input: a camera or a network stream that has no frame count and never ends by itself,
//! decoded by the `ffmpeg` command-line tool (as [`crate::video`]) on a reader thread.
//!
//! Inputs ([`LiveInput::parse`]): `rtsp://…`, `rtsps://…`, `udp://…`, `srt://…`, `tcp://…`,
//! `rtmp://…`, `rtp://…` (network streams), `v4l2:///dev/video0` or `/dev/video0` (a V4L2
//! camera), `-` (a stream on standard input in any format ffmpeg recognises by its content:
//! MJPEG, MPEG-TS, Matroska, y4m, H.264 …). A live input always needs a camera file (the stream
//! cannot be probed before the run without consuming it); its frames are undistorted with it.
//!
//! ```text
//!  ffmpeg … -i URL -vf showinfo -f rawvideo -pix_fmt gray pipe:1
//!     │ stdout: gray frames ──► reader thread ──► buffer (policy: newest | all) ──► LiveSource
//!     │ stderr: showinfo lines (n, pts_time, size) ─┘   (reconnects, timestamps)      (Iterator of
//!     └ watchdog: killed when no frame comes for the stall limit                       SourceItem)
//! ```
//!
//! **Timestamps** come from the stream: ffmpeg's `showinfo` filter prints each frame's
//! presentation time on stderr (`-f rawvideo` on stdout carries none) and the reader pairs the
//! lines with the frames by their number. A stream without presentation times gets the frames'
//! arrival times instead, said once in the log. Times start at 0 at the first frame; after a
//! reconnection they continue from the last frame's time plus the wall-clock gap, so they
//! always increase. **Arrival**: [`SourceItem::received`] is the instant the frame's last byte
//! left ffmpeg's pipe (the latency of a pose is measured from it).
//!
//! **Frame policy** ([`FramePolicy`]): with `newest` (the default for live input) a frame that
//! arrives while the previous one still waits for the odometry replaces it; the replaced frames
//! are counted ([`SourceItem::dropped_before`], [`LiveStats::frames_dropped`]). With `all` every
//! frame is queued, up to [`LiveConfig::queue_frames`] (beyond, the oldest is dropped and
//! counted: a live stream cannot be paused).
//!
//! **Lost streams**: ffmpeg is given a read timeout (`-timeout` for udp/rtsp/srt/tcp,
//! `-rw_timeout` for every network protocol) and a watchdog kills it when no frame comes for
//! [`LiveConfig::stall_limit_s`], so a dead stream never hangs the run. A stream that ends
//! (ffmpeg exits, timeout) is a logged gap, then up to [`LiveConfig::reconnect`] new attempts
//! with a doubling wait ([`LiveConfig::backoff_s`] … [`LiveConfig::max_backoff_s`]); a
//! connection that delivered frames resets the count. Standard input is not reopened: its end
//! is the end of the run. A stop flag (Ctrl-C) ends the stream at once.

mod config;
mod reader;
mod shared;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use visnav_core::{GrayImage, PinholeCamera};

use crate::calibration::{Rectifier, read_camera_file};
use crate::error::{IoError, Result};
use crate::source::{Frame, SourceItem};

pub use config::{FramePolicy, LiveConfig, LiveInput, LiveStats, TimestampOrigin, is_live_input};
use shared::{End, RawFrame, Shared, State};

/// A live input as an endless, ordered stream of [`SourceItem`]s (module docs). Iterating
/// blocks until the next frame, the end of the stream or the stop flag.
pub struct LiveSource {
    input: LiveInput,
    rectifier: Arc<Rectifier>,
    size: (usize, usize),
    shared: Arc<Shared>,
    reader: Option<JoinHandle<()>>,
    next_position: usize,
}

impl std::fmt::Debug for LiveSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveSource")
            .field("input", &self.input)
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

impl LiveSource {
    /// Starts reading `input` with the camera file `camera`, and waits for its first frame (or
    /// its failure, after the reconnections). `stop` ends the stream when set (Ctrl-C).
    ///
    /// # Errors
    /// Not a live input, no camera file, an unreadable camera file, ffmpeg missing, a stream
    /// whose frames do not have the camera file's size, or a stream that gave no frame before
    /// the reconnections were used up (ffmpeg's last message names the problem).
    pub fn open(
        input: &Path,
        camera: Option<&Path>,
        config: &LiveConfig,
        stop: Arc<AtomicBool>,
    ) -> Result<Self> {
        let bad = |message: String| IoError::Format {
            path: input.to_path_buf(),
            message,
        };
        let live = LiveInput::parse(input).ok_or_else(|| {
            bad("not a live input (rtsp://, udp://, srt://, tcp://, rtmp://, rtp://, v4l2:///dev/videoN, /dev/videoN or -)".into())
        })?;
        config.validate().map_err(&bad)?;
        let Some(calib_path) = camera else {
            return Err(IoError::NotFound {
                path: input.to_path_buf(),
                what: "a camera file for this live input: pass --camera camera.yaml (a live stream cannot be probed before the run)".into(),
            });
        };
        let calib = read_camera_file(calib_path)?;
        let rectifier = Rectifier::new(&calib, false, calib_path)?;
        let size = (
            calib.left.pinhole.width as usize,
            calib.left.pinhole.height as usize,
        );
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                frames: VecDeque::new(),
                dropped_pending: 0,
                stats: LiveStats::default(),
                end: None,
            }),
            changed: Condvar::new(),
            stop,
            closing: AtomicBool::new(false),
            policy: config.policy,
            queue_frames: config.queue_frames,
        });
        let job = reader::Reader {
            input: live.clone(),
            size,
            calib_path: calib_path.to_path_buf(),
            config: config.clone(),
            shared: Arc::clone(&shared),
        };
        let reader = std::thread::Builder::new()
            .name("visnav-live".into())
            .spawn(move || job.run())
            .map_err(|e| bad(format!("cannot start the reader thread: {e}")))?;
        let mut source = Self {
            input: live,
            rectifier,
            size,
            shared,
            reader: Some(reader),
            next_position: 0,
        };
        source.wait_first_frame().map_err(bad)?;
        Ok(source)
    }

    /// Waits until a frame is buffered; `Err` with the reason when the stream ended first.
    fn wait_first_frame(&mut self) -> std::result::Result<(), String> {
        let mut s = self.shared.lock();
        loop {
            if !s.frames.is_empty() || self.shared.stopped() {
                return Ok(());
            }
            match &s.end {
                Some(End::Failed(m) | End::Finished(m)) => return Err(m.clone()),
                None => {}
            }
            s = self
                .shared
                .changed
                .wait_timeout(s, Duration::from_millis(100))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }

    /// The pinhole camera of the frames given (undistorted).
    #[must_use]
    pub fn camera(&self) -> PinholeCamera {
        self.rectifier.camera
    }

    /// The input.
    #[must_use]
    pub fn input(&self) -> &LiveInput {
        &self.input
    }

    /// Counts so far.
    #[must_use]
    pub fn stats(&self) -> LiveStats {
        self.shared.lock().stats
    }

    /// Why the stream ended (`None` while it runs or when it was stopped).
    #[must_use]
    pub fn end_reason(&self) -> Option<String> {
        self.shared.lock().end.as_ref().map(|e| match e {
            End::Finished(m) | End::Failed(m) => m.clone(),
        })
    }

    fn item(&mut self, raw: RawFrame, dropped_before: usize) -> SourceItem {
        let position = self.next_position;
        self.next_position += 1;
        let data = raw.gray.iter().copied().map(f32::from).collect();
        let frame = GrayImage::from_vec(self.size.0, self.size.1, data)
            .map(|img| Frame {
                left: self.rectifier.left(img),
                right: None,
            })
            .ok_or_else(|| IoError::Format {
                path: PathBuf::from(self.input.name()),
                message: format!("frame {} has the wrong size", raw.index),
            });
        SourceItem {
            position,
            index: raw.index,
            timestamp_s: Some(raw.timestamp_s),
            frame,
            received: raw.received,
            dropped_before,
        }
    }
}

impl Iterator for LiveSource {
    type Item = SourceItem;

    /// The next frame (by the policy): blocks until one comes; `None` at the end of the stream
    /// or when the stop flag is set.
    fn next(&mut self) -> Option<SourceItem> {
        let mut s = self.shared.lock();
        loop {
            if self.shared.stopped() {
                return None;
            }
            if let Some(raw) = s.frames.pop_front() {
                let dropped = std::mem::take(&mut s.dropped_pending);
                drop(s);
                return Some(self.item(raw, dropped));
            }
            if s.end.is_some() {
                return None;
            }
            s = self
                .shared
                .changed
                .wait_timeout(s, Duration::from_millis(100))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }
}

impl Drop for LiveSource {
    fn drop(&mut self) {
        // the watchdog kills ffmpeg when it sees the flag, which ends the reader's read
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.changed.notify_all();
        if let Some(h) = self.reader.take()
            && h.join().is_err()
        {
            log::error!("the live reader thread panicked");
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;

    #[test]
    fn live_inputs_are_recognised_by_name() {
        let p = |s: &str| LiveInput::parse(Path::new(s));
        assert_eq!(p("-"), Some(LiveInput::Stdin));
        assert_eq!(
            p("v4l2:///dev/video2"),
            Some(LiveInput::Device("/dev/video2".into()))
        );
        assert_eq!(
            p("/dev/video0"),
            Some(LiveInput::Device("/dev/video0".into()))
        );
        for url in [
            "udp://127.0.0.1:5000",
            "RTSP://cam/stream",
            "srt://h:1?mode=caller",
        ] {
            assert!(matches!(p(url), Some(LiveInput::Url { .. })), "{url}");
        }
        for not in ["clip.mp4", "/data/kitti/00", "http://host/video.mp4", "--"] {
            assert_eq!(p(not), None, "{not}");
        }
    }

    #[test]
    fn backoff_doubles_up_to_its_limit_and_config_is_checked() {
        let c = LiveConfig::default();
        let waits: Vec<f64> = (1..=6).map(|a| c.backoff_before(a)).collect();
        assert_eq!(waits, [0.5, 1.0, 2.0, 4.0, 8.0, 8.0]);
        assert!(c.validate().is_ok());
        let bad = LiveConfig {
            timeout_s: 0.0,
            ..LiveConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("timeout_s"));
    }

    fn shared(policy: FramePolicy, queue_frames: usize) -> Shared {
        Shared {
            state: Mutex::new(State {
                frames: VecDeque::new(),
                dropped_pending: 0,
                stats: LiveStats::default(),
                end: None,
            }),
            changed: Condvar::new(),
            stop: Arc::new(AtomicBool::new(false)),
            closing: AtomicBool::new(false),
            policy,
            queue_frames,
        }
    }

    fn raw(index: usize) -> RawFrame {
        RawFrame {
            gray: vec![0],
            index,
            timestamp_s: index as f64,
            received: Instant::now(),
        }
    }

    #[test]
    fn newest_keeps_one_frame_and_counts_the_rest_all_queues() {
        let s = shared(FramePolicy::Newest, 8);
        for i in 0..5 {
            s.push(raw(i));
        }
        let st = s.lock();
        assert_eq!(st.frames.len(), 1);
        assert_eq!(st.frames[0].index, 4);
        assert_eq!((st.dropped_pending, st.stats.frames_dropped), (4, 4));
        assert_eq!(st.stats.frames_received, 5);
        drop(st);
        let s = shared(FramePolicy::All, 3);
        for i in 0..5 {
            s.push(raw(i));
        }
        let st = s.lock();
        let kept: Vec<usize> = st.frames.iter().map(|f| f.index).collect();
        assert_eq!(kept, [2, 3, 4]);
        assert_eq!(st.stats.frames_dropped, 2);
    }
}
