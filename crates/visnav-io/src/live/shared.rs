//! The state the reader thread and the consumer ([`super::LiveSource`]) share: the frames
//! waiting, the counts, and how the stream ended.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Instant;

use super::config::{FramePolicy, LiveStats};

/// A decoded frame waiting for the consumer.
pub(super) struct RawFrame {
    pub(super) gray: Vec<u8>,
    pub(super) index: usize,
    pub(super) timestamp_s: f64,
    pub(super) received: Instant,
}

/// Why the stream ended.
#[derive(Debug, Clone)]
pub(super) enum End {
    /// The input ended (standard input's end, reconnections used up) after frames.
    Finished(String),
    /// The input is unusable (wrong size, ffmpeg missing): an error.
    Failed(String),
}

/// The state shared by the reader thread and the consumer.
pub(super) struct State {
    pub(super) frames: VecDeque<RawFrame>,
    /// Dropped since the consumer took its last frame.
    pub(super) dropped_pending: usize,
    pub(super) stats: LiveStats,
    pub(super) end: Option<End>,
}

pub(super) struct Shared {
    pub(super) state: Mutex<State>,
    pub(super) changed: Condvar,
    /// The caller's stop flag (Ctrl-C).
    pub(super) stop: Arc<AtomicBool>,
    /// Set when the source is dropped.
    pub(super) closing: AtomicBool,
    pub(super) policy: FramePolicy,
    pub(super) queue_frames: usize,
}

impl Shared {
    pub(super) fn lock(&self) -> MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether reading must stop.
    pub(super) fn stopped(&self) -> bool {
        self.stop.load(Ordering::SeqCst) || self.closing.load(Ordering::SeqCst)
    }

    pub(super) fn push(&self, frame: RawFrame) {
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

    pub(super) fn end(&self, end: End) {
        self.lock().end.get_or_insert(end);
        self.changed.notify_all();
    }

    pub(super) fn update(&self, f: impl FnOnce(&mut LiveStats)) {
        f(&mut self.lock().stats);
    }
}
