//! The reader thread of a [`super::LiveSource`]: runs ffmpeg, pairs its frames with their
//! `showinfo` lines, stamps them, reconnects after a loss and keeps a watchdog on ffmpeg.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::os::unix::process::CommandExt as _;
use std::path::PathBuf;
use std::process::{Child, ChildStderr, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::config::{LiveConfig, LiveInput, TimestampOrigin};
use super::shared::{End, RawFrame, Shared};

/// ffmpeg's stderr lines kept for the message of a lost stream.
const KEPT_LINES: usize = 4;

/// How long a frame waits for its `showinfo` line (stderr and stdout are separate pipes).
const INFO_WAIT: Duration = Duration::from_secs(2);

/// What `showinfo` says about a frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FrameInfo {
    /// Frame number since ffmpeg started.
    pub n: usize,
    /// Presentation time, seconds (`None`: the stream has none).
    pub pts_time_s: Option<f64>,
    /// Width and height.
    pub size: Option<(usize, usize)>,
}

/// Parses a `showinfo` frame line (`… n:   3 pts: 3 pts_time:0.3 … s:64x48 …`).
pub(crate) fn parse_showinfo(line: &str) -> Option<FrameInfo> {
    if !line.contains("Parsed_showinfo") {
        return None;
    }
    let value = |key: &str| {
        let at = line.find(key)? + key.len();
        line[at..].split_whitespace().next()
    };
    let n = value(" n:")?.parse().ok()?;
    let pts_time_s = value(" pts_time:")
        .and_then(|t| t.parse::<f64>().ok())
        .filter(|t| t.is_finite());
    let size = value(" s:").and_then(|s| {
        let (w, h) = s.split_once('x')?;
        Some((w.parse().ok()?, h.parse().ok()?))
    });
    Some(FrameInfo {
        n,
        pts_time_s,
        size,
    })
}

/// The stream clock: seconds from the first frame, increasing across reconnections.
#[derive(Debug, Default)]
pub(crate) struct StreamClock {
    /// Time of the first frame of the current connection, and the stream's own time there.
    segment: Option<(f64, f64)>,
    /// Time and arrival of the last frame.
    last: Option<(f64, Instant)>,
    first_arrival: Option<Instant>,
    pub origin: TimestampOrigin,
}

impl StreamClock {
    /// A new connection: its times continue from the last frame's plus the wall-clock gap.
    pub fn reconnected(&mut self) {
        self.segment = None;
    }

    /// The time of a frame that arrived at `received` with the stream time `pts_s`.
    pub fn stamp(&mut self, pts_s: Option<f64>, received: Instant) -> f64 {
        let first = *self.first_arrival.get_or_insert(received);
        let t = match pts_s {
            Some(pts) if self.origin == TimestampOrigin::Stream => {
                let (base, pts0) = *self.segment.get_or_insert_with(|| {
                    let base = self.last.map_or(0.0, |(t, at)| {
                        t + received.saturating_duration_since(at).as_secs_f64()
                    });
                    (base, pts)
                });
                base + (pts - pts0)
            }
            _ => {
                if self.origin == TimestampOrigin::Stream {
                    log::warn!(
                        "live: the stream gives no presentation times; the frames' arrival times are their timestamps"
                    );
                    self.origin = TimestampOrigin::Arrival;
                }
                received.saturating_duration_since(first).as_secs_f64()
            }
        };
        // times must increase: a repeated or backward stream time gets the smallest step up
        let t = match self.last {
            Some((last, _)) if t <= last => last + 1e-6,
            _ => t,
        };
        self.last = Some((t, received));
        t
    }
}

/// The reader thread's job.
pub(crate) struct Reader {
    pub input: LiveInput,
    pub size: (usize, usize),
    pub calib_path: PathBuf,
    pub config: LiveConfig,
    pub shared: Arc<Shared>,
}

/// How one connection ended.
enum Connection {
    /// The stream ended or was lost, after `frames` frames; `why` from ffmpeg.
    Lost { frames: usize, why: String },
    /// The input is unusable: end with this error.
    Fatal(String),
}

