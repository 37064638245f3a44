//! Measures the ground-truth quality and the render time of a generated drive: for several
//! consecutive pairs, the mean absolute difference between frame t and frame t+1 warped by the
//! ground-truth flow (valid pixels), the valid fraction, and the time per view.
//!
//! `cargo run --release -p visnav-synth --example quality -- [WIDTH HEIGHT]`
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use visnav_synth::{
    Scene, drive_trajectory, flow_between, kitti_like_camera, render_view, warp_by_flow,
};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let width: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1241);
    let height: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(376);
    // optional: intensity statistics of a real image for comparison (KITTI_IMAGE=path.png)
    if let Some(path) = std::env::var_os("KITTI_IMAGE") {
        let img = visnav_io::image_io::load_gray(std::path::Path::new(&path)).unwrap();
        let d = img.data();
        let mean = d.iter().sum::<f32>() / d.len() as f32;
        let std = (d.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / d.len() as f32).sqrt();
        println!("{}: mean {mean:.1}, std {std:.1}", path.to_string_lossy());
        return;
    }
    let poses = drive_trajectory(60, 11);
    let scene = Scene::along(&poses, 11).unwrap();
    let cam = kitti_like_camera(width, height);
    let mut render_ms = Vec::new();
    let mut flow_ms = Vec::new();
    for i in [3usize, 14, 27, 39, 55] {
        let t0 = Instant::now();
        let a = render_view(&scene, &cam, &poses[i]);
        let t1 = Instant::now();
        let b = render_view(&scene, &cam, &poses[i + 1]);
        let t2 = Instant::now();
        let gt = flow_between(&scene, &cam, &poses[i], &a, &poses[i + 1], &b);
        let t3 = Instant::now();
        render_ms.push((t1 - t0).as_secs_f64() * 1e3);
        render_ms.push((t2 - t1).as_secs_f64() * 1e3);
        flow_ms.push((t3 - t2).as_secs_f64() * 1e3);
        let warped = warp_by_flow(&b.image, &gt.flow);
        let (mut sum, mut n) = (0.0f64, 0usize);
        let w = width as usize;
        for (k, v) in warped.iter().enumerate() {
            let (x, y) = (k % w, k / w);
            if x < 2 || y < 2 || x + 2 >= w || y + 2 >= height as usize {
                continue;
            }
            if let (true, Some(v)) = (gt.valid[k], v) {
                sum += f64::from((v - a.image.get(x, y)).abs());
                n += 1;
            }
        }
        println!(
            "pair {i}->{}: warp MAE {:.3} gray levels over {n} px, valid {:.3}",
            i + 1,
            sum / n as f64,
            gt.valid_fraction()
        );
    }
    render_ms.sort_by(f64::total_cmp);
    flow_ms.sort_by(f64::total_cmp);
    println!(
        "{width}x{height}: render median {:.1} ms (min {:.1}), flow median {:.1} ms",
        render_ms[render_ms.len() / 2],
        render_ms[0],
        flow_ms[flow_ms.len() / 2]
    );
}
