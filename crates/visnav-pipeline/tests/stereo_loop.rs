//! Stereo loop closure (issue #25) on a rendered closed drive through the streaming odometry:
//! RotROCC with the window bundle adjustment, then the loop closer with the stereo defaults
//! (`LoopConfig::stereo`: SSIM candidates, flow verification, PnP from the earlier frame's stereo
//! points, at least half of them inliers, robust pose graph).
//!
//! The drive (`visnav_synth::loop_trajectory`) goes once around a 70 m x 50 m block with 25 m
//! corner radii (197.1 m) in 160 steps of 1.23 m, 620x188 stereo pairs with the KITTI baseline;
//! its last frame (160) is back at the start and is a candidate-search frame (every 10 frames).
//! (The 10 m corners of `block_loop_trajectory`, 9° a frame at 1.6 m steps, are too sharp for
//! the stereo front end at this size: 80 m of error on that lap.) At the last frame the closure
//! must cut the odometry's end-point error at least five-fold, every accepted closure must be a
//! true revisit, and the odometry's own trajectory must be untouched by the closures.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use visnav_core::{Pose, StereoCamera};
use visnav_io::InMemorySource;
use visnav_loop::LoopConfig;
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::{Control, MemoryStore, MonoRunConfig, Odometry, run_source};
use visnav_synth::{KITTI_BASELINE_M, Scene, kitti_like_camera, loop_trajectory, render_stereo};

/// Steps of one lap; the drive has one more frame, back at the start.
const LAP_STEPS: usize = 160;

#[test]
fn stereo_loop_closure_cuts_the_end_point_error_five_fold() {
    let (length_m, width_m, radius_m) = (70.0, 50.0, 25.0);
    let perimeter_m =
        2.0 * (length_m + width_m) - 8.0 * radius_m + std::f64::consts::TAU * radius_m;
    let frames = LAP_STEPS + 1;
    let gt = loop_trajectory(
        frames,
        length_m,
        width_m,
        radius_m,
        perimeter_m / LAP_STEPS as f64,
    );
    let last = frames - 1;
    assert!((gt[last].translation.vector - gt[0].translation.vector).norm() < 1e-6);
    let scene = Scene::along(&gt, 0).unwrap().with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let pairs: Vec<_> = gt
        .iter()
        .map(|p| {
            let (l, r) = render_stereo(&scene, &rig, p);
            (l.image, r.image)
        })
        .collect();
    let config = MonoRunConfig {
        loop_closure: LoopConfig::stereo(),
        ..MonoRunConfig::default()
    };
    let mut vo = Odometry::stereo(rig, StereoConfig::default())
        .unwrap()
        .with_loop_closure(rig.left, &config, Box::new(MemoryStore::default()))
        .unwrap();
    let source = Arc::new(InMemorySource::stereo(pairs.clone()));
    let n = run_source(&mut vo, source, |_, _| Control::Continue);
    assert_eq!(n, frames);
    let odometry = vo.trajectory().to_vec();
    let corrected = vo.corrected_trajectory();
    let closures = vo.loop_closer().unwrap().closures();
    assert_eq!(odometry.len(), frames);
    assert_eq!(corrected.len(), frames);
    let err = |p: &[Pose], k: usize| (p[k].translation.vector - gt[k].translation.vector).norm();
    let (before, after) = (err(&odometry, last), err(&corrected, last));
    eprintln!(
        "end point (frame {last}): odometry {before:.4} m, with loop closure {after:.4} m; closures {closures:#?}"
    );
    let accepted: Vec<_> = closures.iter().filter(|c| c.accepted).collect();
    assert!(accepted.iter().any(|c| c.step == last), "{closures:?}");
    for c in &accepted {
        // true revisits: a lap apart and within a few metres of each other
        let apart_m = (gt[c.step].translation.vector - gt[c.candidate].translation.vector).norm();
        assert!(c.step - c.candidate >= 50 && apart_m < 5.0, "{c:?}");
        let pose = c.relative_pose.unwrap();
        assert!(2 * pose.pnp_inliers >= pose.pnp_correspondences, "{c:?}");
    }
    // the odometry's own trajectory is untouched by the closures
    let mut plain = Odometry::stereo(rig, StereoConfig::default()).unwrap();
    run_source(
        &mut plain,
        Arc::new(InMemorySource::stereo(pairs)),
        |_, _| Control::Continue,
    );
    assert_eq!(plain.trajectory(), odometry.as_slice());
    assert!(after * 5.0 <= before, "{before} m -> {after} m");
}

