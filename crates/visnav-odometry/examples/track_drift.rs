//! How far the stereo odometry's persistent tracks drift from the point they started on, on the
//! rendered highway drive (exact depth and poses): each track's first left observation is lifted
//! to 3-D with the renderer's depth and the true pose, and every later observation of the track is
//! compared with that point's true projection. Prints, for one-frame-old tracks, the error by
//! image motion, the signed error by the kind of depth edge at the point and by depth; then the
//! median and 90th percentile of the error (pixels) by the track's age. `DRIFT_R` (default 1):
//! only tracks whose first pixel's `(2r+1)²` neighbourhood has one depth within 1 % are followed.
//! `VISNAV_STEREO_JSON` sets the odometry (e.g. `'{"window":{"warp_tracks":false}}'`).
//!
//! ```sh
//! cargo run --release -p visnav-odometry --example track_drift -- [FRAMES] [SEED] [NOISE_SIGMA]
//! ```

use std::collections::HashMap;

use nalgebra::{Point2, Point3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use visnav_core::{GrayImage, Pose, StereoCamera};
use visnav_odometry::RelativeMotion;
use visnav_odometry::stereo::{StereoConfig, StereoOdometry};
use visnav_synth::{
    KITTI_BASELINE_M, Scene, SceneConfig, highway_trajectory, kitti_like_camera, render_stereo,
};

/// Gaussian pixel noise of `sigma` grey levels.
fn noisy(image: &GrayImage, sigma: f32, rng: &mut ChaCha8Rng) -> GrayImage {
    let mut out = image.clone();
    if sigma > 0.0 {
        let noise = Normal::new(0.0f32, sigma).expect("finite sigma");
        for v in out.data_mut() {
            *v = (*v + noise.sample(rng)).clamp(0.0, 255.0);
        }
    }
    out
}

/// The depth at the pixel nearest `px` when its `(2r+1)²` neighbourhood agrees within 1 % (no
/// edge).
fn depth_at(view: &visnav_synth::View, px: &Point2<f64>, r: isize) -> Option<f64> {
    let (w, h) = (view.image.width(), view.image.height());
    let (x, y) = (px.x.round() as isize, px.y.round() as isize);
    if x < r || y < r || x + r >= w as isize || y + r >= h as isize {
        return None;
    }
    let z = f64::from(view.depth_at(x as usize, y as usize));
    for dy in -r..=r {
        for dx in -r..=r {
            let n = f64::from(view.depth_at((x + dx) as usize, (y + dy) as usize));
            if !n.is_finite() || (n - z).abs() > 0.01 * z {
                return None;
            }
        }
    }
    Some(z)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().map_or(Ok(300), |s| s.parse())?;
    let seed: u64 = args.next().map_or(Ok(5), |s| s.parse())?;
    let sigma: f32 = args.next().map_or(Ok(2.0), |s| s.parse())?;
    let gt = highway_trajectory(frames, seed);
    let scene = Scene::along_with(&gt, seed, SceneConfig::highway())?.with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(620, 188), KITTI_BASELINE_M)?;
    let config: StereoConfig = std::env::var("VISNAV_STEREO_JSON").map_or_else(
        |_| Ok(StereoConfig::default()),
        |j| serde_json::from_str(&j),
    )?;
    let mut vo = StereoOdometry::new(rig, config)?;
    let mut motion = RelativeMotion::identity();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // id -> (world point, its first observation's pixel, frame)
    let mut origin: HashMap<u64, Option<Point3<f64>>> = HashMap::new();
    let mut first_frame: HashMap<u64, usize> = HashMap::new();
    let ages = [1usize, 2, 3, 5, 8, 12, 16, 24, 32];
    let mut err: Vec<Vec<f64>> = vec![Vec::new(); ages.len()];
    let mut along: Vec<Vec<f64>> = vec![Vec::new(); ages.len()];
    let mut prev_obs: HashMap<u64, Point2<f64>> = HashMap::new();
    let mut right_err = Vec::new();
    let mut by_motion: Vec<Vec<f64>> = vec![Vec::new(); 5];
    let mut signed: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); 4];
    let mut kinds: HashMap<u64, usize> = HashMap::new();
    let mut by_depth: Vec<Vec<f64>> = vec![Vec::new(); 4];
    for (f, world_from_left) in gt.iter().enumerate() {
        let (l, r) = render_stereo(&scene, &rig, world_from_left);
        let (li, ri) = (
            noisy(&l.image, sigma, &mut rng),
            noisy(&r.image, sigma, &mut rng),
        );
        // (the driver keeps the constant-velocity model)
        motion = vo.process(&li, &ri, &motion).motion.unwrap_or(motion);
        let cam_from_world: Pose = world_from_left.inverse();
        let mut obs_now = HashMap::new();
        for (feat, &id) in vo.features().iter().zip(vo.feature_ids()) {
            obs_now.insert(id, feat.left_px);
            let start = *first_frame.entry(id).or_insert(f);
            if start == f {
                let r = std::env::var("DRIFT_R").map_or(1, |v| v.parse().unwrap_or(1));
                let p = depth_at(&l, &feat.left_px, r)
                    .map(|z| world_from_left * rig.left.unproject(&feat.left_px, z));
                if let Some(z) = depth_at(&l, &feat.left_px, 0) {
                    let off = |dy: f64| {
                        depth_at(&l, &Point2::new(feat.left_px.x, feat.left_px.y + dy), 0)
                            .unwrap_or(f64::INFINITY)
                    };
                    let kind = if off(-4.0) > 1.3 * z {
                        0
                    } else if off(4.0) > 1.3 * z {
                        1
                    } else if depth_at(&l, &feat.left_px, 4).is_some() {
                        2
                    } else {
                        3
                    };
                    kinds.insert(id, kind);
                }
                if let Some(rp) = p.and_then(|pw| rig.project_right(&(cam_from_world * pw))) {
                    right_err.push((feat.right_px - rp).norm());
                }
                origin.insert(id, p);
                continue;
            }
            let Some(Some(p_world)) = origin.get(&id) else {
                continue;
            };
            let age = f - start;
            let Some(slot) = ages.iter().position(|&a| a == age) else {
                continue;
            };
            let Some(truth) = rig.left.project(&(cam_from_world * p_world)) else {
                continue;
            };
            let e = feat.left_px - truth;
            if age == 1
                && let Some(prev) = prev_obs.get(&id)
            {
                let m = (truth - prev).norm();
                let b = [2.0, 5.0, 10.0, 20.0].iter().filter(|&&t| m >= t).count();
                by_motion[b].push(e.norm());
                if let Some(Some(pw)) = origin.get(&id) {
                    let z = (gt[f - 1].inverse() * pw).z;
                    let b = [15.0, 40.0, 100.0].iter().filter(|&&t| z >= t).count();
                    by_depth[b].push(e.y);
                }
                if let Some(&k) = kinds.get(&id) {
                    signed[k].0.push(e.x);
                    signed[k].1.push(e.y);
                }
            }
            err[slot].push(e.norm());
            if let Some(prev) = prev_obs.get(&id) {
                let motion = feat.left_px - prev;
                if motion.norm() > 0.5 {
                    along[slot].push(e.dot(&motion) / motion.norm());
                }
            }
        }
        prev_obs = obs_now;
    }
    println!(
        "new features: right pixel against the truth, median {:.3} px ({} features)",
        percentile(&mut right_err, 0.5),
        right_err.len()
    );
    for (b, v) in by_motion.iter_mut().enumerate() {
        let n = v.len();
        println!(
            "age 1, image motion bucket {b} (<2, 2-5, 5-10, 10-20, >=20 px): {n} tracks, median {:.3} px",
            percentile(v, 0.5)
        );
    }
    for (b, (ex, ey)) in signed.iter_mut().enumerate() {
        let n = ex.len();
        let (mx, my) = (
            ex.iter().sum::<f64>() / n as f64,
            ey.iter().sum::<f64>() / n as f64,
        );
        println!(
            "age 1, {}: {n} tracks, mean error x {mx:+.3} y {my:+.3} px, median x {:+.3} y {:+.3}",
            ["farther above", "farther below", "smooth 9x9", "other edge"][b],
            percentile(ex, 0.5),
            percentile(ey, 0.5)
        );
    }
    for (b, v) in by_depth.iter_mut().enumerate() {
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        println!(
            "age 1, depth band {b} (<15, 15-40, 40-100, >=100 m): {n} tracks, y error mean {mean:+.4} median {:+.4} px",
            percentile(v, 0.5)
        );
    }
    println!("age | tracks | median px | p90 px | median along the motion px");
    for (i, a) in ages.iter().enumerate() {
        let n = err[i].len();
        let (m, p90) = (percentile(&mut err[i], 0.5), percentile(&mut err[i], 0.9));
        let al = percentile(&mut along[i], 0.5);
        println!("{a:3} | {n:6} | {m:.3} | {p90:.3} | {al:+.3}");
    }
    Ok(())
}
