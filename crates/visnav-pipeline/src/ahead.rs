//! The one threaded component of the pipeline: the dense flow of the next image pair computed on
//! its own thread while the current frame's odometry runs.
//!
//! The flow does not depend on the odometry, so with a frame of latency the two overlap: when
//! frame `k+1` arrives, the flow `k-1 → k` is waited for, the flow `k → k+1` starts on a thread
//! and the odometry of frame `k` runs on the caller's thread (both share rayon's pool, so the
//! sequential parts of one fill the other's gaps). At most one flow computes at a time, so the
//! flow's buffers exist once. The flow is speculative: it is keyed by the positions of its two images and
//! used only when frame `k` was accepted as the reference of frame `k+1`; otherwise it is joined
//! and dropped, and the flow from the actual reference is computed inline.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use visnav_core::GrayImage;
use visnav_flow::{DenseFlow, FlowTimings};
use visnav_odometry::mono::{MonoError, MonoFlow};

/// A flow result with its timings, or the flow stage's error.
pub(crate) type FlowOutcome = Result<(DenseFlow, FlowTimings), MonoError>;

/// A flow computing on its own thread (see the module docs).
pub(crate) struct FlowAhead {
    /// Position of the image the flow starts from.
    pub from_position: usize,
    /// Position of the image it ends in.
    pub to_position: usize,
    handle: JoinHandle<FlowOutcome>,
}

impl FlowAhead {
    /// Starts the flow `from → to` on a new thread; `None` when no thread can be spawned (the
    /// flow is then computed inline when needed).
    pub fn spawn(
        estimator: &Arc<MonoFlow>,
        from: &GrayImage,
        to: &GrayImage,
        from_position: usize,
        to_position: usize,
    ) -> Option<Self> {
        let (estimator, from, to) = (Arc::clone(estimator), from.clone(), to.clone());
        let handle = std::thread::Builder::new()
            .name("visnav-flow-ahead".into())
            .spawn(move || estimator.compute_timed(&from, &to))
            .map_err(|e| log::warn!("cannot start the flow thread ({e}); computing inline"))
            .ok()?;
        Some(Self {
            from_position,
            to_position,
            handle,
        })
    }

    /// Waits for the flow. A panic of the flow thread is re-raised on the caller's thread.
    pub fn join(self) -> FlowOutcome {
        match self.handle.join() {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }

    /// Waits for the flow and keeps it with its key and the time waited.
    pub fn wait(self) -> ReadyFlow {
        let t = Instant::now();
        let (from_position, to_position) = (self.from_position, self.to_position);
        let outcome = self.join();
        ReadyFlow {
            from_position,
            to_position,
            outcome,
            wait_ms: t.elapsed().as_secs_f64() * 1e3,
        }
    }
}

/// A flow computed ahead and waited for.
pub(crate) struct ReadyFlow {
    /// Position of the image the flow starts from.
    pub from_position: usize,
    /// Position of the image it ends in.
    pub to_position: usize,
    /// The flow or its error.
    pub outcome: FlowOutcome,
    /// Time waited for it, milliseconds.
    pub wait_ms: f64,
}
