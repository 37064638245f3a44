//! The paper's aerial mode on rendered UAV flights (issue 26): a downward-looking and a
//! forward-looking camera over the synthetic city, fed by the renderer's ground-truth flow.
#![allow(clippy::unwrap_used)]

mod common;
use common::dense_flow_from_gt;

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_odometry::mono::{
    DepthPoints, FrameStatus, HomographySelection, KnownDistance, MonoConfig, MonoOdometry,
};
use visnav_synth::{
    FlightConfig, FlightView, Scene, Terrain, View, flight_trajectory, flow_between,
    kitti_like_camera, render_view,
};

struct Flown {
    gt: Vec<Pose>,
    est: Vec<Pose>,
    statuses: Vec<FrameStatus>,
    /// The model selection's GRIC gain per frame (when the homography was fitted).
    gains: Vec<Option<f64>>,
}

fn fly(flight: &FlightConfig, frames: usize, width: u32, height: u32) -> Flown {
    let mut cfg = MonoConfig::default();
    cfg.scale.camera_height_m = flight.height_m;
    fly_with(flight, frames, width, height, cfg)
}

fn fly_with(
    flight: &FlightConfig,
    frames: usize,
    width: u32,
    height: u32,
    cfg: MonoConfig,
) -> Flown {
    let (gt, cam, inputs) = rendered_flight(flight, frames, width, height);
    run_aerial(cam, cfg, gt, inputs)
}

/// A flight's true poses, its camera and its frames, rendered as they are drawn: each image
/// with the renderer's exact flow from the previous one (none for the first).
fn rendered_flight(
    flight: &FlightConfig,
    frames: usize,
    width: u32,
    height: u32,
) -> (
    Vec<Pose>,
    PinholeCamera,
    impl Iterator<Item = (GrayImage, Option<DenseFlow>)>,
) {
    let gt = flight_trajectory(frames, flight).unwrap();
    let scene = Scene::along_with(&gt, 5, flight.scene())
        .unwrap()
        .with_supersampling(1);
    let cam = kitti_like_camera(width, height);
    let mut prev: Option<(Pose, View)> = None;
    let inputs = gt.clone().into_iter().map(move |pose| {
        let view = render_view(&scene, &cam, &pose);
        let flow = prev
            .as_ref()
            .map(|(p, v)| dense_flow_from_gt(&flow_between(&scene, &cam, p, v, &pose, &view)));
        let image = view.image.clone();
        prev = Some((pose, view));
        (image, flow)
    });
    (gt, cam, inputs)
}

/// The monocular odometry in aerial mode with `cfg` over a flight's frames.
fn run_aerial(
    cam: PinholeCamera,
    mut cfg: MonoConfig,
    gt: Vec<Pose>,
    inputs: impl IntoIterator<Item = (GrayImage, Option<DenseFlow>)>,
) -> Flown {
    cfg.scale.aerial = true;
    let mut vo = MonoOdometry::new(cam, cfg).unwrap();
    // the constant-velocity prior, kept by the driver
    let mut prior = None;
    let mut f = Flown {
        gt,
        est: Vec::new(),
        statuses: Vec::new(),
        gains: Vec::new(),
    };
    for (image, flow) in inputs {
        let r = vo.process(&image, flow.as_ref(), prior.as_ref()).unwrap();
        prior = r.motion.or(prior);
        f.est.push(r.world_from_cam);
        f.statuses.push(r.status);
        f.gains.push(r.homography_gric_gain);
    }
    f
}

/// The flight's figures: Sim(3)-aligned ATE over the path length, the alignment's scale (1 =
/// metric scale right), frames that failed.
struct Scores {
    ate_fraction: f64,
    scale: f64,
    failed: usize,
}

