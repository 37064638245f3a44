//! The monocular pipeline with loop closure over images held in memory: dense flow between
//! consecutive images, [`MonoOdometry`], then [`LoopCloser`]. Used by the synthetic loop-drive
//! test and `visnav demo`; the CLI (`visnav odometry --mode mono --loop-closure`) drives the same
//! stages frame by frame from disk.

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::{FlowConfig, FlowEstimator, FlowInput};
use visnav_odometry::mono::{FrameStatus, MonoConfig, MonoOdometry};

use crate::{ClosureReport, LoopCloser, LoopConfig, LoopError};

/// The result of [`run_mono_with_loop_closure`].
#[derive(Debug, Clone)]
pub struct MonoLoopRun {
    /// Odometry-only poses, one per image.
    pub odometry: Vec<Pose>,
    /// Poses after loop closure, one per image.
    pub corrected: Vec<Pose>,
    /// Every verified candidate.
    pub closures: Vec<ClosureReport>,
    /// Frames whose flow or odometry failed (constant-velocity prediction).
    pub failed_frames: usize,
    /// Time in dense flow between consecutive images, seconds.
    pub flow_s: f64,
}

/// Runs the monocular odometry and the loop-closure stage over `images` (one pose per image).
/// A frame whose flow or odometry fails keeps the last motion (logged) and the run goes on.
///
/// # Errors
/// [`LoopError::InvalidConfig`] for an invalid configuration, [`LoopError::ThumbnailSize`] when
/// the images differ in size.
pub fn run_mono_with_loop_closure(
    camera: PinholeCamera,
    images: &[GrayImage],
    mono: MonoConfig,
    flow: FlowConfig,
    config: LoopConfig,
) -> Result<MonoLoopRun, LoopError> {
    let invalid = |field, e: &dyn std::fmt::Display| LoopError::InvalidConfig {
        field,
        message: e.to_string(),
    };
    let estimator = FlowEstimator::new(flow.clone()).map_err(|e| invalid("flow", &e))?;
    let mut vo = MonoOdometry::new(camera, mono.clone()).map_err(|e| invalid("mono", &e))?;
    let mut closer = LoopCloser::new(camera, config, mono, flow)?;
    let mut failed_frames = 0;
    let mut flow_s = 0.0;
    let mut last_motion = Pose::identity();
    for (i, image) in images.iter().enumerate() {
        let t = std::time::Instant::now();
        let dense = match i.checked_sub(1).map(|p| &images[p]) {
            Some(prev) => match estimator.compute(prev, image, &FlowInput::default()) {
                Ok(f) => Some(f),
                Err(e) => {
                    log::warn!("flow into frame {i}: {e}");
                    None
                }
            },
            None => None,
        };
        flow_s += t.elapsed().as_secs_f64();
        let motion = match (i, &dense) {
            (0, _) | (_, Some(_)) => match vo.process(image, dense.as_ref()) {
                Ok(r) => {
                    if r.status == FrameStatus::Failed {
                        failed_frames += 1;
                    }
                    Some(r.cur_from_prev)
                }
                Err(e) => {
                    log::warn!("odometry of frame {i}: {e}");
                    None
                }
            },
            _ => None,
        };
        // a frame the odometry did not take has no depth map of its own
        let depth = motion.and(vo.depth_map());
        let motion = motion.unwrap_or_else(|| {
            failed_frames += 1;
            last_motion
        });
        last_motion = motion;
        closer.process(Some(image), &motion, depth, |s| {
            images
                .get(s)
                .cloned()
                .ok_or_else(|| format!("no image {s}"))
        })?;
    }
    Ok(MonoLoopRun {
        odometry: closer.odometry_poses().to_vec(),
        corrected: closer.corrected_poses(),
        closures: closer.closures(),
        failed_frames,
        flow_s,
    })
}
