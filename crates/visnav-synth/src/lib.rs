//! Synthetic scenes with exact ground truth for tests, benchmarks and the demo.
//!
//! A procedurally textured city ([`Scene`]: road with markings, kerbs and sidewalks, building
//! facades with windows, boxes, poles, sky) is ray cast in f64 by a pinhole camera
//! ([`render_view`], [`render_stereo`]), supersampled and with textures band-limited by the pixel
//! footprint. Each view carries the depth `z` of its pixel centres, from which
//! [`flow_between`] computes the exact forward optical flow and the occlusion mask. Camera
//! motion comes from [`drive_trajectory`] (turns, a stop, a rotation on the spot) or from any
//! KITTI ground-truth file, and [`Scene::along`] lays the city out along that path.
//!
//! Frames: world = the first camera frame, x right, y down, z forward, metres; the ground is a
//! plane 1.65 m below the camera path (`y = +1.65 m` for the level generated drive; fitted to the
//! path of a KITTI trajectory). Poses are `world_from_cam`. Everything is deterministic for a
//! seed.
//!
//! ```
//! use visnav_synth::{Scene, drive_trajectory, flow_between, kitti_like_camera, render_view};
//! let poses = drive_trajectory(3, 7);
//! let scene = Scene::along(&poses, 7).unwrap().with_supersampling(1);
//! let cam = kitti_like_camera(80, 24);
//! let a = render_view(&scene, &cam, &poses[0]);
//! let b = render_view(&scene, &cam, &poses[1]);
//! let gt = flow_between(&scene, &cam, &poses[0], &a, &poses[1], &b);
//! assert!(gt.valid_fraction() > 0.5);
//! ```

mod flight;
mod indoor;
mod mat;
pub mod noise;
mod render;
mod scene;
mod scene_config;
mod trajectory;
pub mod write;
pub mod write_indoor;

pub use flight::{FlightConfig, FlightView, Terrain, flight_trajectory};
pub use indoor::{IndoorCamera, IndoorFlight, IndoorFlightConfig, indoor_flight};
pub use mat::MatConfig;
pub use render::{
    FlowGt, KITTI_BASELINE_M, LensRays, UNKNOWN_FLOW, View, flow_between, kitti_like_camera,
    render_stereo, render_view, render_view_distorted, render_view_through, warp_by_flow,
};
pub use scene::{MAX_ROAD_M, Scene};
pub use scene_config::SceneConfig;
pub use trajectory::{
    DriveConfig, block_loop_trajectory, drive_trajectory, drive_trajectory_with,
    highway_trajectory, loop_trajectory,
};

/// Errors of scene construction.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SynthError {
    /// A scene was requested along an empty trajectory.
    #[error("cannot lay out a scene along an empty trajectory")]
    EmptyTrajectory,
    /// A trajectory pose has a non-finite entry.
    #[error("trajectory pose {index} has a non-finite entry")]
    NonFinitePose { index: usize },
    /// The road along the trajectory is too long to lay out (a pose far away, e.g. 1e7 m, made
    /// the scene take seconds and gigabytes, 1e308 m never finished).
    #[error(
        "the road along the trajectory would be {length_m:.3e} m long (limit {limit_m} m); pose {index} is {distance_m:.3e} m from the first"
    )]
    TrajectoryTooLong {
        length_m: f64,
        limit_m: f64,
        /// The pose farthest from the first.
        index: usize,
        distance_m: f64,
    },
    /// A configuration value is out of range.
    #[error("invalid config field '{field}': {message}")]
    InvalidConfig { field: String, message: String },
}