fn score(name: &str, f: &Flown) -> Scores {
    let gt = visnav_eval::pose_matrices(&f.gt);
    let est = visnav_eval::pose_matrices(&f.est);
    let path = visnav_eval::path_length_m(&f.gt);
    let Some(ate) = visnav_eval::align::ate(&gt, &est, true) else {
        eprintln!("{name}: the estimate does not move");
        return Scores {
            ate_fraction: f64::INFINITY,
            scale: f64::NAN,
            failed: f.statuses.len(),
        };
    };
    let failed = f
        .statuses
        .iter()
        .filter(|s| matches!(s, FrameStatus::Failed))
        .count();
    let low = f
        .statuses
        .iter()
        .filter(|s| matches!(s, FrameStatus::LowParallax))
        .count();
    eprintln!(
        "{name}: path {path:.1} m, Sim(3) ATE {:.3} m ({:.3} % of the path), scale {:.4}, {failed} failed and {low} low-parallax (PnP) frames",
        ate.rmse_m,
        100.0 * ate.rmse_m / path,
        ate.alignment.scale,
    );
    Scores {
        ate_fraction: ate.rmse_m / path,
        scale: ate.alignment.scale,
        failed,
    }
}

/// Flies each `(height_m, speed_mps, climb_m)` with `view` and checks the metric scale and the
/// trajectory: no failed frame, Sim(3) ATE within 1 % of the path, scale within 5 %.
fn check_flights(view: FlightView, cases: &[(f64, f64, f64)]) {
    for &(height_m, speed_mps, climb_m) in cases {
        let flight = FlightConfig {
            view,
            height_m,
            speed_mps,
            climb_m,
            ..FlightConfig::default()
        };
        let name = format!("{view:?} {height_m} m {speed_mps} m/s");
        let s = score(&name, &fly(&flight, 30, 320, 96));
        assert_eq!(s.failed, 0, "{name}");
        assert!(s.ate_fraction < 0.01, "{name}");
        assert!((s.scale - 1.0).abs() < 0.05, "{name}: scale {}", s.scale);
    }
}

/// Downward-looking flights at 30 m (15 m/s) and 300 m (60 m/s), 10 Hz, climbing by a tenth
/// of the height: the metric scale from the height at the first frame and the trajectory within
/// 1 % of the path. Before the aerial ground was the dominant plane and the bounds scaled with
/// the height (issue 26), the 30 m flight came out 2.96 times too long and the 300 m one never
/// moved (every step over `max_translation_m` = 5 m).
#[test]
fn downward_flights_keep_the_metric_scale() {
    check_flights(FlightView::Down, &[(30.0, 15.0, 3.0), (300.0, 60.0, 30.0)]);
}

/// Forward-looking flights (20° down) at 30 m (15 m/s) and 100 m (40 m/s) with climbs and
/// descents of half the height. Before: scale 0.54 at 30 m, no motion at 100 m.
#[test]
fn forward_flights_keep_the_metric_scale() {
    check_flights(
        FlightView::Forward,
        &[(30.0, 15.0, 15.0), (100.0, 40.0, 50.0)],
    );
}

/// The paper's tape marks: a known distance between two points of the first image sets the
/// scale, whatever the camera height says (given 10 m for a flight 30 m up: the ground alone
/// would make the path 3 times too short).
#[test]
fn a_known_distance_in_the_first_image_sets_the_scale() {
    let flight = FlightConfig {
        view: FlightView::Down,
        climb_m: 3.0,
        ..FlightConfig::default()
    };
    let (width, height) = (320, 96);
    let cam = kitti_like_camera(width, height);
    let first = flight_trajectory(1, &flight).unwrap()[0];
    let scene = Scene::along_with(&[first], 5, flight.scene()).unwrap();
    let view = render_view(&scene, &cam, &first);
    let point = |u: usize, v: usize| {
        let z = f64::from(view.depth_m[v * width as usize + u]);
        nalgebra::Vector3::new(
            (u as f64 - cam.cx) / cam.fx * z,
            (v as f64 - cam.cy) / cam.fy * z,
            z,
        )
    };
    let (a, b) = ([80.0, 48.0], [240.0, 48.0]);
    let distance_m = (point(80, 48) - point(240, 48)).norm();
    let mut cfg = MonoConfig::default();
    cfg.scale.camera_height_m = 10.0;
    cfg.scale.known_distance = Some(KnownDistance {
        a_px: a,
        b_px: b,
        distance_m,
    });
    let f = fly_with(&flight, 30, width, height, cfg.clone());
    let s = score("down 30 m, tape marks", &f);
    assert_eq!(s.failed, 0);
    assert!((s.scale - 1.0).abs() < 0.05, "scale {}", s.scale);
    // the same flight with the wrong height alone
    cfg.scale.known_distance = None;
    let wrong = score(
        "down 30 m, height given as 10 m",
        &fly_with(&flight, 30, width, height, cfg),
    );
    assert!(wrong.scale > 2.0, "scale {}", wrong.scale);
}