#[test]
fn feature_depth_map_holds_each_feature_at_its_pixel_and_skips_bad_ones() {
    use nalgebra::{Point2, Vector3};
    use visnav_odometry::stereo::StereoFeature;
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let feature = |u: f64, v: f64, z_m: f64| StereoFeature {
        left_px: Point2::new(u, v),
        right_px: Point2::new(u - 10.0, v),
        disparity_px: 10.0,
        p_in_cam: Vector3::new(0.0, 0.0, z_m),
    };
    let features = [
        feature(100.4, 50.6, 12.0),
        feature(-5.0, 20.0, 8.0),   // left of the image
        feature(300.0, 90.0, -3.0), // behind the camera
        feature(310.0, 95.0, f64::NAN),
    ];
    let map = visnav_pipeline::feature_depth_map(&rig, &features).unwrap();
    assert_eq!((map.stride, map.cols, map.rows), (4, 155, 47));
    assert_eq!(map.known(), 1);
    let cell = map.cell_of(&Point2::new(100.4, 50.6)).unwrap();
    let (z_m, variance_m2) = map.get(cell).unwrap();
    assert!((z_m - 12.0).abs() < 1e-6);
    // the point keeps the feature's own pixel
    assert!((map.point_pixel(cell) - Point2::new(100.4, 50.6)).norm() < 1e-4);
    // of two features in one cell, the nearer
    let two = [feature(100.4, 50.6, 12.0), feature(101.0, 50.0, 9.0)];
    let map = visnav_pipeline::feature_depth_map(&rig, &two).unwrap();
    assert_eq!(map.known(), 1);
    assert!((map.get(cell).unwrap().0 - 9.0).abs() < 1e-6);
    // σ_z = z² σ_d / (f b) with σ_d = 0.5 px
    let sigma_m = 144.0 * 0.5 / (rig.left.fx * rig.baseline_m);
    assert!((variance_m2 - sigma_m * sigma_m).abs() < 1e-6 * sigma_m * sigma_m);
    assert!(visnav_pipeline::feature_depth_map(&rig, &features[1..]).is_none());
    assert!(visnav_pipeline::feature_depth_map(&rig, &[]).is_none());
}

#[test]
fn stereo_loop_table_overrides_the_stereo_defaults() {
    use visnav_pipeline::Mode;
    use visnav_pipeline::job::{ConfigSource, RunSpec};
    let mut spec = RunSpec::new("unused", Mode::Stereo);
    spec.loop_closure = true;
    assert_eq!(
        spec.stereo_loop_config().unwrap().loop_closure,
        LoopConfig::stereo()
    );
    // inline: the loop table beside the stereo keys, one nested key overridden
    spec.config = Some(ConfigSource::Inline(serde_json::json!({
        "max_depth_m": 60.0,
        "loop_closure": {"candidates": {"min_index_gap": 4}}
    })));
    assert!((spec.stereo_config().unwrap().max_depth_m - 60.0).abs() < 1e-12);
    let lc = spec.stereo_loop_config().unwrap().loop_closure;
    assert_eq!(lc.candidates.min_index_gap, 4);
    assert_eq!(lc.candidates.every_n_frames, 10);
    assert!((lc.min_pnp_inlier_fraction - 0.5).abs() < 1e-12);
    // a TOML file: the same, and an unknown loop key is an error naming the file
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stereo.toml");
    std::fs::write(
        &path,
        "max_depth_m = 60.0\n[loop_closure]\nmin_pnp_inlier_fraction = 0.7\n",
    )
    .unwrap();
    spec.config = Some(ConfigSource::File(path.clone()));
    assert!((spec.stereo_config().unwrap().max_depth_m - 60.0).abs() < 1e-12);
    let lc = spec.stereo_loop_config().unwrap().loop_closure;
    assert!((lc.min_pnp_inlier_fraction - 0.7).abs() < 1e-12);
    assert_eq!(lc.candidates.min_index_gap, 50);
    // the effective configuration holds both and reads back (TOML file, report JSON)
    let effective = spec.effective_config().unwrap();
    assert!(matches!(
        effective,
        visnav_pipeline::RunConfig::StereoLoop(_)
    ));
    let json = serde_json::to_value(&effective).unwrap();
    assert_eq!(
        serde_json::from_value::<visnav_pipeline::RunConfig>(json).unwrap(),
        effective
    );
    let written = dir.path().join("effective.toml");
    std::fs::write(&written, effective.to_toml().unwrap()).unwrap();
    let mut again = spec.clone();
    again.config = Some(ConfigSource::File(written));
    assert_eq!(again.effective_config().unwrap(), effective);
    std::fs::write(&path, "[loop_closure]\nnope = 1\n").unwrap();
    let e = spec.stereo_loop_config().unwrap_err().to_string();
    assert!(e.contains("stereo.toml"), "{e}");
    std::fs::write(&path, "[loop_closure]\nmin_pnp_inlier_fraction = 1.5\n").unwrap();
    assert!(spec.stereo_loop_config().is_err());
}
