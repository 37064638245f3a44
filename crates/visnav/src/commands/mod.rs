//! One module per subcommand: each has its `Args` (clap) and a `run` function.

pub mod batch;
pub mod demo;
pub mod eval;
pub mod flow;
pub mod flow_eval;
pub mod info;
pub mod odometry;
pub mod odometry_live;
pub mod posegraph;
pub mod poses_out;
pub mod report;
pub mod synth;

/// Options shared by every subcommand.
#[derive(Debug, Clone, Copy)]
pub struct Context {
    /// `--quiet`: no progress bars or tables.
    pub quiet: bool,
}