/// The paper's fast forward flight: 15 m/s at 10 Hz, 30 m up, climbing and descending by 30 m
/// every 25 s.
fn papers_forward_flight() -> FlightConfig {
    FlightConfig {
        view: FlightView::Forward,
        height_m: 30.0,
        speed_mps: 15.0,
        climb_m: 30.0,
        climb_period_s: 25.0,
        ..FlightConfig::default()
    }
}

/// The median of `step length estimated / true` over `frames` of a flight.
fn median_step_ratio(f: &Flown, frames: std::ops::Range<usize>) -> f64 {
    let mut r: Vec<f64> = frames
        .filter(|&i| i > 0)
        .map(|i| {
            let est = (f.est[i].translation.vector - f.est[i - 1].translation.vector).norm();
            let gt = (f.gt[i].translation.vector - f.gt[i - 1].translation.vector).norm();
            est / gt
        })
        .collect();
    r.sort_by(f64::total_cmp);
    r[r.len() / 2]
}

/// The frames with zero-mean Gaussian noise of `sigma_px` added to each component of every
/// pixel's flow (seeded: every run sees the same noise).
fn with_flow_noise(
    frames: impl Iterator<Item = (GrayImage, Option<DenseFlow>)>,
    sigma_px: f32,
) -> Vec<(GrayImage, Option<DenseFlow>)> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let noise = Normal::new(0.0f32, sigma_px).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(26);
    frames
        .map(|(image, mut flow)| {
            for uv in flow.iter_mut().flat_map(|f| f.flow.iter_mut()) {
                uv[0] += noise.sample(&mut rng);
                uv[1] += noise.sample(&mut rng);
            }
            (image, flow)
        })
        .collect()
}

/// The paper's fast forward flight (15 m/s, 10 Hz, 30 m up, climbing and descending by 30 m
/// every 25 s) for 200 frames: after the first frames the scale comes from the depth-ratio
/// chain alone, so any bias of the depth map's propagation compounds. With the map's points at
/// the cells' pixels (`DepthPoints::Cell`, the default before) the steps of the last 40 frames
/// were 0.64 of the first 40's on this flight; the sub-pixel map (aerial default) keeps the
/// scale. Both run with the depth-ratio chain alone (`aerial_ground_weight` 0), which this
/// test is about; the defaults (the tracked ground) run third: with exact flow they drift more
/// than the chain (+4.5 % against +0.3 %, 2026-11-26), with the pipeline's own flow far less
/// (docs/notes/2026-12-02-aerial-history.md, round 3).
#[test]
fn a_long_forward_flight_keeps_its_scale() {
    let flight = papers_forward_flight();
    let frames = 200;
    for (points, weight) in [
        (DepthPoints::Subpixel, 0.0),
        (DepthPoints::Cell, 0.0),
        (DepthPoints::Auto, 1.0),
    ] {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        cfg.scale.aerial_ground_weight = weight;
        cfg.depth_points = points;
        // the frame-to-frame odometry's scale chain (the window holds the scale by itself)
        cfg.window.mode = visnav_odometry::mono::WindowMode::Off;
        let f = fly_with(&flight, frames, 620, 188, cfg);
        let first = median_step_ratio(&f, 1..41);
        let last = median_step_ratio(&f, frames - 40..frames);
        let name = format!("forward flight, {points:?} depth points, ground weight {weight}");
        let s = score(&name, &f);
        eprintln!("  step ratio first 40 frames {first:.4}, last 40 {last:.4}");
        let max_drift = match points {
            DepthPoints::Subpixel => 0.03,
            DepthPoints::Auto => 0.10,
            DepthPoints::Cell => continue,
        };
        assert_eq!(s.failed, 0, "{name}");
        assert!(
            (last / first - 1.0).abs() < max_drift,
            "{name}: scale drift {:.4}",
            last / first
        );
        assert!(s.ate_fraction < 0.01, "{name}: ATE {}", s.ate_fraction);
    }
}

