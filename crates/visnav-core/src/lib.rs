//! Core types shared by every stage of visnav.
//!
//! * [`se3`]: rigid motions (`Isometry3<f64>`), the SO(3)/SE(3) exponential and logarithm maps,
//!   skew-symmetric matrices. Poses are named `a_from_b`: `world_from_cam * p_in_cam = p_in_world`.
//! * [`camera`]: the pinhole camera and the rectified stereo rig (KITTI convention).
//! * [`distortion`]: radial–tangential and equidistant lens distortion, calibrated cameras.
//! * [`rectify`]: undistortion, Bouguet stereo rectification and remap maps.
//! * [`information`]: the 2x2 information matrix of a pixel measurement (eq. 1 of paper 000).
//! * [`bilinear`]: the one clamped bilinear sampler of row-major grids (images, flow fields).
//! * [`image`]: a planar `f32` grayscale image (intensities in 0..=255) with bilinear sampling.
//! * [`simd`]: run-time AVX2 selection for hot numeric kernels ([`simd_kernel!`]).
//!
//! This crate does no I/O; readers live in `visnav-io`. The `test-support` feature (off by
//! default, enabled by the dev-dependencies of the crates whose tests need it) adds `testdata`,
//! which finds the shared real data of tests through `VISNAV_DATA`.

pub mod bilinear;
pub mod camera;
pub mod distortion;
pub mod flow;
pub mod image;
pub mod information;
pub mod progress;
pub mod rectify;
pub mod se3;
pub mod simd;
/// The shared real data of tests and benchmarks (reads `VISNAV_DATA`): test support, not the
/// library's API, compiled only with the `test-support` feature (dev-dependencies enable it).
#[cfg(any(test, feature = "test-support"))]
pub mod testdata;

pub use camera::{PinholeCamera, StereoCamera};
pub use distortion::{CalibratedCamera, Distortion};
pub use flow::FlowField;
pub use image::GrayImage;
pub use information::Information2;
pub use progress::{NoProgress, Progress};
pub use se3::Pose;
