//! The monocular stream after a stretch of unusable frames, on the real KITTI 00 clip: frames
//! 6–13 are black (a covered lens). Every black frame is refused and predicted; the first real
//! frame after them lies too far from the last accepted one to match against
//! (`TrustConfig::max_reference_gap_frames`), so the odometry starts a new map there
//! (`FallbackReason::Restarted`) and estimates every later frame again, at the ground plane's
//! metric scale. Without the restart (a gap limit beyond the stream) the same stream refuses
//! the frames after the blackout.
#![allow(clippy::unwrap_used)]

mod common;

use common::StepError;

use visnav_core::{GrayImage, Pose};
use visnav_pipeline::{FallbackReason, FrameInput, FrameResult, MonoRunConfig, Odometry, Status};

const FRAMES: usize = 24;
const BLACK: std::ops::Range<usize> = 6..14;
/// Bound on the last frame's distance from the ground truth, metres (as `mono_untrusted.rs`).
const MAX_POSITION_ERROR_M: f64 = 2.0;

/// The clip's first `FRAMES` frames with `BLACK` blacked out, through the stream (synchronous);
/// `None` without the data.
fn run(max_gap: usize) -> Option<(Vec<FrameResult>, Vec<Pose>)> {
    let (seq, all) = common::kitti_00()?;
    let gt = all[..FRAMES].to_vec();
    let mut config = MonoRunConfig::default();
    config.mono.trust.max_reference_gap_frames = max_gap;
    let mut vo = Odometry::mono(seq.camera, &config).unwrap();
    let mut out = Vec::new();
    for k in 0..FRAMES {
        let real = seq.load_left(k).unwrap();
        let image = if BLACK.contains(&k) {
            GrayImage::from_fn(real.width(), real.height(), |_, _| 0.0)
        } else {
            real
        };
        out.extend(vo.push(FrameInput::mono(image, Some(k as f64 * 0.1))));
    }
    out.extend(vo.finish());
    assert_eq!(out.len(), FRAMES, "one result per pushed frame");
    Some((out, gt))
}

#[test]
fn a_blackout_is_bridged_by_a_new_map_at_metric_scale() {
    let Some((r, gt)) = run(3) else { return };
    let restart = BLACK.end;
    for f in &r[BLACK] {
        assert!(
            matches!(&f.status, Status::Fallback { reason: FallbackReason::Refused { message } } if message.contains("texture")),
            "black frame {}: {:?}",
            f.position,
            f.status
        );
    }
    assert_eq!(
        r[restart].status,
        Status::Fallback {
            reason: FallbackReason::Restarted {
                last_accepted: BLACK.start - 1,
                gap_frames: restart - (BLACK.start - 1),
            }
        }
    );
    for (k, f) in r.iter().enumerate().skip(restart + 1) {
        assert!(!f.status.is_predicted(), "frame {k}: {:?}", f.status);
        // the step against the truth: rotation, direction and metric length (the ground plane)
        let e = StepError::of(&gt[k - 1], &gt[k], &f.prev_from_cur);
        eprintln!("frame {k}: {}, {e}", f.status.name());
        assert!(e.rotation_deg < 0.5, "frame {k}: {e}");
        assert!(e.direction_deg < 5.0, "frame {k}: {e}");
        assert!((0.8..1.25).contains(&e.length_ratio), "frame {k}: {e}");
    }
    // the blackout bridged by the constant-velocity prediction (KITTI 00 drives straight there)
    let end = FRAMES - 1;
    let off_m = (r[end].world_from_cam.translation.vector - gt[end].translation.vector).norm();
    eprintln!("frame {end}: {off_m:.3} m from the ground truth");
    assert!(off_m < MAX_POSITION_ERROR_M, "frame {end}: {off_m} m off");
}

#[test]
fn without_the_restart_the_frames_after_a_blackout_are_refused() {
    let Some((r, _)) = run(FRAMES) else { return };
    let refused = r[BLACK.end..]
        .iter()
        .filter(|f| f.status.is_predicted())
        .count();
    for f in &r[BLACK.end..] {
        eprintln!("frame {}: {:?}", f.position, f.status);
    }
    assert!(
        refused >= (FRAMES - BLACK.end) / 2,
        "{refused} of the {} frames after the blackout refused",
        FRAMES - BLACK.end
    );
}