/// A downward flight over open, flat ground (the eight-point algorithm's degenerate case): the
/// model selection picks the homography on every frame that runs the eight-point stage, and
/// its motion keeps the trajectory within 1 % of the path. With the selection off, the first
/// step's direction comes from a fundamental matrix the plane cannot fix (8.3° off with the
/// exact flow of this flight; with the rendered images' dense flow the same flight drifted to
/// 22 % of the path, docs/notes/2026-12-02-aerial-history.md).
#[test]
fn a_flight_over_flat_ground_takes_its_motion_from_the_homography() {
    let flight = FlightConfig {
        view: FlightView::Down,
        climb_m: 3.0,
        terrain: Terrain::Open,
        ..FlightConfig::default()
    };
    let frames = 30;
    let first_step_error_deg = |f: &Flown| {
        let est = (f.est[1].inverse() * f.est[0]).translation.vector;
        let gt = (f.gt[1].inverse() * f.gt[0]).translation.vector;
        est.normalize()
            .dot(&gt.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    };
    let mut with = MonoConfig::default();
    with.scale.camera_height_m = flight.height_m;
    let mut without = with.clone();
    without.homography.selection = HomographySelection::Off;
    let f = fly_with(&flight, frames, 620, 188, with);
    let s = score("flat ground, homography", &f);
    let off = fly_with(&flight, frames, 620, 188, without);
    score("flat ground, fundamental only", &off);
    let (e_on, e_off) = (first_step_error_deg(&f), first_step_error_deg(&off));
    eprintln!("  first step direction error: {e_on:.3}° (fundamental only: {e_off:.3}°)");
    assert_eq!(s.failed, 0);
    assert!(s.ate_fraction < 0.01, "ATE {}", s.ate_fraction);
    assert!(e_on < 0.5, "first step {e_on}°");
    let gains: Vec<f64> = f.gains.iter().flatten().copied().collect();
    assert!(
        !gains.is_empty() && gains.iter().all(|g| *g > 0.0),
        "{gains:?}"
    );
}

/// The paper's case: a forward-looking camera over a forest (crowns 8–25 m high on both sides
/// of a track), 30 m up at 15 m/s with a climb: the dominant plane may be the canopy rather
/// than the ground, yet the trajectory keeps within 1 % of the path and the scale within 10 %.
#[test]
fn a_forward_flight_over_a_forest_keeps_its_path() {
    let flight = FlightConfig {
        view: FlightView::Forward,
        climb_m: 15.0,
        terrain: Terrain::Forest,
        ..FlightConfig::default()
    };
    let s = score("forest, forward", &fly(&flight, 40, 620, 188));
    assert_eq!(s.failed, 0);
    assert!(s.ate_fraction < 0.01, "ATE {}", s.ate_fraction);
    assert!((s.scale - 1.0).abs() < 0.1, "scale {}", s.scale);
}

/// The paper's forward flight (as above, 160 frames) with zero-mean noise on the flow (σ 0.3 px
/// on each component of every pixel, the renderer's exact flow otherwise): the noise makes the
/// far triangulations come out nearer than they are, so the depth-ratio chain alone shrinks
/// the scale frame after frame. The tracked ground (`scale.aerial_ground_weight`, default 1: the
/// height at the first frame, moved by every step along the ground's normal; the ground
/// re-fitted near where it is expected every frame) keeps it. Both run on the same frames.
/// Measured 2026-11-26: last 40 steps over the first 40, chain 0.878, tracked 0.982; Sim(3)
/// ATE 0.60 % and 1.31 % of the path. The noise also spoils the first scale (both start about
/// 4 times too long: the first frame's dominant plane is fitted to noisy points), which the
/// test does not judge: it compares each run with its own start.
#[test]
fn the_tracked_ground_holds_the_scale_of_a_noisy_flow() {
    let flight = papers_forward_flight();
    let frames = 160;
    let (gt, cam, rendered) = rendered_flight(&flight, frames, 620, 188);
    let inputs = with_flow_noise(rendered, 0.3);
    let run = |weight: f64| {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        cfg.scale.aerial_ground_weight = weight;
        // the frame-to-frame odometry: the window holds this flight's scale by itself
        cfg.window.mode = visnav_odometry::mono::WindowMode::Off;
        let f = run_aerial(cam, cfg, gt.clone(), inputs.iter().cloned());
        let first = median_step_ratio(&f, 1..41);
        let last = median_step_ratio(&f, frames - 40..frames);
        let s = score(&format!("noisy forward flight, ground weight {weight}"), &f);
        eprintln!("  step ratio first 40 frames {first:.4}, last 40 {last:.4}");
        (last / first, s)
    };
    let (chain_drift, _) = run(0.0);
    let (tracked_drift, tracked) = run(MonoConfig::default().scale.aerial_ground_weight);
    assert!(chain_drift < 0.95, "the chain alone kept {chain_drift:.3}");
    assert!(
        (tracked_drift - 1.0).abs() < 0.05,
        "tracked ground: scale drift {tracked_drift:.3}"
    );
    assert_eq!(tracked.failed, 0);
    assert!(tracked.ate_fraction < 0.02, "ATE {}", tracked.ate_fraction);
}

/// The window adjustment ([`visnav_odometry::mono::MonoWindowConfig`], its scale its own:
/// `WindowScale::Window`, no pull towards the ground) on the paper's forward flight, 160
/// frames, tracks over the whole image (`border_px` 0), against the frame-to-frame chain on the
/// same frames: with the renderer's exact flow
/// both keep the path; with zero-mean noise on the flow (σ 0.3 px on each component of every
/// pixel, as `the_tracked_ground_holds_the_scale_of_a_noisy_flow`) the chain's depth-ratio
/// scale shrinks while the window, whose points are seen over up to seven frames, holds it.
/// Measured 2026-11-27: exact flow ATE 0.007 % (chain) / 0.001 % (window) of the path; noisy,
/// last 40 steps over the first 40: chain 0.878, window 0.9995, ATE 0.60 % / 0.024 % (window
/// 0.9987 since it needs `min_points`, 2026-11-29).
#[test]
fn the_window_holds_the_scale_of_a_noisy_flow() {
    let flight = papers_forward_flight();
    let frames = 160;
    let (gt, cam, rendered) = rendered_flight(&flight, frames, 620, 188);
    let exact: Vec<(GrayImage, Option<DenseFlow>)> = rendered.collect();
    let noisy = with_flow_noise(exact.iter().cloned(), 0.3);
    let run = |window: bool, inputs: &[(GrayImage, Option<DenseFlow>)], name: &str| {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        // the adjustment's own robustness to the flow's noise: tracks chained through the flow
        // (the refinement would align the noise away)
        own_scale_window(&mut cfg, window, false);
        // the whole image: the renderer's flow has no border bias to keep away from
        cfg.window.border_px = 0.0;
        let f = run_aerial(cam, cfg, gt.clone(), inputs.iter().cloned());
        let drift = median_step_ratio(&f, frames - 40..frames) / median_step_ratio(&f, 1..41);
        let s = score(&format!("{name}, window {window}"), &f);
        eprintln!("  scale drift (last 40 steps over the first 40) {drift:.4}");
        assert_eq!(s.failed, 0, "{name}, window {window}");
        (drift, s.ate_fraction)
    };
    let (_, chain_exact) = run(false, &exact, "exact flow");
    let (_, window_exact) = run(true, &exact, "exact flow");
    assert!(
        chain_exact < 1e-3 && window_exact < 1e-3,
        "{chain_exact} {window_exact}"
    );
    let (chain_drift, chain_ate) = run(false, &noisy, "noisy flow");
    let (window_drift, window_ate) = run(true, &noisy, "noisy flow");
    assert!(chain_drift < 0.95, "the chain kept {chain_drift:.3}");
    assert!(
        (window_drift - 1.0).abs() < 0.02,
        "window: scale drift {window_drift:.4}"
    );
    assert!(
        window_ate < 0.5 * chain_ate,
        "window ATE {window_ate} against the chain's {chain_ate}"
    );
}

/// `cfg` with the window (when `window`) holding its own scale (`WindowScale::Window`, no
/// pull, no tracked ground); `refine` its tracks, or chain them through the flow with the
/// settings of that window before 2026-11-29 (σ 0.5 px, 7 frames).
fn own_scale_window(cfg: &mut MonoConfig, window: bool, refine: bool) {
    use visnav_odometry::mono::{WindowMode, WindowScale};
    cfg.scale.aerial_ground_weight = 0.0;
    cfg.window.mode = if window {
        WindowMode::On
    } else {
        WindowMode::Off
    };
    cfg.window.scale = WindowScale::Window;
    cfg.window.ground_pull = 0.0;
    cfg.window.refine_tracks = refine;
    if !refine {
        cfg.window.sigma_px = 0.5;
        cfg.window.window_frames = 7;
    }
}

/// The renderer's exact flow shortened as the pipeline's own flow is on the 563-frame city
/// flight (docs/notes/2026-12-02-aerial-history.md, round 6:
/// the median share of the true flow found, by
/// distance from the border and the flow's length), or with the interior's length dependence
/// alone (`interior_only`).
fn with_measured_shortfall(
    frames: impl Iterator<Item = (GrayImage, Option<DenseFlow>)>,
    interior_only: bool,
) -> Vec<(GrayImage, Option<DenseFlow>)> {
    // rows: border 0-5, 5-10, 10-25, 25-50, >= 50 px; columns: length < 3, 3-6, 6-12, >= 12 px
    const SHARE: [[f32; 4]; 5] = [
        [0.915, 0.962, 0.986, 0.908],
        [0.937, 0.956, 0.942, 0.908],
        [0.981, 0.982, 0.968, 0.951],
        [1.003, 1.005, 0.994, 0.987],
        [1.004, 1.011, 0.999, 0.984],
    ];
    frames
        .map(|(image, mut flow)| {
            if let Some(f) = flow.as_mut() {
                let (w, h) = (f.width, f.height);
                for (k, uv) in f.flow.iter_mut().enumerate() {
                    let (x, y) = (k % w, k / w);
                    let edge = x.min(w - 1 - x).min(y).min(h - 1 - y);
                    let band = if interior_only {
                        4
                    } else {
                        [5, 10, 25, 50].iter().filter(|&&b| edge >= b).count()
                    };
                    let length = uv[0].hypot(uv[1]);
                    let column = [3.0, 6.0, 12.0].iter().filter(|&&b| length >= b).count();
                    let share = SHARE[band][column];
                    uv[0] *= share;
                    uv[1] *= share;
                }
            }
            (image, flow)
        })
        .collect()
}

/// Whether the pipeline flow's measured shortfall is enough to shrink a forward flight's scale:
/// the renderer's flow, exact but for that shortfall (a deterministic function of the border
/// distance and the flow's length, no noise), through the depth-ratio chain and the window.
/// 2026-11-28: chain 0.883 (last 40 steps over the first 40), window 0.917 (40-px border) /
/// 0.751 (tracks to the border); the interior's length dependence alone: chain 0.939, window
/// 0.926 / 0.952.
/// The pipeline's own flow over the rendered 563-frame flight's first 160 frames, same
/// settings: chain 0.758, window 0.785 — the shortfall alone makes 36–45 % of that drift (in
/// log). An experiment for issue 26 (a minute in release), hence ignored.
#[test]
#[ignore = "experiment: run with --release --ignored --nocapture"]
fn the_flows_measured_shortfall_shrinks_a_forward_flights_scale() {
    let flight = papers_forward_flight();
    let frames = 160;
    let (gt, cam, rendered) = rendered_flight(&flight, frames, 620, 188);
    let exact: Vec<(GrayImage, Option<DenseFlow>)> = rendered.collect();
    let short = with_measured_shortfall(exact.iter().cloned(), false);
    let interior = with_measured_shortfall(exact.iter().cloned(), true);
    let run = |window: Option<f64>, inputs: &[(GrayImage, Option<DenseFlow>)], name: &str| {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        // tracks chained through the (shortened) flow
        own_scale_window(&mut cfg, window.is_some(), false);
        cfg.window.border_px = window.unwrap_or(0.0);
        let f = run_aerial(cam, cfg, gt.clone(), inputs.iter().cloned());
        let drift = median_step_ratio(&f, frames - 40..frames) / median_step_ratio(&f, 1..41);
        let s = score(&format!("{name}, window border {window:?} px"), &f);
        eprintln!("  scale drift (last 40 steps over the first 40) {drift:.4}");
        assert_eq!(s.failed, 0, "{name}");
        drift
    };
    let chain = run(None, &short, "measured shortfall");
    let window_40 = run(Some(40.0), &short, "measured shortfall");
    let window_0 = run(Some(0.0), &short, "measured shortfall");
    let chain_interior = run(None, &interior, "interior shortfall");
    let interior_40 = run(Some(40.0), &interior, "interior shortfall");
    let interior_0 = run(Some(0.0), &interior, "interior shortfall");
    // the exact flow keeps the scale within 0.1 % (the_window_holds_the_scale_of_a_noisy_flow)
    for (name, drift) in [
        ("chain", chain),
        ("window", window_40),
        ("interior", interior_40),
    ] {
        assert!(
            drift < 0.97,
            "{name}: the shortfall left the scale at {drift:.4}"
        );
    }
    assert!(
        window_0 < window_40,
        "{window_0} {window_40}: the border layer"
    );
    assert!(interior_0 > window_0, "{interior_0} {window_0}");
    assert!(
        chain_interior < 0.99,
        "chain, interior: {chain_interior:.4}"
    );
}

/// An image and the flow into it from the one before (none for the first).
type Frame = (GrayImage, Option<DenseFlow>);

/// A flight's `frames` rendered as `visnav synth --flight` renders them (seed 0, supersampling
/// 3, 620x188), flown in `order` (indices into them): the true poses in that order, the camera,
/// and each image with the pipeline's own dense flow from the one before it (none for the
/// first).
fn with_pipeline_flow(
    flight: &FlightConfig,
    frames: usize,
    order: &[usize],
) -> (Vec<Pose>, PinholeCamera, Vec<Frame>) {
    use visnav_odometry::mono::MonoFlow;
    let gt = flight_trajectory(frames, flight).unwrap();
    let scene = Scene::along_with(&gt, 0, flight.scene())
        .unwrap()
        .with_supersampling(3);
    let cam = kitti_like_camera(620, 188);
    let images: Vec<GrayImage> = gt
        .iter()
        .map(|p| render_view(&scene, &cam, p).image)
        .collect();
    let stage = MonoFlow::new(&MonoConfig::default().flow).unwrap();
    let inputs = order
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            let flow = (k > 0).then(|| {
                stage
                    .compute_timed(&images[order[k - 1]], &images[i])
                    .unwrap()
                    .0
            });
            (images[i].clone(), flow)
        })
        .collect();
    (order.iter().map(|&i| gt[i]).collect(), cam, inputs)
}

