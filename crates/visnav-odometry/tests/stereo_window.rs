//! Persistent tracks and the window bundle adjustment in the stereo odometry (issue #25) on
//! rendered drives: tracks live over many frames, the window runs, and (ignored, long) the
//! ablation on the 1,000-frame highway drive.
#![allow(clippy::unwrap_used)] // fixtures of fixed, valid synthetic scenes

mod common;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use visnav_core::{GrayImage, Pose, StereoCamera};
use visnav_eval::kitti::{KittiMetricConfig, KittiScore, kitti_score, sequence_errors};
use visnav_image::{Pyramid, detect_corners};
use visnav_odometry::RelativeMotion;
use visnav_odometry::stereo::{
    FrameStatus, MatchConfig, StereoConfig, StereoOdometry, match_feature,
};
use visnav_synth::{
    KITTI_BASELINE_M, Scene, SceneConfig, drive_trajectory, highway_trajectory, kitti_like_camera,
    render_stereo,
};

/// The pipeline variants of the ablation, on the stereo settings of `VISNAV_STEREO_JSON` (any
/// field, e.g. `'{"max_depth_m":200}'`; default: the defaults); the BA variant's window settings
/// from `VISNAV_WINDOW_JSON` (e.g. `'{"window_frames":10}'`).
fn variants() -> Vec<(&'static str, StereoConfig)> {
    let base: StereoConfig = std::env::var("VISNAV_STEREO_JSON").map_or_else(
        |_| StereoConfig::default(),
        |json| serde_json::from_str(&json).unwrap(),
    );
    let mut f2f = base.clone();
    f2f.window.persistent_tracks = false;
    f2f.window.bundle_adjustment = false;
    let mut tracks = base.clone();
    tracks.window.bundle_adjustment = false;
    let mut ba = base;
    if let Ok(json) = std::env::var("VISNAV_WINDOW_JSON") {
        ba.window = serde_json::from_str(&json).unwrap();
    }
    vec![
        ("frame-to-frame", f2f),
        ("tracks", tracks),
        ("tracks + BA", ba),
    ]
}

/// Gaussian pixel noise of `sigma` grey levels (the renderer is noise-free).
fn noisy(image: &GrayImage, sigma: f32, rng: &mut ChaCha8Rng) -> GrayImage {
    let noise = Normal::new(0.0f32, sigma).unwrap();
    let mut out = image.clone();
    for v in out.data_mut() {
        *v = (*v + noise.sample(rng)).clamp(0.0, 255.0);
    }
    out
}

struct Run {
    gt: Vec<Pose>,
    est: Vec<Vec<Pose>>,
    status: Vec<Vec<FrameStatus>>,
    carried: Vec<usize>,
    window_points: Vec<usize>,
}

/// Renders the drive once and feeds every variant the same noisy pairs.
fn run(gt: Vec<Pose>, scene: &Scene, rig: StereoCamera, sigma: f32, seed: u64) -> Run {
    let configs = variants();
    let mut vos: Vec<StereoOdometry> = configs
        .iter()
        .map(|(_, c)| StereoOdometry::new(rig, c.clone()).unwrap())
        .collect();
    // each odometry's constant-velocity model, kept by its driver
    let mut motions = vec![RelativeMotion::identity(); vos.len()];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Run {
        gt: Vec::new(),
        est: vec![Vec::new(); vos.len()],
        status: vec![Vec::new(); vos.len()],
        carried: Vec::new(),
        window_points: Vec::new(),
    };
    for world_from_left in &gt {
        let (l, r) = render_stereo(scene, &rig, world_from_left);
        let (l, r) = (
            noisy(&l.image, sigma, &mut rng),
            noisy(&r.image, sigma, &mut rng),
        );
        for (k, (vo, motion)) in vos.iter_mut().zip(&mut motions).enumerate() {
            let res = vo.process(&l, &r, motion);
            *motion = res.motion.unwrap_or(*motion);
            out.est[k].push(res.world_from_cam);
            out.status[k].push(res.status);
            if k + 1 == configs.len() {
                out.carried.push(res.counts.carried);
                out.window_points.push(res.counts.window_points);
            }
        }
    }
    let first_inv = gt[0].inverse();
    out.gt = gt.iter().map(|p| first_inv * p).collect();
    out
}

fn score(gt: &[Pose], est: &[Pose], cfg: &KittiMetricConfig) -> KittiScore {
    let gt_m: Vec<_> = gt.iter().map(Pose::to_homogeneous).collect();
    let est_m: Vec<_> = est.iter().map(Pose::to_homogeneous).collect();
    let errors = sequence_errors(&gt_m, &est_m, cfg, 0);
    assert!(!errors.is_empty());
    kitti_score(&errors, &cfg.lengths_m)
}

