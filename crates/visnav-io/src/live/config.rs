//! What a live run is given and what it reports: the input ([`LiveInput`]), the reading
//! settings ([`LiveConfig`], [`FramePolicy`]) and the counts so far ([`LiveStats`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

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