/// The window adjustment through the pipeline's own dense flow (not the renderer's): the
/// paper's forward flight rendered as `visnav synth --flight` renders it (seed 0, supersampling
/// 3, 620x188), 100 frames, the window's own scale (no pull towards the ground, no tracked
/// ground). Chained through the flow alone the tracks carry its magnitude's bias from frame to
/// frame and the window's steps shrink; refined by Lucas–Kanade
/// (`MonoWindowConfig::refine_tracks`, the default) they do not. Measured 2026-11-29 (the
/// 563-frame flight, docs/notes/2026-12-02-aerial-history.md, round 9):
/// the first 200 frames' 20-step medians
/// 0.988 … 0.647 of the truth chained, 0.995 … 0.988 refined.
#[test]
fn refined_tracks_hold_the_windows_scale_on_the_pipelines_flow() {
    let flight = papers_forward_flight();
    let frames = 100;
    let order: Vec<usize> = (0..frames).collect();
    let (gt, cam, inputs) = with_pipeline_flow(&flight, frames, &order);
    let run = |refine: bool| {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        own_scale_window(&mut cfg, true, refine);
        let f = run_aerial(cam, cfg, gt.clone(), inputs.iter().cloned());
        let drift = median_step_ratio(&f, frames - 30..frames) / median_step_ratio(&f, 1..31);
        let s = score(&format!("pipeline flow, refined tracks {refine}"), &f);
        eprintln!("  scale drift (last 30 steps over the first 30) {drift:.4}");
        assert_eq!(s.failed, 0, "refine {refine}");
        drift
    };
    let chained = run(false);
    let refined = run(true);
    assert!(
        (refined - 1.0).abs() < 0.03,
        "refined tracks: scale drift {refined:.4}"
    );
    assert!(
        (refined - 1.0).abs() < 0.5 * (chained - 1.0).abs(),
        "refined {refined:.4} against chained {chained:.4}"
    );
}

