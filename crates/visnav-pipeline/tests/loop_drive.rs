//! Loop closure on a rendered closed drive around a block (`visnav_synth::block_loop_trajectory`,
//! 320x96) with the real pipeline: dense flow with uncertainty, monocular odometry,
//! `LoopCloser` with the paper's defaults, all through the streaming odometry. The drive has 91 frames: one lap of 89 frames and
//! two more, so its last frame (90, 1.2 m past the start) is back where it began and is a
//! candidate-search frame (every 10 frames). There, at the end point, the closures must cut the
//! odometry's drift at least five-fold.
//!
//! The odometry must also stay sane on these small images: every step between a quarter and
//! twice the true 1.6 m. Before the fixes in `visnav_odometry::mono`
//! (`git show 0a7500f:docs/benchmarks.md`, *Why the monocular odometry
//! collapsed on the loop drive*) its scale collapsed after the corners (steps down to 0.008 m
//! on this drive),
//! and a degenerate ground plane could make it diverge (a 5e14 m step at 480x144).
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use visnav_core::{GrayImage, Pose};
use visnav_io::InMemorySource;
use visnav_odometry::mono::MonoConfig;
use visnav_pipeline::{Control, MemoryStore, MonoRunConfig, Odometry, run_source};
use visnav_synth::{Scene, block_loop_trajectory, kitti_like_camera, render_view};

struct Run {
    odometry: Vec<Pose>,
    corrected: Vec<Pose>,
    closures: Vec<visnav_loop::ClosureReport>,
}

/// Frames of the drive: one lap (89) and the start again; the last one closes the loop.
const FRAMES: usize = 91;

#[test]
fn loop_closure_cuts_the_end_point_drift_five_fold() {
    let gt = block_loop_trajectory(FRAMES);
    let scene = Scene::along(&gt, 0).unwrap().with_supersampling(2);
    let camera = kitti_like_camera(320, 96);
    let images: Vec<GrayImage> = gt
        .iter()
        .map(|p| render_view(&scene, &camera, p).image)
        .collect();
    // the paper's mono defaults (the parallax thresholds, given for KITTI's 1241-px width,
    // scale to the width by themselves) with the renderer's camera height, as in `visnav demo`
    let mut mono = MonoConfig::default();
    mono.scale.camera_height_m = scene.config().ground_depth_m;
    let config = MonoRunConfig {
        mono,
        ..MonoRunConfig::default()
    };
    let mut vo = Odometry::mono(camera, &config)
        .unwrap()
        .pipelined(true)
        .with_loop_closure(camera, &config, Box::new(MemoryStore::default()))
        .unwrap();
    let mut failed_frames = 0;
    let n = run_source(&mut vo, Arc::new(InMemorySource::mono(images)), |r, _| {
        failed_frames += usize::from(r.status.is_predicted());
        Control::Continue
    });
    assert_eq!(n, FRAMES);
    let run = Run {
        odometry: vo.trajectory().to_vec(),
        corrected: vo.corrected_trajectory(),
        closures: vo.loop_closer().unwrap().closures(),
    };
    assert_eq!(run.odometry.len(), FRAMES);
    assert_eq!(run.corrected.len(), FRAMES);
    let last = FRAMES - 1;
    let err = |p: &[Pose], k: usize| (p[k].translation.vector - gt[k].translation.vector).norm();
    for k in [0, 10, 30, 45, 60, 80, 89, last] {
        let xz = |p: &Pose| format!("({:.2}, {:.2})", p.translation.x, p.translation.z);
        eprintln!(
            "frame {k}: truth {}, odometry {} (error {:.3} m), corrected {} (error {:.3} m)",
            xz(&gt[k]),
            xz(&run.odometry[k]),
            err(&run.odometry, k),
            xz(&run.corrected[k]),
            err(&run.corrected, k)
        );
    }
    // the odometry's steps: no scale collapse, no divergence
    let steps: Vec<f64> = run
        .odometry
        .windows(2)
        .map(|w| (w[0].inverse() * w[1]).translation.vector.norm())
        .collect();
    let (min_step, max_step) = steps
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &s| (a.min(s), b.max(s)));
    eprintln!(
        "odometry steps {min_step:.3}..{max_step:.3} m (truth 1.6 m), {failed_frames} failed frames"
    );
    assert!(
        min_step >= 0.4 && max_step <= 3.2,
        "steps {min_step}..{max_step} m"
    );
    let (before, after) = (err(&run.odometry, last), err(&run.corrected, last));
    let accepted: Vec<_> = run.closures.iter().filter(|c| c.accepted).collect();
    eprintln!(
        "drift at the last frame ({last}, where the loop closes): odometry {before:.3} m, with loop closure {after:.3} m; closures {:#?}",
        run.closures
    );
    assert!(
        accepted.iter().any(|c| c.step == last),
        "{:?}",
        run.closures
    );
    for c in &accepted {
        // true revisits: the earlier frame is (nearly) a lap back and looks down the same street
        assert!(c.step - c.candidate >= 50, "{c:?}");
        assert!(c.reliable_fraction.unwrap() > 0.2);
    }
    assert!(after * 5.0 <= before, "{before} m -> {after} m");
}