impl Reader {
    /// Connects, reads, reconnects (module docs of [`super`]) until the stream is over.
    pub fn run(self) {
        let mut clock = StreamClock::default();
        let mut next_index = 0;
        let mut attempt = 0;
        let name = self.input.name();
        loop {
            let outcome = match self.spawn() {
                Ok(child) => self.read(child, &mut clock, &mut next_index),
                Err(e) => Connection::Fatal(e),
            };
            if self.shared.stopped() {
                return;
            }
            let (frames, why) = match outcome {
                Connection::Fatal(m) => return self.shared.end(End::Failed(m)),
                Connection::Lost { frames, why } => (frames, why),
            };
            if self.input == LiveInput::Stdin {
                let m = format!("{name}: the stream ended after frame {next_index} ({why})");
                return self.shared.end(End::Finished(m));
            }
            if frames > 0 {
                attempt = 0;
            }
            if attempt >= self.config.reconnect {
                let m = format!(
                    "{name}: the stream is lost ({why}); {} reconnection attempts made (--reconnect {})",
                    attempt, self.config.reconnect
                );
                return self.shared.end(End::Finished(m));
            }
            attempt += 1;
            let wait_s = self.config.backoff_before(attempt);
            log::warn!(
                "live {name}: the stream is lost after frame {next_index} ({why}); reconnecting in {wait_s:.1} s (attempt {attempt} of {})",
                self.config.reconnect
            );
            if !self.sleep(wait_s) {
                return;
            }
            clock.reconnected();
            self.shared.update(|s| s.reconnects += 1);
        }
    }

