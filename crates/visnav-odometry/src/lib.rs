//! Visual odometry pipelines of visnav.
//!
//! * [`stereo`]: RotROCC stereo VO (Buczko & Willert): Shi–Tomasi features, SAD stereo, predicted
//!   pyramidal Lucas–Kanade tracking with a circular check, rotation phase on the reprojection
//!   error and translation phase on the decoupled normalized reprojection error (eq. 24–30).
//! * [`mono`]: monocular VO from dense flow with uncertainty (Ng, Li, Kim 2021, §4–5).

pub mod ba;
pub mod mono;
pub mod stereo;
