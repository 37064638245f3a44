//! A trajectory as an MCAP file of `geometry_msgs/msg/PoseStamped` messages (ROS 2 CDR), which
//! Foxglove Studio and ROS 2 tools (`ros2 bag play`) show beside the input bag.
//!
//! One message a frame on [`POSE_TOPIC`], `header.stamp` = the frame's timestamp,
//! `header.frame_id` = [`WORLD_FRAME`]: the pose is `world_from_cam` of the (left) camera,
//! `world` being the camera frame of the first frame (x right, y down, z forward, metres).
//! Written whole into memory, then atomically to disk (`crate::atomic`).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use visnav_core::Pose;

use super::msgs::{POSE_STAMPED, POSE_STAMPED_DEFINITION, encode_pose_stamped};
use crate::error::{IoError, Result};

/// The topic of the poses.
pub const POSE_TOPIC: &str = "/visnav/pose";
/// `header.frame_id` of the poses: the first camera frame.
pub const WORLD_FRAME: &str = "visnav_world";

/// Writes `world_from_cam` poses stamped with `timestamps_s` (seconds) to `path`.
///
/// # Errors
/// Different lengths, a timestamp that is not finite, or a write error.
pub fn write_pose_mcap(path: &Path, poses: &[Pose], timestamps_s: &[f64]) -> Result<()> {
    let format = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if poses.len() != timestamps_s.len() {
        return Err(format(format!(
            "{} poses but {} timestamps",
            poses.len(),
            timestamps_s.len()
        )));
    }
    let mcap_err = |e: mcap::McapError| format(e.to_string());
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("visnav ", env!("CARGO_PKG_VERSION")))
        .create(Cursor::new(Vec::new()))
        .map_err(mcap_err)?;
    let schema = w
        .add_schema(POSE_STAMPED, "ros2msg", POSE_STAMPED_DEFINITION.as_bytes())
        .map_err(mcap_err)?;
    let channel = w
        .add_channel(schema, POSE_TOPIC, "cdr", &BTreeMap::new())
        .map_err(mcap_err)?;
    for (i, (pose, &t)) in poses.iter().zip(timestamps_s).enumerate() {
        if !(t.is_finite() && t.abs() < 9.2e9) {
            return Err(format(format!("timestamp {t} s of frame {i}")));
        }
        let stamp_ns = (t * 1e9).round() as i64;
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: u32::try_from(i).unwrap_or(u32::MAX),
            log_time: u64::try_from(stamp_ns).unwrap_or(0),
            publish_time: u64::try_from(stamp_ns).unwrap_or(0),
        };
        w.write_to_known_channel(&header, &encode_pose_stamped(stamp_ns, WORLD_FRAME, pose))
            .map_err(mcap_err)?;
    }
    w.finish().map_err(mcap_err)?;
    crate::atomic::write_atomic(path, &w.into_inner().into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bag::{Bag, msgs};

    #[test]
    fn poses_read_back_through_the_bag_reader() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.mcap");
        let poses: Vec<Pose> = (0..5)
            .map(|i| Pose::translation(0.0, 0.0, f64::from(i) * 0.5))
            .collect();
        let t: Vec<f64> = (0..5).map(|i| 100.0 + f64::from(i) * 0.1).collect();
        write_pose_mcap(&path, &poses, &t).unwrap();
        let bag = Bag::open(&path).unwrap();
        let topics = bag.topics();
        assert_eq!(topics.len(), 1);
        assert_eq!(topics[0].topic, POSE_TOPIC);
        assert_eq!(topics[0].message_type, msgs::POSE_STAMPED);
        assert_eq!(topics[0].count, 5);
        let last = &bag.index.messages[POSE_TOPIC][4];
        let data = bag.index.read(&last.at).unwrap();
        let h = msgs::header_of(&data).unwrap();
        assert_eq!(h.stamp_ns, 100_400_000_000);
        assert_eq!(h.frame_id, WORLD_FRAME);
        assert!(write_pose_mcap(&path, &poses, &t[..4]).is_err());
    }
}
