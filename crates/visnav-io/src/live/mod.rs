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

mod reader;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use visnav_core::{GrayImage, PinholeCamera};

use crate::calibration::{Rectifier, read_camera_file};
use crate::error::{IoError, Result};
use crate::source::{Frame, SourceItem};

/// What happens to the frames that arrive while the odometry is busy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FramePolicy {
    /// Keep the newest frame only; the ones it replaces are dropped and counted (real time).
    #[default]
    Newest,
    /// Queue every frame (up to [`LiveConfig::queue_frames`]): the poses lag behind the camera
    /// when the odometry is slower than it.
    All,
}

impl FramePolicy {
    /// `newest` or `all`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Newest => "newest",
            Self::All => "all",
        }
    }
}

/// How a live input is read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiveConfig {
    /// The frame policy (module docs).
    pub policy: FramePolicy,
    /// New connection attempts after the stream is lost (0: the run ends at the first loss).
    pub reconnect: usize,
    /// ffmpeg's connect and read timeout, seconds.
    pub timeout_s: f64,
    /// The wait before the first reconnection, seconds; it doubles at every further attempt.
    pub backoff_s: f64,
    /// The longest wait between two attempts, seconds.
    pub max_backoff_s: f64,
    /// Policy `all`: frames queued at most (the oldest is dropped beyond).
    pub queue_frames: usize,
    /// How much of a network or piped stream ffmpeg analyses before its first frame, seconds
    /// (`-analyzeduration`; ffmpeg's default of 5 s delays the first pose by as much).
    pub analyze_s: f64,
}

impl Default for LiveConfig {
    fn default() -> Self {
        Self {
            policy: FramePolicy::Newest,
            reconnect: 3,
            timeout_s: 5.0,
            backoff_s: 0.5,
            max_backoff_s: 8.0,
            queue_frames: 256,
            analyze_s: 1.0,
        }
    }
}

impl LiveConfig {
    /// The watchdog's limit: no frame for this long (seconds) and ffmpeg is killed. It leaves
    /// ffmpeg's own timeout and its stream analysis time to act first.
    #[must_use]
    pub fn stall_limit_s(&self) -> f64 {
        2.0 * self.timeout_s + self.analyze_s + 2.0
    }

    /// The wait before reconnection attempt `attempt` (1, 2, …), seconds.
    #[must_use]
    pub fn backoff_before(&self, attempt: usize) -> f64 {
        let doublings = i32::try_from(attempt.saturating_sub(1).min(30)).unwrap_or(30);
        (self.backoff_s * 2f64.powi(doublings)).min(self.max_backoff_s)
    }

    /// Checks the values.
    ///
    /// # Errors
    /// A message naming the field out of range.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let positive = [
            ("timeout_s", self.timeout_s),
            ("max_backoff_s", self.max_backoff_s),
            ("analyze_s", self.analyze_s),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("live {name} = {v}: must be a positive number"));
            }
        }
        if !(self.backoff_s.is_finite() && self.backoff_s >= 0.0) {
            return Err(format!(
                "live backoff_s = {}: must be a number >= 0",
                self.backoff_s
            ));
        }
        if self.queue_frames == 0 {
            return Err("live queue_frames = 0: must be at least 1".into());
        }
        Ok(())
    }
}

/// A live input, recognised by its name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LiveInput {
    /// A network stream: the URL as given (ffmpeg's protocol options may follow a `?`).
    Url {
        /// The URL.
        url: String,
        /// Its scheme, lower case (`udp`, `rtsp` …).
        scheme: String,
    },
    /// A V4L2 camera device.
    Device(PathBuf),
    /// Standard input.
    Stdin,
}

/// The schemes of network streams.
const STREAM_SCHEMES: [&str; 7] = ["rtsp", "rtsps", "udp", "srt", "tcp", "rtmp", "rtp"];

impl LiveInput {
    /// The live input `input` names, `None` for anything else (a file or a folder).
    #[must_use]
    pub fn parse(input: &Path) -> Option<Self> {
        let s = input.to_str()?;
        if s == "-" {
            return Some(Self::Stdin);
        }
        if let Some(device) = s.strip_prefix("v4l2://") {
            return Some(Self::Device(PathBuf::from(device)));
        }
        if s.starts_with("/dev/video") {
            return Some(Self::Device(PathBuf::from(s)));
        }
        let (scheme, _) = s.split_once("://")?;
        let scheme = scheme.to_ascii_lowercase();
        STREAM_SCHEMES
            .contains(&scheme.as_str())
            .then(|| Self::Url {
                url: s.to_owned(),
                scheme,
            })
    }

    /// How the input is named in messages.
    #[must_use]
    pub fn name(&self) -> String {
        match self {
            Self::Url { url, .. } => url.clone(),
            Self::Device(d) => d.display().to_string(),
            Self::Stdin => "standard input".into(),
        }
    }
}

/// `true` when `input` names a live input ([`LiveInput::parse`]).
#[must_use]
pub fn is_live_input(input: &Path) -> bool {
    LiveInput::parse(input).is_some()
}

/// Where the timestamps of a live run come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimestampOrigin {
    /// The stream's presentation times.
    #[default]
    Stream,
    /// The frames' arrival times (the stream has none).
    Arrival,
}

/// Counts of a live input so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LiveStats {
    /// Frames read from the stream.
    pub frames_received: usize,
    /// Frames dropped by the frame policy (never given to the odometry).
    pub frames_dropped: usize,
    /// Reconnections after a lost stream.
    pub reconnects: usize,
    /// Where the timestamps come from.
    pub timestamps: TimestampOrigin,
}

/// A decoded frame waiting for the consumer.
struct RawFrame {
    gray: Vec<u8>,
    index: usize,
    timestamp_s: f64,
    received: Instant,
}

/// Why the stream ended.
#[derive(Debug, Clone)]
enum End {
    /// The input ended (standard input's end, reconnections used up) after frames.
    Finished(String),
    /// The input is unusable (wrong size, ffmpeg missing): an error.
    Failed(String),
}

/// The state shared by the reader thread and the consumer.
struct State {
    frames: VecDeque<RawFrame>,
    /// Dropped since the consumer took its last frame.
    dropped_pending: usize,
    stats: LiveStats,
    end: Option<End>,
}

pub(crate) struct Shared {
    state: Mutex<State>,
    changed: Condvar,
    /// The caller's stop flag (Ctrl-C).
    stop: Arc<AtomicBool>,
    /// Set when the source is dropped.
    closing: AtomicBool,
    policy: FramePolicy,
    queue_frames: usize,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether reading must stop.
    pub(crate) fn stopped(&self) -> bool {
        self.stop.load(Ordering::SeqCst) || self.closing.load(Ordering::SeqCst)
    }

    fn push(&self, frame: RawFrame) {
        let mut s = self.lock();
        s.stats.frames_received += 1;
        let keep = match self.policy {
            FramePolicy::Newest => 0,
            FramePolicy::All => self.queue_frames - 1,
        };
        while s.frames.len() > keep {
            s.frames.pop_front();
            s.dropped_pending += 1;
            s.stats.frames_dropped += 1;
        }
        s.frames.push_back(frame);
        drop(s);
        self.changed.notify_all();
    }

    fn end(&self, end: End) {
        self.lock().end.get_or_insert(end);
        self.changed.notify_all();
    }

    fn update(&self, f: impl FnOnce(&mut LiveStats)) {
        f(&mut self.lock().stats);
    }
}

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
