//! The stereo matcher's disparities against KITTI 2015's ground truth (one pair in the shared
//! data, `disp_noc_0`): bias and spread of `d − d_gt` at the stereo pipeline's corners (its
//! detector, denser), for the SAD parabola, the refinement along the row (the default) and the
//! two-dimensional Lucas–Kanade refinement. A negative median is a measured disparity below the
//! truth: depths too far, a trajectory too long
//! (docs/notes/2026-12-02-stereo-history.md, *The rig's disparity offset*).
//!
//! `VISNAV_DATA=... cargo run --release -p visnav-odometry --example disparity_bias`
use std::path::PathBuf;

use visnav_core::{PinholeCamera, StereoCamera};
use visnav_image::{Pyramid, detect_corners};
use visnav_io::image_io::load_gray;
use visnav_io::kitti_flow::read_kitti_disparity_png;
use visnav_odometry::stereo::StereoConfig;
use visnav_odometry::stereo::matching::match_feature;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let data = PathBuf::from(std::env::var("VISNAV_DATA")?).join("stereo/kitti2015/training");
    let left = load_gray(&data.join("image_2/000000_10.png"))?;
    let right = load_gray(&data.join("image_3/000000_10.png"))?;
    let gt = read_kitti_disparity_png(&data.join("disp_noc_0/000000_10.png"))?;
    let cam = PinholeCamera::new(
        721.5377,
        721.5377,
        609.5593,
        172.854,
        u32::try_from(left.width())?,
        u32::try_from(left.height())?,
    )?;
    let rig = StereoCamera::new(cam, 0.54)?;
    let cfg = StereoConfig::default();
    let (pl, pr) = (Pyramid::build(&left, 4), Pyramid::build(&right, 4));
    // the pipeline's corner detector, denser (the ground truth covers a third of the pixels)
    let dense = visnav_image::CornerConfig {
        min_distance_px: 2.0,
        max_per_bucket: 100_000,
        ..cfg.corners.clone()
    };
    let corners = detect_corners(&left, &dense);
    for (name, refine_on_row, refine_lk) in [
        ("SAD parabola", false, false),
        ("SAD + row refinement", true, false),
        ("SAD + LK", false, true),
    ] {
        let m = visnav_odometry::stereo::MatchConfig {
            refine_lk,
            refine_on_row,
            ..cfg.matching.clone()
        };
        let mut err = Vec::new();
        let mut rel = Vec::new();
        for c in &corners {
            let Some(f) = match_feature(&rig, &pl, &pr, c.px, &m, &cfg.klt) else {
                continue;
            };
            let (x, y) = (c.px.x.round() as usize, c.px.y.round() as usize);
            let Some(d) = gt.get(x, y) else { continue };
            let e = f.disparity_px - f64::from(d);
            if e.abs() < 3.0 {
                err.push(e);
                rel.push(f.disparity_px / f64::from(d));
            }
        }
        report(name, &mut err, &mut rel, corners.len());
    }
    Ok(())
}

fn report(name: &str, err: &mut [f64], rel: &mut [f64], n: usize) {
    err.sort_by(f64::total_cmp);
    rel.sort_by(f64::total_cmp);
    let mean = err.iter().sum::<f64>() / err.len() as f64;
    let q = |v: &[f64], p: f64| v[((v.len() - 1) as f64 * p) as usize];
    let mad = {
        let mut a: Vec<f64> = err.iter().map(|e| (e - q(err, 0.5)).abs()).collect();
        a.sort_by(f64::total_cmp);
        q(&a, 0.5)
    };
    println!(
        "{name}: {} of {n} corners with ground truth (|e| < 3 px): mean e {mean:+.4} px, median {:+.4}, MAD {mad:.4}, median ratio {:.5}",
        err.len(),
        q(err, 0.5),
        q(rel, 0.5)
    );
}
