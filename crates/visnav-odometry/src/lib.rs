//! Visual odometry pipelines of visnav.
//!
//! * [`stereo`]: RotROCC stereo VO (Buczko & Willert): Shi–Tomasi features, SAD stereo, predicted
//!   pyramidal Lucas–Kanade tracking with a circular check, rotation phase on the reprojection
//!   error and translation phase on the decoupled normalized reprojection error (eq. 24–30).
//! * [`mono`]: monocular VO from dense flow with uncertainty (Ng, Li, Kim 2021, §4–5).
//!
//! Relative poses: the interfaces give the motion of a frame as `prev_from_cur` (the pose of the
//! current camera in the previous camera's frame, `x_prev = prev_from_cur · x_cur`), as
//! `visnav-pipeline` does; inside, a [`RelativeMotion`] carries both directions by name.

pub mod ba;
pub mod mono;
mod motion;
pub mod stereo;

pub use motion::RelativeMotion;
