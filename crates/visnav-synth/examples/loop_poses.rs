//! Writes the poses of a closed drive around a block ([`visnav_synth::loop_trajectory`]) as a
//! KITTI ground-truth file, for `visnav synth --trajectory` (the stereo loop-closure benchmark of
//! docs/benchmarks.md renders 2,000 frames of it).
//!
//! `cargo run --release -p visnav-synth --example loop_poses -- OUT.txt FRAMES LENGTH_M WIDTH_M
//! CORNER_RADIUS_M STEP_M`
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_synth::loop_trajectory;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 7 {
        eprintln!("usage: loop_poses OUT.txt FRAMES LENGTH_M WIDTH_M CORNER_RADIUS_M STEP_M");
        std::process::exit(2);
    }
    let number = |i: usize| -> f64 {
        args[i].parse().unwrap_or_else(|_| {
            eprintln!("argument {i} ({}) is not a number", args[i]);
            std::process::exit(2)
        })
    };
    let frames = number(2) as usize;
    let poses = loop_trajectory(frames, number(3), number(4), number(5), number(6));
    if poses.is_empty() {
        eprintln!("no poses: check the block size (2 x radius <= width <= length) and the step");
        std::process::exit(2);
    }
    visnav_io::trajectory::write_kitti(Path::new(&args[1]), &poses).unwrap();
    let length_m: f64 = poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    println!("{} poses, {length_m:.1} m", poses.len());
}