    /// Sleeps `s` seconds unless stopped; `false` when stopped.
    fn sleep(&self, s: f64) -> bool {
        let until = Instant::now() + Duration::from_secs_f64(s);
        while Instant::now() < until {
            if self.shared.stopped() {
                return false;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        !self.shared.stopped()
    }

    /// ffmpeg's input options and input for this kind of input.
    fn input_args(&self) -> Vec<String> {
        let us = format!("{:.0}", self.config.timeout_s * 1e6);
        let analyze_us = format!("{:.0}", self.config.analyze_s * 1e6);
        let mut args: Vec<String> = Vec::new();
        if !matches!(self.input, LiveInput::Device(_)) {
            args.extend(["-analyzeduration".into(), analyze_us]);
        }
        match &self.input {
            LiveInput::Url { url, scheme } => {
                if matches!(scheme.as_str(), "udp" | "rtsp" | "rtsps" | "srt" | "tcp") {
                    args.extend(["-timeout".into(), us.clone()]);
                }
                if !matches!(scheme.as_str(), "rtsp" | "rtsps") {
                    args.extend(["-rw_timeout".into(), us]);
                }
                args.extend(["-i".into(), url.clone()]);
            }
            LiveInput::Device(d) => {
                args.extend(["-f".into(), "v4l2".into(), "-i".into()]);
                args.push(d.display().to_string());
            }
            LiveInput::Stdin => args.extend(["-i".into(), "pipe:0".into()]),
        }
        args
    }

    /// Starts ffmpeg (in its own process group: a Ctrl-C in the terminal stops visnav, which
    /// then stops ffmpeg, rather than ffmpeg first).
    fn spawn(&self) -> Result<Child, String> {
        let mut cmd = Command::new("ffmpeg");
        cmd.args(["-hide_banner", "-nostats", "-loglevel", "info"]);
        if self.input != LiveInput::Stdin {
            cmd.arg("-nostdin");
        }
        cmd.args(self.input_args())
            .args([
                "-map",
                "0:v:0",
                "-vf",
                "showinfo",
                "-fps_mode",
                "passthrough",
            ])
            .args(["-f", "rawvideo", "-pix_fmt", "gray", "pipe:1"])
            .stdin(if self.input == LiveInput::Stdin {
                Stdio::inherit()
            } else {
                Stdio::null()
            })
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0);
        cmd.spawn().map_err(|e| {
            format!(
                "cannot run `ffmpeg` ({e}): live input needs ffmpeg; install it with scripts/setup.sh or `apt-get install ffmpeg`"
            )
        })
    }

    /// Reads the frames of one connection until ffmpeg ends or is killed.
    fn read(&self, child: Child, clock: &mut StreamClock, next_index: &mut usize) -> Connection {
        let child = Arc::new(Mutex::new(child));
        let lock = |c: &Arc<Mutex<Child>>| {
            let mut g = c.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            (g.stdout.take(), g.stderr.take())
        };
        let (Some(mut stdout), Some(stderr)) = lock(&child) else {
            kill(&child);
            return Connection::Fatal("ffmpeg has no output pipes".into());
        };
        let said = Arc::new(Mutex::new(VecDeque::new()));
        let (infos, stderr_thread) = watch_stderr(stderr, Arc::clone(&said));
        let progress = Arc::new(Mutex::new(Instant::now()));
        let done = Arc::new(AtomicBool::new(false));
        let watchdog = self.watchdog(&child, &progress, &done);
        let (w, h) = self.size;
        let mut frames = 0;
        let outcome = loop {
            let mut gray = vec![0u8; w * h];
            if let Err(e) = stdout.read_exact(&mut gray) {
                break Connection::Lost {
                    frames,
                    why: last_words(&said)
                        .unwrap_or_else(|| format!("ffmpeg's output ended: {}", end_of(&e))),
                };
            }
            let received = Instant::now();
            *progress
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = received;
            let info = frame_info(&infos, frames);
            if let Some(size) = info.as_ref().and_then(|i| i.size)
                && size != self.size
            {
                break Connection::Fatal(format!(
                    "{}: the calibration is for {w}x{h} images but {} gives {}x{}",
                    self.calib_path.display(),
                    self.input.name(),
                    size.0,
                    size.1
                ));
            }
            let pts = info.and_then(|i| i.pts_time_s);
            let timestamp_s = clock.stamp(pts, received);
            if clock.origin == TimestampOrigin::Arrival {
                self.shared
                    .update(|s| s.timestamps = TimestampOrigin::Arrival);
            }
            self.shared.push(RawFrame {
                gray,
                index: *next_index,
                timestamp_s,
                received,
            });
            *next_index += 1;
            frames += 1;
        };
        done.store(true, Ordering::SeqCst);
        kill(&child);
        let _ = watchdog.map(std::thread::JoinHandle::join);
        let _ = stderr_thread.map(std::thread::JoinHandle::join);
        outcome
    }

    /// Kills ffmpeg when no frame came for the stall limit or when the source stops.
    fn watchdog(
        &self,
        child: &Arc<Mutex<Child>>,
        progress: &Arc<Mutex<Instant>>,
        done: &Arc<AtomicBool>,
    ) -> Option<std::thread::JoinHandle<()>> {
        let (child, progress, done) = (Arc::clone(child), Arc::clone(progress), Arc::clone(done));
        let shared = Arc::clone(&self.shared);
        let limit = Duration::from_secs_f64(self.config.stall_limit_s());
        let name = self.input.name();
        let spawned = std::thread::Builder::new()
            .name("visnav-live-watchdog".into())
            .spawn(move || {
                while !done.load(Ordering::SeqCst) {
                    std::thread::sleep(Duration::from_millis(50));
                    let last = *progress
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    if shared.stopped() {
                        kill(&child);
                        return;
                    }
                    if last.elapsed() > limit {
                        log::warn!(
                            "live {name}: no frame for {:.1} s; stopping ffmpeg",
                            limit.as_secs_f64()
                        );
                        kill(&child);
                        return;
                    }
                }
            });
        match spawned {
            Ok(h) => Some(h),
            Err(e) => {
                log::warn!("live: no watchdog thread ({e}); ffmpeg's own timeout applies");
                None
            }
        }
    }
}

/// How a read that ended says so: the end of the stream, or the error.
fn end_of(e: &std::io::Error) -> String {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        "end of stream".into()
    } else {
        e.to_string()
    }
}

