//! A trajectory as an MCAP file of `geometry_msgs/msg/PoseStamped` messages (ROS 2 CDR), which
//! Foxglove Studio and ROS 2 tools (`ros2 bag play`) show beside the input bag.
//!
//! One message a frame on [`POSE_TOPIC`], `header.stamp` = the frame's timestamp,
//! `header.frame_id` = [`WORLD_FRAME`]: the pose is `world_from_cam` of the (left) camera,
//! `world` being the camera frame of the first frame (x right, y down, z forward, metres).
//! Written whole into memory, then atomically to disk (`crate::atomic`).
//!
//! With the steps' covariances ([`write_odometry_mcap`]), a `nav_msgs/msg/Odometry` per frame
//! on [`ODOMETRY_TOPIC`] too (child frame [`CAMERA_FRAME`]; the layout and what its covariances
//! mean: [`super::odometry_msg`]).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use nalgebra::Matrix6;
use visnav_core::Pose;

use super::msgs::{Header, POSE_STAMPED, POSE_STAMPED_DEFINITION, encode_pose_stamped};
use super::odometry_msg::{ODOMETRY, ODOMETRY_DEFINITION, OdometryMessage};
use crate::error::{IoError, Result};

/// The topic of the poses.
pub const POSE_TOPIC: &str = "/visnav/pose";
/// `header.frame_id` of the poses: the first camera frame.
pub const WORLD_FRAME: &str = "visnav_world";
/// The topic of the `nav_msgs/msg/Odometry` messages.
pub const ODOMETRY_TOPIC: &str = "/visnav/odometry";
/// `child_frame_id` of the odometry messages: the (left) camera.
pub const CAMERA_FRAME: &str = "visnav_camera";

/// Writes `world_from_cam` poses stamped with `timestamps_s` (seconds) to `path`.
///
/// # Errors
/// Different lengths, a timestamp that is not finite, or a write error.
pub fn write_pose_mcap(path: &Path, poses: &[Pose], timestamps_s: &[f64]) -> Result<()> {
    write_odometry_mcap(path, poses, timestamps_s, None)
}

/// Writes `world_from_cam` poses stamped with `timestamps_s` (seconds) to `path`, and with
/// `covariances` (one per pose: the covariance of its step from the pose before, `None` for a
/// frame without one) a `nav_msgs/msg/Odometry` per frame beside each `PoseStamped`.
///
/// # Errors
/// Different lengths, a timestamp that is not finite, or a write error.
pub fn write_odometry_mcap(
    path: &Path,
    poses: &[Pose],
    timestamps_s: &[f64],
    covariances: Option<&[Option<Matrix6<f64>>]>,
) -> Result<()> {
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
    if let Some(c) = covariances
        && c.len() != poses.len()
    {
        return Err(format(format!(
            "{} poses but {} covariances",
            poses.len(),
            c.len()
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
    let odometry = match covariances {
        Some(c) => {
            let schema = w
                .add_schema(ODOMETRY, "ros2msg", ODOMETRY_DEFINITION.as_bytes())
                .map_err(mcap_err)?;
            let channel = w
                .add_channel(schema, ODOMETRY_TOPIC, "cdr", &BTreeMap::new())
                .map_err(mcap_err)?;
            Some((channel, c))
        }
        None => None,
    };
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
        if let Some((channel_id, c)) = odometry {
            let (prev_from_cur, dt_s) = match i.checked_sub(1) {
                Some(p) => (poses[p].inverse() * pose, Some(t - timestamps_s[p])),
                None => (Pose::identity(), None),
            };
            let message = OdometryMessage::new(
                Header {
                    stamp_s: t,
                    stamp_ns,
                    frame_id: WORLD_FRAME.to_string(),
                },
                CAMERA_FRAME,
                (pose, &prev_from_cur),
                c[i].as_ref(),
                dt_s,
            );
            let header = mcap::records::MessageHeader {
                channel_id,
                ..header
            };
            w.write_to_known_channel(&header, &message.encode())
                .map_err(mcap_err)?;
        }
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

    /// The odometry messages read back: pose, covariance (the unknown one for a frame without),
    /// twist from the step and the time step.
    #[test]
    fn odometry_messages_read_back_with_their_covariance() {
        use super::super::odometry_msg::UNKNOWN_VARIANCE;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("odometry.mcap");
        let poses: Vec<Pose> = (0..4)
            .map(|i| Pose::translation(0.0, 0.0, f64::from(i) * 0.5))
            .collect();
        let t: Vec<f64> = (0..4).map(|i| 10.0 + f64::from(i) * 0.1).collect();
        let cov = Matrix6::from_fn(|r, c| if r == c { 1e-4 * (r + 1) as f64 } else { 1e-6 });
        let covariances = [None, Some(cov), None, Some(cov * 2.0)];
        write_odometry_mcap(&path, &poses, &t, Some(&covariances)).unwrap();
        let bag = Bag::open(&path).unwrap();
        let topic = bag
            .topics()
            .into_iter()
            .find(|x| x.topic == ODOMETRY_TOPIC)
            .unwrap();
        assert_eq!((topic.message_type.as_str(), topic.count), (ODOMETRY, 4));
        let read = |k: usize| {
            let m = &bag.index.messages[ODOMETRY_TOPIC][k];
            OdometryMessage::decode(&bag.index.read(&m.at).unwrap()).unwrap()
        };
        let m = read(3);
        assert_eq!(m.header.frame_id, WORLD_FRAME);
        assert_eq!(m.child_frame_id, CAMERA_FRAME);
        assert_eq!(m.header.stamp_ns, 10_300_000_000);
        assert!((m.world_from_cam.translation.vector.z - 1.5).abs() < 1e-12);
        assert_eq!(m.pose_covariance[7], cov[(1, 1)] * 2.0);
        assert_eq!(m.pose_covariance[1], cov[(0, 1)] * 2.0);
        // 0.5 m in 0.1 s along z
        assert!((m.twist[2] - 5.0).abs() < 1e-9, "{:?}", m.twist);
        assert!((m.twist_covariance[0] - cov[(0, 0)] * 2.0 / 0.01).abs() < 1e-9);
        let first = read(0);
        assert_eq!(first.pose_covariance[0], UNKNOWN_VARIANCE);
        assert_eq!(first.twist_covariance[0], -1.0);
        assert_eq!(read(2).pose_covariance[35], UNKNOWN_VARIANCE);
        assert!(write_odometry_mcap(&path, &poses, &t, Some(&covariances[..3])).is_err());
    }
}
