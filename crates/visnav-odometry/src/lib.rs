//! Visual odometry pipelines of visnav (being built).
//!
//! * [`stereo`]: RotROCC stereo VO (Buczko & Willert), decoupled normalized reprojection error.
//! * [`mono`]: monocular VO from dense flow with uncertainty (Ng, Li, Kim 2021, §4–5).

pub mod mono;
pub mod stereo;
