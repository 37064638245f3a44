//! Frames the stereo pipeline cannot trust (issue 21 item 3) on the real KITTI 06 clip, through
//! the streaming odometry: four pairs of the clip are replaced by a black, a white, a noise and
//! an upside-down pair. Each corrupted frame must be refused (a constant-velocity prediction with
//! its reason, never `ok`), the stream must keep one pose per frame, and every pose must stay
//! near the ground truth: the prediction bridges the refused frame and the one after it (which
//! has nothing to track from), then the estimation resumes.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use visnav_core::GrayImage;
use visnav_io::trajectory::read_kitti;
use visnav_io::{FrameSource, Sequence, Take};
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::{Control, FrameInput, Odometry, Status, run_source};

const FRAMES: usize = 40;

fn corrupt(kind: usize, real: &GrayImage) -> GrayImage {
    let (w, h) = (real.width(), real.height());
    let mut state = 0x2545_F491_4F6C_DD1D_u64;
    GrayImage::from_fn(w, h, |x, y| match kind {
        0 => 0.0,
        1 => 255.0,
        2 => {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 256) as f32
        }
        _ => real.get(x, h - 1 - y),
    })
}

#[test]
fn corrupted_pairs_in_kitti_06_are_refused_and_the_poses_stay_on_the_ground_truth() {
    let Some(root) = visnav_core::testdata::shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let gt_path = visnav_core::testdata::shared_data("kitti/odometry/poses/06.txt").unwrap();
    let seq = Sequence::open(&root).unwrap();
    let n = FRAMES.min(seq.len());
    let gt = read_kitti(&gt_path).unwrap();
    let corrupted = [8, 16, 24, 32];
    let mut vo = Odometry::stereo(seq.stereo_camera().unwrap(), StereoConfig::default()).unwrap();
    let mut results = Vec::new();
    for k in 0..n {
        let f = seq.load(k, true).unwrap();
        let (l, r) = (f.left, f.right.unwrap());
        let input = match corrupted.iter().position(|&c| c == k) {
            Some(kind) => FrameInput::stereo(corrupt(kind, &l), corrupt(kind, &r), None),
            None => FrameInput::stereo(l, r, None),
        };
        results.extend(vo.process(input));
    }
    assert_eq!(results.len(), n);
    let travelled = visnav_eval::path_length_m(&gt[..n]);
    for (k, r) in results.iter().enumerate() {
        if corrupted.contains(&k) {
            assert!(
                matches!(r.status, Status::Fallback { .. }),
                "corrupted frame {k} accepted: {:?}",
                r.status
            );
        }
        let truth = (gt[0].inverse() * gt[k]).translation.vector;
        let err = (r.world_from_cam.translation.vector - truth).norm();
        eprintln!("frame {k}: {} error {err:.3} m", r.status.name());
        assert!(
            err < 0.02 * travelled,
            "frame {k}: {err} m from the truth ({travelled} m travelled)"
        );
    }
    // the clean clip through the same API, for comparison: the corrupted stream's end point
    // stays within a few per cent of the distance of the clean one's
    let mut clean =
        Odometry::stereo(seq.stereo_camera().unwrap(), StereoConfig::default()).unwrap();
    run_source(&mut clean, Arc::new(Take::new(seq, n)), |_, _| {
        Control::Continue
    });
    let d = (clean.trajectory()[n - 1].translation.vector
        - results[n - 1].world_from_cam.translation.vector)
        .norm();
    eprintln!("end point {d:.3} m from the clean run's ({travelled:.1} m travelled)");
    assert!(d < 0.02 * travelled);
}
