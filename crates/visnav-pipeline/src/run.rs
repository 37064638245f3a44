//! Driving an [`Odometry`] over a [`FrameSource`]: frames are prefetched on a thread, pushed in
//! order (an unreadable frame is pushed as [`Images::Missing`](crate::Images::Missing), so it
//! still gets a pose), and every result is handed to the caller, who may stop the run.

use std::sync::Arc;
use std::time::Instant;

use visnav_io::{FrameSource, Prefetch};

use crate::{FrameInput, FrameResult, Mode, Odometry};

/// What the caller wants after a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// Stop after this frame (e.g. on Ctrl-C); the frames still in flight are finished first.
    Stop,
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
    let mut frames = Prefetch::new(source, stereo, 2);
    let mut processed = 0;
    let mut waits: std::collections::VecDeque<f64> = std::collections::VecDeque::new();
    let mut stop = false;
    while !stop {
        let t = Instant::now();
        let Some(item) = frames.next() else { break };
        waits.push_back(t.elapsed().as_secs_f64() * 1e3);
        if let Some(r) = odometry.push(FrameInput::from_item(item)) {
            processed += 1;
            stop = on_frame(r, waits.pop_front().unwrap_or(0.0)) == Control::Stop;
        }
    }
    drop(frames);
    if let Some(r) = odometry.finish() {
        processed += 1;
        // the last frame is reported even after a stop: it was pushed
        let _ = on_frame(r, waits.pop_front().unwrap_or(0.0));
    }
    processed
}