/// #26's flight in short: the paper's forward flight over a rendered forest (seed 0,
/// supersampling 3, 620x188, as `visnav synth --flight` renders it) flown out for `FRAMES`
/// frames and back along the same images (a palindrome, as `visnav odometry --palindrome`), each
/// frame's flow the pipeline's own. With the defaults (the window, aerial mode) the way back
/// ends near the start and at the way out's scale (#26's targets: end point within 1 % of the
/// path, scale drift within 5 %), far nearer than the frame-to-frame odometry's (`mode =
/// "off"`). Measured 2026-11-29, 150 frames out and back: end point 0.259 % of the path, scale
/// drift 1.0015; without the window 8.0 %, 1.177 (the 563-frame flight: 0.71 % and 31.2 %,
/// docs/notes/2026-12-02-aerial-history.md, round 10).
#[test]
fn a_forest_palindrome_returns_to_its_start() {
    use visnav_odometry::mono::WindowMode;
    const FRAMES: usize = 150;
    let flight = FlightConfig {
        terrain: Terrain::Forest,
        ..papers_forward_flight()
    };
    let order = visnav_io::source::palindrome_order(FRAMES);
    let (gt_palindrome, cam, inputs) = with_pipeline_flow(&flight, FRAMES, &order);
    let run = |mode: WindowMode| {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = flight.height_m;
        cfg.window.mode = mode;
        let f = run_aerial(cam, cfg, gt_palindrome.clone(), inputs.iter().cloned());
        let failed = score(&format!("forest palindrome, window {mode:?}"), &f).failed;
        let d = visnav_eval::palindrome::palindrome_drift(&f.est).unwrap();
        eprint!("{d}");
        (d.end_point_error_relative, d.scale_drift_ratio, failed)
    };
    let (end, drift, failed) = run(WindowMode::Auto);
    let (end_off, drift_off, _) = run(WindowMode::Off);
    eprintln!("  without the window: {end_off:.4}, {drift_off:.4}");
    assert_eq!(failed, 0);
    assert!(end < 0.01, "end point {end}");
    assert!((drift - 1.0).abs() < 0.05, "scale drift {drift}");
    assert!(end < 0.25 * end_off, "end point {end} against {end_off}");
}

/// The first case: a downward camera 3 km up at 4 frames a second, 40 m between
/// frames (160 m/s, climbing by 300 m), the ground's texture at a field's scale
/// (`texture_scale` 100), with the defaults and the camera height alone: the metric scale and
/// the trajectory within 1 % of the path. Before issue 26 every step was rejected by the car's
/// 5 m bound. Measured 2026-11-29 (exact flow, 40 frames 620x188): Sim(3) ATE 0.025 % of the
/// 1,594 m, scale 0.983.
#[test]
fn a_flight_three_kilometres_up_keeps_the_metric_scale() {
    let flight = FlightConfig {
        view: FlightView::Down,
        height_m: 3000.0,
        speed_mps: 160.0,
        rate_hz: 4.0,
        climb_m: 300.0,
        texture_scale: 100.0,
        ..FlightConfig::default()
    };
    let s = score("down 3 km, 40 m steps", &fly(&flight, 40, 620, 188));
    assert_eq!(s.failed, 0);
    assert!(s.ate_fraction < 0.01, "ATE {}", s.ate_fraction);
    assert!((s.scale - 1.0).abs() < 0.05, "scale {}", s.scale);
}