#[test]
fn tracks_persist_and_the_window_adjusts_on_a_rendered_drive() {
    let gt = drive_trajectory(30, 7);
    let scene = Scene::along(&gt, 7).unwrap();
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let r = run(gt, &scene, rig, 1.0, 7);
    for status in &r.status {
        common::assert_no_fallback(status);
    }
    // most features of a frame are carried over, and the window adjusts every frame
    let moving = 2..8; // the first cruise (the drive stops later)
    assert!(
        r.carried[moving.clone()].iter().all(|&c| c > 100),
        "{:?}",
        r.carried
    );
    assert!(
        r.window_points[moving].iter().all(|&p| p > 100),
        "{:?}",
        r.window_points
    );
    let cfg = KittiMetricConfig {
        lengths_m: vec![5.0, 10.0, 15.0, 20.0],
        step_frames: 2,
        frame_period_s: 0.1,
    };
    for ((name, _), est) in variants().iter().zip(&r.est) {
        let s = score(&r.gt, est, &cfg);
        eprintln!(
            "{name}: t_err {:.4} %  r_err {:.4} deg/100m",
            s.t_err_percent, s.r_err_deg_per_100m
        );
        assert!(s.t_err_percent < 1.0, "{name}: t_err {} %", s.t_err_percent);
    }
}

