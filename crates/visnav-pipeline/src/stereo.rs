//! The stereo stream: RotROCC (the stereo paper) on rectified pairs, with the library's failure
//! policy: a frame without a usable pair (missing or unreadable image, no right image) gets the
//! constant-velocity prediction with status [`Status::Skipped`] and the tracking restarts at the
//! next pair; an estimation failure inside the odometry is a [`Status::Fallback`] with the
//! stereo reason.

use std::time::Instant;

use visnav_core::{GrayImage, StereoCamera};
use visnav_odometry::stereo::{
    FailReason, FrameResult as StereoResult, FrameStatus, StereoConfig, StereoOdometry,
};

use crate::PipelineError;
use crate::frame::{
    Detail, FallbackReason, FrameInput, FrameResult, FrameTimings, Images, Outputs, Status,
    StereoDetail,
};

/// The stereo stream's state (driven by [`crate::Odometry`]).
pub(crate) struct StereoStream {
    vo: StereoOdometry,
}

impl StereoStream {
    pub fn new(rig: StereoCamera, config: StereoConfig) -> Result<Self, PipelineError> {
        Ok(Self {
            vo: StereoOdometry::new(rig, config)?,
        })
    }

    /// Processes the frame at `position`.
    pub fn process(&mut self, input: FrameInput, position: usize, outputs: Outputs) -> FrameResult {
        let t = Instant::now();
        let FrameInput {
            timestamp_s,
            images,
        } = input;
        let (r, image): (StereoResult, Option<GrayImage>) = match images {
            Images::Stereo { left, right } => {
                let r = self.vo.process(&left, &right);
                (r, Some(left))
            }
            Images::Mono(left) => (
                self.vo.skip(format!("frame {position} has no right image")),
                Some(left),
            ),
            Images::Missing { reason } => (self.vo.skip(reason), None),
        };
        let status = match r.status {
            FrameStatus::First | FrameStatus::Ok => Status::Ok,
            FrameStatus::LowSpeed => Status::LowParallax,
            FrameStatus::Fallback(FailReason::MissingInput { message }) => {
                Status::Skipped { reason: message }
            }
            FrameStatus::Fallback(reason) => Status::Fallback {
                reason: FallbackReason::Stereo { reason },
            },
        };
        let detail = Detail::Stereo(StereoDetail {
            counts: r.counts,
            median_translation_flow_px: r.median_translation_flow_px,
        });
        let reference_position = (!status.is_predicted() && position > 0).then(|| position - 1);
        FrameResult {
            position,
            timestamp_s,
            world_from_cam: r.world_from_cam,
            prev_from_cur: r.prev_from_cur,
            status,
            detail,
            timings: FrameTimings {
                stereo: Some(r.timings),
                total_ms: t.elapsed().as_secs_f64() * 1e3,
                ..FrameTimings::default()
            },
            reference_position,
            flow: None,
            depth: None,
            tracks: outputs.tracks.then_some(r.tracks),
            image: if outputs.image { image } else { None },
            loop_closures: Vec::new(),
        }
    }
}
