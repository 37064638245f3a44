//! Progress of long stages, reported by the libraries and drawn by the front ends (the CLI's
//! progress bars): a library only counts.

/// Receives the progress of a long stage.
pub trait Progress: Sync {
    /// `done` of `total` steps of the stage `stage` are finished.
    fn step(&self, stage: &str, done: u64, total: u64);
}

/// Reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn step(&self, _stage: &str, _done: u64, _total: u64) {}
}
