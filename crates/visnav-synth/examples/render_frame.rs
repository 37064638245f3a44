//! Renders one frame of a generated drive to a PNG and prints the time it took.
//!
//! `cargo run --release -p visnav-synth --example render_frame -- OUT.png [FRAME] [WIDTH HEIGHT]`
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use visnav_synth::{Scene, drive_trajectory, kitti_like_camera, render_view};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(1).map_or("frame.png", String::as_str);
    let frame: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
    let width: u32 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1241);
    let height: u32 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(376);
    let poses = drive_trajectory(frame.max(1) + 1, 0);
    let t0 = Instant::now();
    let ss: u32 = std::env::var("SS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let scene = Scene::along(&poses, 0).unwrap().with_supersampling(ss);
    let t1 = Instant::now();
    let cam = kitti_like_camera(width, height);
    let view = render_view(&scene, &cam, &poses[frame]);
    let t2 = Instant::now();
    let data = view.image.data();
    let mean = data.iter().sum::<f32>() / data.len() as f32;
    let var = data.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / data.len() as f32;
    println!(
        "scene {:.1} ms ({} objects), render {:.1} ms, mean {mean:.1}, std {:.1}",
        (t1 - t0).as_secs_f64() * 1e3,
        scene.object_count(),
        (t2 - t1).as_secs_f64() * 1e3,
        var.sqrt()
    );
    visnav_io::image_io::save_gray_png(&view.image, std::path::Path::new(out)).unwrap();
}
