//! Driving an [`Odometry`] over a [`FrameSource`] or any ordered stream of
//! [`SourceItem`]s (a live source): frames are pushed in order (an unreadable frame is pushed
//! as [`Images::Missing`](crate::Images::Missing), so it still gets a pose), and every result is
//! handed to the caller, who may stop the run.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use visnav_io::{FrameSource, Prefetch, SourceItem};

use crate::{FrameInput, FrameResult, Mode, Odometry};

/// What the caller wants after a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// Stop after this frame (e.g. on Ctrl-C); the frames still in flight are finished first.
    Stop,
}

/// How a frame came to the odometry and how long its pose took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrival {
    /// The frame's index in the input (a live stream counts the dropped frames too).
    pub index: usize,
    /// Time the run waited for the frame's images, milliseconds.
    pub wait_ms: f64,
    /// From the frame's arrival ([`SourceItem::received`]) to its result, milliseconds.
    pub latency_ms: f64,
    /// Frames dropped just before this one by a live stream's frame policy.
    pub dropped_before: usize,
}

/// Runs `odometry` over every position of `source`. `on_frame` gets each result in order with
/// the time the run waited for that frame's images (milliseconds). Returns the number of frames
/// processed (every pushed frame gets a result, also when stopped early).
pub fn run_source(
    odometry: &mut Odometry,
    source: Arc<dyn FrameSource>,
    mut on_frame: impl FnMut(FrameResult, f64) -> Control,
) -> usize {
    let stereo = odometry.mode() == Mode::Stereo;
    let frames = Prefetch::new(source, stereo, 2);
    run_items(odometry, frames, |r, a| on_frame(r, a.wait_ms))
}

/// Runs `odometry` over the items of `frames` in order until it ends (a live source: at the end
/// of the stream or its stop flag). `on_frame` gets each result with its [`Arrival`]. Returns
/// the number of frames processed (every pushed frame gets a result, also when stopped early).
pub fn run_items(
    odometry: &mut Odometry,
    mut frames: impl Iterator<Item = SourceItem>,
    mut on_frame: impl FnMut(FrameResult, &Arrival) -> Control,
) -> usize {
    let mut processed = 0;
    // the frames pushed whose result has not come yet (one in pipelined mode)
    let mut pending: VecDeque<(f64, Instant, usize, usize)> = VecDeque::new();
    let arrival = |r: &FrameResult, pending: &mut VecDeque<_>| {
        let (wait_ms, received, index, dropped_before) =
            pending
                .pop_front()
                .unwrap_or((0.0, Instant::now(), r.position, 0));
        Arrival {
            index,
            wait_ms,
            latency_ms: received.elapsed().as_secs_f64() * 1e3,
            dropped_before,
        }
    };
    let mut stop = false;
    while !stop {
        let t = Instant::now();
        let Some(item) = frames.next() else { break };
        let wait_ms = t.elapsed().as_secs_f64() * 1e3;
        pending.push_back((wait_ms, item.received, item.index, item.dropped_before));
        if let Some(r) = odometry.push(FrameInput::from_item(item)) {
            processed += 1;
            let a = arrival(&r, &mut pending);
            stop = on_frame(r, &a) == Control::Stop;
        }
    }
    drop(frames);
    if let Some(r) = odometry.finish() {
        processed += 1;
        // the last frame is reported even after a stop: it was pushed
        let a = arrival(&r, &mut pending);
        let _ = on_frame(r, &a);
    }
    processed
}
