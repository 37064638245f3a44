//! What the tracker and the mapper read of the odometry while they work on one frame.

use visnav_core::PinholeCamera;

use super::config::MonoConfig;
use crate::RelativeMotion;

/// The odometry's fixed parts and the frame's place in the sequence, lent to the stages of
/// one frame (none of them changes the odometry: [`super::MonoOdometry`] commits their results).
#[derive(Debug, Clone, Copy)]
pub(super) struct FrameContext<'a> {
    /// The configuration.
    pub(super) config: &'a MonoConfig,
    /// The camera the images and flows are taken with.
    pub(super) camera: &'a PinholeCamera,
    /// The frame's number (0 = the first image).
    pub(super) frame: usize,
    /// The driver's constant-velocity prior, metres: the last estimated motion
    /// ([`super::MonoOdometry::process`]'s `prior`; `None` before the first estimate).
    pub(super) last_motion: Option<RelativeMotion>,
}

impl FrameContext<'_> {
    /// Whether the depth map keeps sub-pixel points (`depth_points`).
    pub(super) fn subpixel_depth(&self) -> bool {
        self.config.depth_points.subpixel(self.config.scale.aerial)
    }

    /// Whether the depth map is an unfiltered inverse-depth filter (`inverse_depth_filter`,
    /// with sub-pixel points only).
    pub(super) fn inverse_depth_filter(&self) -> bool {
        self.config.inverse_depth_filter && self.subpixel_depth()
    }
}
