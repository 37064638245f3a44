//! Stereo visual odometry (RotROCC) with the streaming API, in a program of your own:
//! `cargo run --release -p visnav-pipeline --example stereo -- [SEQUENCE]`.
//! Without an argument it renders a short synthetic stereo drive; any stereo layout
//! `visnav odometry --mode stereo` reads (KITTI, EuRoC, `left/` + `right/` folders) works.

use visnav_core::{GrayImage, Pose, StereoCamera};
use visnav_io::{FrameSource, Sequence};
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::{FrameInput, Odometry};
use visnav_synth::{KITTI_BASELINE_M, Scene, drive_trajectory, kitti_like_camera, render_stereo};

type Pairs = Vec<(GrayImage, GrayImage)>;

/// The rig and the stereo pairs of the input.
pub fn input(path: Option<&String>) -> Result<(StereoCamera, Pairs), Box<dyn std::error::Error>> {
    if let Some(path) = path {
        let seq = Sequence::open(path.as_ref())?;
        let rig = seq.stereo_camera().ok_or("no stereo rig")?;
        let mut pairs = Vec::with_capacity(seq.len());
        for i in 0..seq.len() {
            let f = seq.load(i, true)?;
            pairs.push((f.left, f.right.ok_or("no right image")?));
        }
        return Ok((rig, pairs));
    }
    let truth = drive_trajectory(12, 2);
    let scene = Scene::along(&truth, 2)?.with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(640, 192), KITTI_BASELINE_M)?;
    let views = truth.iter().map(|p| render_stereo(&scene, &rig, p));
    Ok((rig, views.map(|(l, r)| (l.image, r.image)).collect()))
}

/// Runs the stereo odometry over `pairs`; returns `world_from_cam` of every frame.
pub fn run(rig: StereoCamera, pairs: Pairs) -> Vec<Pose> {
    let mut vo = Odometry::stereo(rig, StereoConfig::default()).expect("valid configuration");
    for (left, right) in pairs {
        for r in vo.process(FrameInput::stereo(left, right, None)) {
            let t = r.world_from_cam.translation.vector;
            let (status, inliers) = (r.status.name(), r.inliers());
            println!(
                "frame {}: {status:<12} t = {t:.2?} m, {inliers} inliers",
                r.position
            );
        }
    }
    vo.trajectory().to_vec()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (rig, pairs) = input(args.first())?;
    println!("{} poses", run(rig, pairs).len());
    Ok(())
}
