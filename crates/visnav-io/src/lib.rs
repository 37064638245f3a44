//! Reading and writing what visnav consumes and produces.
//!
//! * [`image_io`]: grayscale PNG (8 or 16 bit) and JPEG, gray or colour, into
//!   [`visnav_core::GrayImage`] (a truncated file is an error, not a grey frame);
//!   [`frame_order`]: the order of the frames of an image folder (by the number in the names).
//! * [`kitti`]: KITTI odometry (`sequences/XX`) and KITTI raw (`..._drive_NNNN_sync`) layouts,
//!   opened as one [`Sequence`] with lazily loaded frames.
//! * [`layouts`]: EuRoC (ASL), TUM RGB-D and plain image folders, [`tum_mono`]: the TUM monoVO
//!   benchmark (DSO's `camera.txt`), [`video`]: video files through ffmpeg; with [`calibration`] (camera files, EuRoC `sensor.yaml`) they are undistorted or
//!   rectified on load and opened as the same [`Sequence`]. [`orb_slam`]: ORB-SLAM2/3 and
//!   OpenCV settings files read as camera files; [`baseline`]: the warning for a stereo
//!   baseline no rig has (a translation in millimetres).
//! * [`live`]: cameras and network streams (RTSP, UDP, SRT, V4L2, standard input) through
//!   ffmpeg on a reader thread: no frame count, a frame policy, reconnections.
//! * [`trajectory`]: trajectories in KITTI (3x4 row-major camera-to-world) and TUM formats.
//! * [`flo`], [`pfm`]: Middlebury `.flo` optical flow and PFM float images.
//! * [`g2o`]: the g2o pose-graph text format (a typed description; `visnav-graph` solves it).
//! * [`kitti_writer`]: writing a sequence in the KITTI odometry layout (images, `calib.txt`,
//!   `times.txt`, ground-truth poses; the synthetic drives are written with it).
//!
//! * [`source`]: the [`FrameSource`] trait every input implements, with prefetching and the
//!   palindrome order as wrappers; [`atomic`]: outputs written atomically and a per-frame pose
//!   journal that survives a killed run.
//!
//! Every error names the file and, for text formats, the line.

pub mod atomic;
pub mod bag;
pub mod baseline;
pub mod calibration;
pub mod error;
pub mod flo;
pub mod flow_benchmarks;
pub mod frame_order;
pub mod g2o;
pub mod image_io;
pub mod kitti;
pub mod kitti_flow;
pub mod kitti_writer;
pub mod layouts;
mod lines;
pub mod live;
pub mod orb_slam;
pub mod pfm;
pub mod sequence;
pub mod source;
pub mod text;
pub mod tracks;
pub mod trajectory;
pub mod tum_mono;
pub mod video;
pub mod yaml;

pub use bag::open_input;
pub use error::IoError;
pub use sequence::{Sequence, SequenceInfo, SequenceLayout};
pub use source::{Frame, FrameSource, InMemorySource, Palindrome, Prefetch, SourceItem, Take};
