//! Reading and writing what visnav consumes and produces.
//!
//! Inputs are layered, bottom to top; a module imports only from layers below it, and the
//! layouts, peers, not from each other:
//!
//! 1. [`sequence`]: the [`Sequence`] every layout opens as (frames read lazily, the rectified
//!    camera, timestamps); [`source`]: the [`FrameSource`] trait every input implements, with
//!    prefetching and the palindrome order as wrappers. Below them the shared pieces: [`error`],
//!    [`text`] (the one text reader), [`image_io`] (grayscale PNG, 8 or 16 bit, and JPEG into
//!    [`visnav_core::GrayImage`]; a truncated file is an error, not a grey frame),
//!    [`frame_order`], [`camera_model`] (the typed camera descriptions), [`calibration`]
//!    (camera files, EuRoC `sensor.yaml`, the `Rectifier` that undistorts or rectifies on load),
//!    [`orb_slam`] (ORB-SLAM2/3 and OpenCV settings files read as camera files), [`baseline`]
//!    (a stereo baseline no rig has; a rectified pair's constants).
//! 2. The layouts, each a peer that builds a `Sequence`: [`kitti`] (KITTI odometry
//!    `sequences/XX` and raw `..._drive_NNNN_sync`), [`layouts`] (EuRoC, TUM RGB-D, image
//!    folders), [`tum_mono`] (the TUM monoVO benchmark, DSO's `camera.txt`), `video` (video files
//!    through ffmpeg; the `video` feature), `bag` (ROS 2 bags, MCAP; the `bag` feature), and
//!    `live` (cameras and network streams through ffmpeg on a reader thread: no frame count, a
//!    frame policy, reconnections; the `video` feature).
//! 3. [`open`]: the dispatch by content ([`Sequence::open_with_camera`], [`open_input`]), the
//!    one module that knows every layout.
//!
//! Outputs and other formats: [`trajectory`] (KITTI 3x4 row-major camera-to-world, TUM, EuRoC),
//! [`atomic`] (outputs written atomically), [`journal`] (the per-frame pose journal that survives
//! a killed run), [`flo`], [`pfm`] (Middlebury `.flo` flow, PFM float images), [`g2o`] (the g2o
//! pose-graph text format, a typed description; `visnav-graph` solves it), [`kitti_writer`]
//! (writing a sequence in the KITTI odometry layout; the synthetic drives are written with it).
//!
//! A KITTI odometry folder written with [`kitti_writer`], then opened as any input is, by its
//! content ([`Sequence::open`]; `open_sequence` in Python):
//!
//! ```
//! use visnav_core::{GrayImage, PinholeCamera, Pose};
//! use visnav_io::Sequence;
//! use visnav_io::kitti_writer::KittiSequenceWriter;
//!
//! let dir = tempfile::tempdir().unwrap();
//! let camera = PinholeCamera::new(100.0, 100.0, 31.5, 23.5, 64, 48).unwrap();
//! let poses = [Pose::identity(); 3];
//! let writer =
//!     KittiSequenceWriter::create(dir.path(), &camera, None, &[0.0, 0.1, 0.2], &poses).unwrap();
//! for k in 0..3 {
//!     let image = GrayImage::from_fn(64, 48, |x, y| ((x * 4 + y + k) % 256) as f32);
//!     writer.write_images(k, &image, None).unwrap();
//! }
//! let sequence = Sequence::open(dir.path()).unwrap();
//! assert_eq!(sequence.len(), 3);
//! assert_eq!(sequence.camera.fx, 100.0);
//! assert_eq!(sequence.load_left(2).unwrap().get(5, 7), 29.0); // (5 * 4 + 7 + 2) % 256
//! ```
//!
//! Cargo features (both on by default): `bag` (the ROS 2 bag reader and the MCAP pose writer, with
//! the `mcap`, `zstd` and `lz4` crates) and `video` (video files and live streams through an
//! ffmpeg process). Without one, a bag or a video given as input is an error naming the feature;
//! `visnav-graph` uses this crate without either, for the g2o format alone.
//!
//! Every error names the file and, for text formats, the line.

pub mod atomic;
#[cfg(feature = "bag")]
pub mod bag;
pub mod baseline;
pub mod calibration;
pub mod camera_model;
pub mod error;
pub mod flo;
pub mod flow_benchmarks;
pub mod frame_order;
pub mod g2o;
pub mod image_io;
pub mod journal;
pub mod kitti;
pub mod kitti_flow;
pub mod kitti_writer;
pub mod layouts;
mod lines;
#[cfg(feature = "video")]
pub mod live;
pub mod open;
pub mod orb_slam;
pub mod pfm;
pub mod sequence;
pub mod source;
pub mod text;
pub mod tracks;
pub mod trajectory;
pub mod tum_mono;
#[cfg(feature = "video")]
pub mod video;
pub mod yaml;

pub use error::IoError;
pub use open::{is_bag, open_input};
pub use sequence::{Sequence, SequenceInfo, SequenceLayout};
pub use source::{Frame, FrameSource, InMemorySource, Palindrome, Prefetch, SourceItem, Take};
