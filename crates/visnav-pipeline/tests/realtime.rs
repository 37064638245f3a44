//! The real-time preset (`MonoRunConfig::realtime`: the monocular odometry on the fast flow)
//! through the streaming odometry on a rendered drive (a turn, a stop, a rotation on the spot)
//! and a rendered downward flight, with exact ground truth, and on the real KITTI 00 frames. The
//! paper preset's accuracy on these is the yardstick; the speed is measured in
//! `scripts/bench.sh`, not here.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Arc;

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_io::{InMemorySource, Take};
use visnav_pipeline::{Control, MonoRunConfig, Odometry, run_source};
use visnav_synth::{
    FlightConfig, FlightView, Scene, drive_trajectory, flight_trajectory, kitti_like_camera,
    render_view,
};

/// Figures of one run: Sim(3)-aligned ATE over the path, the alignment's scale (1: the metric
/// scale is right), frames that got the fallback.
struct Scores {
    ate_fraction: f64,
    scale: f64,
    predicted: usize,
}

fn run(
    camera: PinholeCamera,
    config: &MonoRunConfig,
    images: Vec<GrayImage>,
    gt: &[Pose],
) -> Scores {
    let mut vo = Odometry::mono(camera, config).unwrap().pipelined(true);
    let mut predicted = 0;
    let n = run_source(&mut vo, Arc::new(InMemorySource::mono(images)), |r, _| {
        predicted += usize::from(r.status.is_predicted());
        Control::Continue
    });
    assert_eq!(n, gt.len(), "one pose per frame");
    let est = visnav_eval::pose_matrices(vo.trajectory());
    let truth = visnav_eval::pose_matrices(gt);
    let ate = visnav_eval::align::ate(&truth, &est, true).unwrap();
    Scores {
        ate_fraction: ate.rmse_m / visnav_eval::path_length_m(gt),
        scale: ate.alignment.scale,
        predicted,
    }
}

fn rendered(scene: &Scene, camera: &PinholeCamera, gt: &[Pose]) -> Vec<GrayImage> {
    gt.iter()
        .map(|p| render_view(scene, camera, p).image)
        .collect()
}

#[test]
fn the_realtime_preset_drives_a_rendered_drive_as_the_paper_preset_does() {
    let gt = drive_trajectory(40, 11);
    let scene = Scene::along(&gt, 11).unwrap().with_supersampling(2);
    let camera = kitti_like_camera(480, 144);
    let images = rendered(&scene, &camera, &gt);
    let mut scores = Vec::new();
    for (name, mut config) in [
        ("realtime", MonoRunConfig::realtime()),
        ("paper", MonoRunConfig::default()),
    ] {
        config.mono.scale.camera_height_m = scene.config().ground_depth_m;
        let s = run(camera, &config, images.clone(), &gt);
        eprintln!(
            "{name}: Sim(3) ATE {:.3} % of the path, scale {:.4}, {} predicted frames",
            100.0 * s.ate_fraction,
            s.scale,
            s.predicted
        );
        scores.push(s);
    }
    let (rt, paper) = (&scores[0], &scores[1]);
    assert!(rt.predicted <= paper.predicted + 1, "predicted frames");
    assert!(
        rt.ate_fraction < 0.05,
        "ATE {} of the path",
        rt.ate_fraction
    );
    assert!((rt.scale - 1.0).abs() < 0.15, "scale {}", rt.scale);
    assert!(
        rt.ate_fraction < 2.0 * paper.ate_fraction.max(0.005),
        "realtime {} paper {}",
        rt.ate_fraction,
        paper.ate_fraction
    );
}

#[test]
fn the_realtime_preset_flies_a_rendered_downward_flight() {
    let flight = FlightConfig {
        view: FlightView::Down,
        height_m: 30.0,
        speed_mps: 15.0,
        climb_m: 3.0,
        ..FlightConfig::default()
    };
    let gt = flight_trajectory(30, &flight).unwrap();
    let scene = Scene::along_with(&gt, 5, flight.scene())
        .unwrap()
        .with_supersampling(1);
    let camera = kitti_like_camera(480, 144);
    let images = rendered(&scene, &camera, &gt);
    let mut config = MonoRunConfig::realtime();
    config.mono.scale.camera_height_m = flight.height_m;
    config.mono.scale.aerial = true;
    let s = run(camera, &config, images, &gt);
    eprintln!(
        "downward flight: Sim(3) ATE {:.3} % of the path, scale {:.4}, {} predicted frames",
        100.0 * s.ate_fraction,
        s.scale,
        s.predicted
    );
    assert_eq!(s.predicted, 0);
    assert!(s.ate_fraction < 0.01, "ATE {} of the path", s.ate_fraction);
    assert!((s.scale - 1.0).abs() < 0.05, "scale {}", s.scale);
}

/// The first 40 frames of the real KITTI 00 clip: every step's rotation, direction and length
/// against the ground truth, with the bounds `mono_kitti`'s CI test puts on the paper preset.
#[test]
fn the_realtime_preset_follows_kitti_00() {
    let Some((seq, all)) = common::kitti_00() else {
        return;
    };
    let frames = 40;
    let mut config = MonoRunConfig::realtime();
    config.mono.scale.camera_height_m = 1.7;
    let mut vo = Odometry::mono(seq.camera, &config).unwrap().pipelined(true);
    let mut results = Vec::new();
    run_source(&mut vo, Arc::new(Take::new(seq, frames)), |r, _| {
        results.push(r);
        Control::Continue
    });
    assert_eq!(results.len(), frames);
    for (k, r) in results.iter().enumerate().skip(1) {
        let e = common::StepError::of(&all[k - 1], &all[k], &r.prev_from_cur);
        assert!(!r.status.is_predicted(), "frame {k}: {}", r.status.name());
        assert!(e.rotation_deg < 0.01_f64.to_degrees(), "frame {k}: {e}");
        assert!(e.direction_deg < 0.1_f64.to_degrees(), "frame {k}: {e}");
        assert!((0.7..1.3).contains(&e.length_ratio), "frame {k}: {e}");
    }
}
