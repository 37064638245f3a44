//! Monocular visual odometry with the streaming API, in a program of your own:
//! `cargo run --release -p visnav-pipeline --example mono -- [SEQUENCE CAMERA_HEIGHT_M]`.
//! Without arguments it renders a short synthetic drive; any layout `visnav odometry` reads
//! (KITTI, EuRoC, TUM, image folders, video with `camera.yaml`) works as `SEQUENCE`.

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_io::{FrameSource, Sequence};
use visnav_pipeline::{FrameInput, MonoRunConfig, Odometry};
use visnav_synth::{Scene, drive_trajectory, kitti_like_camera, render_view};

type Input = (PinholeCamera, Vec<GrayImage>, f64);

/// The camera, the images and the camera height (metres) of the input.
pub fn input(args: &[String]) -> Result<Input, Box<dyn std::error::Error>> {
    if let [path, height] = args {
        let seq = Sequence::open(path.as_ref())?;
        let images: Result<Vec<_>, _> = (0..seq.len()).map(|i| seq.load(i, false)).collect();
        let images = images?.into_iter().map(|f| f.left).collect();
        return Ok((seq.camera, images, height.parse()?));
    }
    let truth = drive_trajectory(12, 2);
    let scene = Scene::along(&truth, 2)?.with_supersampling(2);
    let camera = kitti_like_camera(320, 96);
    let images = truth.iter().map(|p| render_view(&scene, &camera, p).image);
    Ok((camera, images.collect(), scene.config().ground_depth_m))
}

/// Runs the monocular odometry over `images`; returns `world_from_cam` of every frame.
pub fn run(camera: PinholeCamera, images: Vec<GrayImage>, height_m: f64) -> Vec<Pose> {
    let mut config = MonoRunConfig::default(); // the paper's defaults
    config.mono.scale.camera_height_m = height_m; // metric scale from the ground plane
    let mut vo = Odometry::mono(camera, &config).expect("valid configuration");
    for image in images {
        for r in vo.process(FrameInput::mono(image, None)) {
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
    let (camera, images, height_m) = input(&args)?;
    println!("{} poses", run(camera, images, height_m).len());
    Ok(())
}
