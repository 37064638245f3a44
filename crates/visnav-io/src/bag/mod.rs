//! ROS 2 recordings: MCAP files and rosbag2 directories (`metadata.yaml` + `.mcap` files), read
//! without a ROS installation.
//!
//! * [`Bag::open`] (`recording`) indexes every message in one pass ([`mcap_file`]); [`Bag::topics`] lists
//!   the topics with their message types, counts, image encodings and time spans
//!   (`visnav info BAG`).
//! * [`open_bag_sequence`] makes a [`Sequence`](crate::Sequence) of one image topic (`sensor_msgs/msg/Image`
//!   mono8 / mono16 / rgb8 / bgr8 / rgba8 / bgra8, or `sensor_msgs/msg/CompressedImage` JPEG /
//!   PNG), optionally paired with a right image topic by header stamp. Frames are ordered by
//!   `header.stamp`, their timestamps are the stamps, and they are decoded on demand.
//! * Calibration: the `sensor_msgs/msg/CameraInfo` of the sibling `camera_info` topic (ROS's
//!   convention: `/left/camera_info` beside `/left/image_raw`), unless a camera file is given.
//!   Rectified input (no distortion, identity `R`) takes the camera from `P` and the baseline
//!   from the two `P` matrices, as KITTI's `calib.txt` does; otherwise the images are undistorted
//!   or rectified on load from `K`, `D`, `R` and `P` (`plumb_bob` / `rational_polynomial` →
//!   radial–tangential, `equidistant` → equidistant).
//! * A left frame without a right partner within the pairing tolerance keeps its place: loading
//!   its right image is a per-frame error, which the odometry skips with a pose.
//!
//! rosbag2's SQLite storage (`.db3`) is not read: the error says how to convert it to MCAP.

pub mod cdr;
pub mod mcap_file;
pub mod msgs;
pub mod odometry_msg;
mod recording;
mod sequence;
pub mod writer;

pub use mcap_file::{ChannelInfo, McapIndex, MessageRef};
pub use recording::{Bag, MessageMeta, TopicSummary, is_image_type};
pub use sequence::{BagFrames, BagOptions, open_bag_sequence};