fn kill(child: &Arc<Mutex<Child>>) {
    let mut c = child
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    // it may have exited already
    let _ = c.kill();
    let _ = c.wait();
}

/// Reads ffmpeg's stderr on a thread: `showinfo` lines into the channel, the other lines into
/// the log (debug) and the last few into `said`.
fn watch_stderr(
    stderr: ChildStderr,
    said: Arc<Mutex<VecDeque<String>>>,
) -> (Receiver<FrameInfo>, Option<std::thread::JoinHandle<()>>) {
    let (tx, rx) = channel();
    let spawned = std::thread::Builder::new()
        .name("visnav-live-stderr".into())
        .spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if let Some(info) = parse_showinfo(&line) {
                    if tx.send(info).is_err() {
                        break;
                    }
                } else if !line.contains("Parsed_showinfo") {
                    log::debug!("ffmpeg: {line}");
                    let mut s = said
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    if s.len() == KEPT_LINES {
                        s.pop_front();
                    }
                    s.push_back(line);
                }
            }
        });
    match spawned {
        Ok(h) => (rx, Some(h)),
        Err(e) => {
            log::warn!("live: no stderr thread ({e}); arrival times instead of stream times");
            (rx, None)
        }
    }
}

/// The `showinfo` line of frame `n` (earlier lines are skipped), `None` when it does not come.
fn frame_info(infos: &Receiver<FrameInfo>, n: usize) -> Option<FrameInfo> {
    loop {
        match infos.recv_timeout(INFO_WAIT) {
            Ok(i) if i.n < n => {}
            Ok(i) => return (i.n == n).then_some(i),
            Err(_) => return None,
        }
    }
}

/// ffmpeg's last line that looks like an error (a normal end has none).
fn last_words(said: &Mutex<VecDeque<String>>) -> Option<String> {
    let s = said
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let wordy = |l: &&String| {
        let l = l.to_ascii_lowercase();
        [
            "error",
            "timed out",
            "refused",
            "invalid",
            "not found",
            "denied",
            "unreachable",
        ]
        .iter()
        .any(|w| l.contains(w))
    };
    s.iter()
        .rev()
        .find(wordy)
        .map(|l| format!("ffmpeg: {}", l.trim()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn showinfo_lines_parse() {
        let l = "[Parsed_showinfo_0 @ 0x5611] n:  12 pts:  12 pts_time:1.2     pos:  -1 fmt:rgb24 sar:1/1 s:64x48 i:P iskey:1";
        assert_eq!(
            parse_showinfo(l),
            Some(FrameInfo {
                n: 12,
                pts_time_s: Some(1.2),
                size: Some((64, 48)),
            })
        );
        let nopts = "[Parsed_showinfo_0 @ 0x1] n:   0 pts:NOPTS pts_time:NOPTS pos: -1 s:8x4";
        assert_eq!(parse_showinfo(nopts).unwrap().pts_time_s, None);
        assert_eq!(
            parse_showinfo("[Parsed_showinfo_0 @ 0x1] config in time_base: 1/10"),
            None
        );
        assert_eq!(parse_showinfo("frame=  3 fps=0.0"), None);
    }

    #[test]
    fn clock_starts_at_zero_and_increases_across_reconnections() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut c = StreamClock::default();
        assert_eq!(c.stamp(Some(1.4), at(0.0)), 0.0);
        assert!((c.stamp(Some(1.5), at(0.1)) - 0.1).abs() < 1e-12);
        // the stream restarts its clock after a reconnection 2 s later
        c.reconnected();
        let t = c.stamp(Some(0.0), at(2.1));
        assert!((t - 2.1).abs() < 1e-9, "{t}");
        // a repeated time still increases
        assert!(c.stamp(Some(0.0), at(2.2)) > t);
        // no presentation time: arrival times from then on
        let a = c.stamp(None, at(3.0));
        assert_eq!(c.origin, TimestampOrigin::Arrival);
        assert!((a - 3.0).abs() < 1e-9);
    }
}