/// The points beyond 80 m are what fixes the rotation at highway speed (25–30 m/s): with them
/// (the default `max_depth_m`) the window pipeline turns less wrongly than without, on 200 frames
/// of the highway drive of [`highway_ablation`].
#[test]
fn far_points_fix_the_rotation_on_a_highway() {
    let gt = highway_trajectory(200, 5);
    let scene = Scene::along_with(&gt, 5, SceneConfig::highway())
        .unwrap()
        .with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let near = StereoConfig {
        max_depth_m: 80.0,
        ..StereoConfig::default()
    };
    let mut vos = [
        StereoOdometry::new(rig, StereoConfig::default()).unwrap(),
        StereoOdometry::new(rig, near).unwrap(),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut est = [Vec::new(), Vec::new()];
    let mut motions = [RelativeMotion::identity(); 2];
    for world_from_left in &gt {
        let (l, r) = render_stereo(&scene, &rig, world_from_left);
        let (l, r) = (
            noisy(&l.image, 2.0, &mut rng),
            noisy(&r.image, 2.0, &mut rng),
        );
        for ((vo, e), motion) in vos.iter_mut().zip(&mut est).zip(&mut motions) {
            let res = vo.process(&l, &r, motion);
            *motion = res.motion.unwrap_or(*motion);
            e.push(res.world_from_cam);
        }
    }
    let first_inv = gt[0].inverse();
    let gt: Vec<Pose> = gt.iter().map(|p| first_inv * p).collect();
    let cfg = KittiMetricConfig {
        lengths_m: vec![100.0, 200.0, 300.0, 400.0],
        ..KittiMetricConfig::default()
    };
    let [far, near] = est.map(|e| score(&gt, &e, &cfg));
    eprintln!(
        "highway 200 frames: t_err / r_err with far points {:.4} / {:.4}, within 80 m {:.4} / {:.4}",
        far.t_err_percent, far.r_err_deg_per_100m, near.t_err_percent, near.r_err_deg_per_100m
    );
    assert!(
        far.r_err_deg_per_100m < near.r_err_deg_per_100m,
        "r_err {} (far points) vs {} (80 m)",
        far.r_err_deg_per_100m,
        near.r_err_deg_per_100m
    );
}

/// The highway drive of the ablation: `VISNAV_HIGHWAY_FRAMES` frames (default 1,000) of
/// `highway_trajectory` seed `VISNAV_HIGHWAY_SEED` (default 5), its scene, and the 620x188
/// KITTI-like rig.
fn highway() -> (Vec<Pose>, Scene, StereoCamera) {
    let frames = env_or("VISNAV_HIGHWAY_FRAMES", 1000);
    let seed = highway_seed();
    let gt = highway_trajectory(frames, seed);
    let scene = Scene::along_with(&gt, seed, SceneConfig::highway())
        .unwrap()
        .with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    (gt, scene, rig)
}

/// `VISNAV_HIGHWAY_SEED`, default 5: the drive, its scene and its pixel noise.
fn highway_seed() -> u64 {
    env_or("VISNAV_HIGHWAY_SEED", 5)
}

/// The environment variable `name` parsed, or `default` when it is unset or does not parse.
fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The highway ablation of docs/notes/2026-12-02-stereo-history.md:
/// 1,000 frames (`VISNAV_HIGHWAY_FRAMES`), 25–30 m/s,
/// 620x188, pixel noise σ 2 grey levels, KITTI devkit lengths 100..800 m.
#[test]
#[ignore = "long: renders 1,000 stereo pairs (run with --ignored --nocapture)"]
fn highway_ablation() {
    let (gt, scene, rig) = highway();
    let frames = gt.len();
    let r = run(gt, &scene, rig, 2.0, highway_seed());
    let cfg = KittiMetricConfig::default();
    let mut scores = Vec::new();
    for (((name, _), est), status) in variants().iter().zip(&r.est).zip(&r.status) {
        let s = score(&r.gt, est, &cfg);
        let fallbacks = status
            .iter()
            .filter(|s| matches!(s, FrameStatus::Fallback(_)))
            .count();
        eprintln!(
            "highway {frames} frames, {name}: t_err {:.4} %  r_err {:.4} deg/100m, {fallbacks} fallbacks",
            s.t_err_percent, s.r_err_deg_per_100m
        );
        scores.push(s);
    }
    let (f2f, ba) = (&scores[0], &scores[2]);
    eprintln!(
        "r_err BA / frame-to-frame: {:.3}",
        ba.r_err_deg_per_100m / f2f.r_err_deg_per_100m
    );
}

/// The highway drive of [`highway_ablation`] written as a KITTI stereo sequence (8-bit PNGs of
/// the same noisy pairs, calibration, ground truth) into `VISNAV_HIGHWAY_OUT`, so that the CLI
/// can run its variants (`visnav odometry --mode stereo DIR --config v.toml`).
#[test]
#[ignore = "writes 1,000 rendered stereo pairs to disk (about 80 s on 2 cores)"]
fn write_highway() {
    let Ok(out) = std::env::var("VISNAV_HIGHWAY_OUT") else {
        eprintln!("set VISNAV_HIGHWAY_OUT to the output directory");
        return;
    };
    let (gt, scene, rig) = highway();
    let times_s: Vec<f64> = (0..gt.len()).map(|i| i as f64 * 0.1).collect();
    let writer = visnav_io::kitti_writer::KittiSequenceWriter::create(
        std::path::Path::new(&out),
        &rig.left,
        Some(KITTI_BASELINE_M),
        &times_s,
        &gt,
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(highway_seed());
    for (i, world_from_left) in gt.iter().enumerate() {
        let (l, r) = render_stereo(&scene, &rig, world_from_left);
        let (l, r) = (
            noisy(&l.image, 2.0, &mut rng),
            noisy(&r.image, 2.0, &mut rng),
        );
        writer.write_images(i, &l, Some(&r)).unwrap();
    }
}

/// The median distance, pixels, of the tracks' observations `age` frames after their first one
/// from the true projection of the point their first pixel saw (renderer depth and poses), over
/// `frames` frames of the highway drive with `config`; only tracks starting where the depth is
/// smooth over 3x3 pixels (the `track_drift` example's measure).
fn track_drift_px(frames: usize, age: usize, config: StereoConfig) -> (f64, usize) {
    let gt = highway_trajectory(frames, 5);
    let scene = Scene::along_with(&gt, 5, SceneConfig::highway())
        .unwrap()
        .with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let mut vo = StereoOdometry::new(rig, config).unwrap();
    let mut motion = RelativeMotion::identity();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    // track id -> (first frame, the world point it started on)
    let mut start: std::collections::HashMap<u64, (usize, Option<nalgebra::Point3<f64>>)> =
        std::collections::HashMap::new();
    let mut errors = Vec::new();
    for (f, world_from_left) in gt.iter().enumerate() {
        let (l, r) = render_stereo(&scene, &rig, world_from_left);
        let (li, ri) = (
            noisy(&l.image, 2.0, &mut rng),
            noisy(&r.image, 2.0, &mut rng),
        );
        motion = vo.process(&li, &ri, &motion).motion.unwrap_or(motion);
        for (feat, id) in vo.features().iter().zip(vo.feature_ids()) {
            let (first, point) = *start.entry(*id).or_insert_with(|| {
                let (x, y) = (
                    feat.left_px.x.round() as usize,
                    feat.left_px.y.round() as usize,
                );
                let z = f64::from(l.depth_at(x, y));
                let smooth = (x.saturating_sub(1)..=x + 1).all(|xx| {
                    (y.saturating_sub(1)..=y + 1).all(|yy| {
                        xx < l.image.width()
                            && yy < l.image.height()
                            && (f64::from(l.depth_at(xx, yy)) - z).abs() < 0.01 * z
                    })
                });
                let p = (smooth && z.is_finite())
                    .then(|| world_from_left * rig.left.unproject(&feat.left_px, z));
                (f, p)
            });
            if f == first + age
                && let Some(p) = point
                && let Some(truth) = rig.left.project(&(world_from_left.inverse() * p))
            {
                errors.push((feat.left_px - truth).norm());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    (errors[errors.len() / 2], errors.len())
}

/// Warped Lucas–Kanade windows (`window.warp_tracks`, the default) drift less along a
/// persistent track than the translated ones on the highway, whose near patches grow by several
/// per cent a frame (docs/notes/2026-12-02-stereo-history.md,
/// *Warped tracking windows*: 0.68 → 0.33 px after 3
/// frames on 200 frames).
#[test]
fn warped_windows_drift_less_on_a_highway() {
    let mut translated = StereoConfig::default();
    translated.window.warp_tracks = false;
    assert!(StereoConfig::default().warps_tracks() && !translated.warps_tracks());
    let translated = track_drift_px(60, 3, translated);
    let warped = track_drift_px(60, 3, StereoConfig::default());
    eprintln!(
        "median drift after 3 frames: translated {:.3} px ({} tracks), warped {:.3} px ({} tracks)",
        translated.0, translated.1, warped.0, warped.1
    );
    assert!(translated.1 > 100 && warped.1 > 100);
    assert!(
        warped.0 < 0.75 * translated.0,
        "warped {} px against translated {} px",
        warped.0,
        translated.0
    );
}

/// `|d − d_true|`, pixels, of the stereo matches of the default front end's corners on the
/// rendered highway pairs `frames` (seed 5, pixel noise σ 2) with `matching`, sorted. The true
/// disparity is `f b` times the bilinear interpolation of the rendered inverse depth at the
/// feature's sub-pixel position (exact on a plane: its inverse depth is affine in the pixel),
/// scored where the 2x2 pixels around it see one surface (depths within 1 %).
fn disparity_errors_px(frames: &[usize], matching: &MatchConfig) -> Vec<f64> {
    let gt = highway_trajectory(frames.iter().max().unwrap() + 1, 5);
    let scene = Scene::along_with(&gt, 5, SceneConfig::highway())
        .unwrap()
        .with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M).unwrap();
    let config = StereoConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut errors = Vec::new();
    for &f in frames {
        let (l, r) = render_stereo(&scene, &rig, &gt[f]);
        let (li, ri) = (
            noisy(&l.image, 2.0, &mut rng),
            noisy(&r.image, 2.0, &mut rng),
        );
        let pl = Pyramid::build(&li, config.klt.levels);
        let pr = Pyramid::build(&ri, config.klt.levels);
        for c in detect_corners(&li, &config.corners) {
            let Some(m) = match_feature(&rig, &pl, &pr, c.px, matching, &config.klt) else {
                continue;
            };
            let (x0, y0) = (m.left_px.x.floor() as usize, m.left_px.y.floor() as usize);
            if x0 + 1 >= li.width() || y0 + 1 >= li.height() {
                continue;
            }
            let z = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .map(|(dx, dy)| f64::from(l.depth_at(x0 + dx, y0 + dy)));
            if z.iter()
                .any(|v| !v.is_finite() || (v - z[0]).abs() > 0.01 * z[0])
            {
                continue;
            }
            let (fx, fy) = (m.left_px.x - x0 as f64, m.left_px.y - y0 as f64);
            let inverse_depth = (1.0 - fx) * (1.0 - fy) / z[0]
                + fx * (1.0 - fy) / z[1]
                + (1.0 - fx) * fy / z[2]
                + fx * fy / z[3];
            let d_true = rig.left.fx * rig.baseline_m * inverse_depth;
            errors.push((m.disparity_px - d_true).abs());
        }
    }
    errors.sort_by(f64::total_cmp);
    errors
}

/// The window front end's disparities refined along the row (`window.refine_on_row`, default)
/// are closer to the truth than the SAD parabola's, in the median and the 90th percentile
/// (docs/notes/2026-12-02-stereo-history.md, *Disparities refined along the row*).
#[test]
fn row_refined_disparities_are_closer_to_the_truth() {
    let frames = [0, 40, 80, 120, 160, 200];
    let sad = MatchConfig::default();
    let on_row = StereoConfig::default().front_end_matching();
    assert!(on_row.refine_on_row && !sad.refine_on_row);
    let e_sad = disparity_errors_px(&frames, &sad);
    let e_row = disparity_errors_px(&frames, &on_row);
    let q = |e: &[f64], p: f64| e[((e.len() - 1) as f64 * p) as usize];
    eprintln!(
        "|d - d_true| median / p90: SAD parabola {:.4} / {:.4} px ({} matches), refined along \
         the row {:.4} / {:.4} px ({})",
        q(&e_sad, 0.5),
        q(&e_sad, 0.9),
        e_sad.len(),
        q(&e_row, 0.5),
        q(&e_row, 0.9),
        e_row.len()
    );
    assert!(e_row.len() > e_sad.len() * 9 / 10, "refused too many");
    assert!(q(&e_row, 0.5) < 0.9 * q(&e_sad, 0.5));
    assert!(q(&e_row, 0.9) < q(&e_sad, 0.9));
}
