//! `nav_msgs/msg/Odometry` (ROS 2 CDR): a pose with the covariance of its step (issue 55
//! item 5), written beside the `PoseStamped` trajectory ([`super::writer`]).
//!
//! * `header.frame_id` = the world frame, `child_frame_id` = the camera frame.
//! * `pose.pose` = `world_from_cam`; `pose.covariance` = the covariance of the frame's **step**
//!   `prev_from_cur` (row-major 6x6, x, y, z, rotation about x, y, z, metres and radians; a right
//!   perturbation `prev_from_cur · exp(ε)` in the camera frame): the pose's uncertainty given the
//!   previous frame's, what a filter fusing the odometry differentially (robot_localization's
//!   `differential: true`) reads. The absolute pose's covariance grows without bound and is
//!   not given.
//! * `twist.twist` = `log(prev_from_cur) / dt` (`ξ = (v, ω)`, in the camera frame, the child
//!   frame as ROS wants), `twist.covariance` = the step's covariance / dt²; with no time step
//!   (the first frame, equal stamps) the twist is zero and its covariance says "unknown"
//!   (`-1` first, as `sensor_msgs` does).
//! * A frame without a covariance of its own (the first, a fallback, a skipped frame: a
//!   prediction) gets [`UNKNOWN_VARIANCE`] on the diagonals: any filter then all but ignores
//!   it.

use nalgebra::{Matrix6, UnitQuaternion, Vector6};
use visnav_core::Pose;

use super::cdr::{CdrError, CdrReader, CdrWriter};
use super::msgs::{Header, read_header};

/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";

/// The variance (m², rad²) on the diagonals of a frame without a covariance of its own.
pub const UNKNOWN_VARIANCE: f64 = 1e6;

/// One `nav_msgs/msg/Odometry` message (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct OdometryMessage {
    /// Stamp and world frame.
    pub header: Header,
    /// The camera frame.
    pub child_frame_id: String,
    /// `world_from_cam`.
    pub world_from_cam: Pose,
    /// The step's covariance, row-major.
    pub pose_covariance: [f64; 36],
    /// `(v, ω)` of the step per second, camera frame.
    pub twist: [f64; 6],
    /// The twist's covariance, row-major.
    pub twist_covariance: [f64; 36],
}

fn row_major(m: &Matrix6<f64>) -> [f64; 36] {
    std::array::from_fn(|i| m[(i / 6, i % 6)])
}

impl OdometryMessage {
    /// The message of one frame: its pose and step, the step's covariance (`None`: the
    /// "unknown" covariance of the module doc) and the time since the previous frame (`None` or
    /// not positive: no twist).
    #[must_use]
    pub fn new(
        header: Header,
        child_frame_id: &str,
        (world_from_cam, prev_from_cur): (&Pose, &Pose),
        covariance: Option<&Matrix6<f64>>,
        dt_s: Option<f64>,
    ) -> Self {
        let unknown = Matrix6::identity() * UNKNOWN_VARIANCE;
        let cov = covariance.copied().unwrap_or(unknown);
        let (twist, twist_covariance) = match dt_s.filter(|dt| dt.is_finite() && *dt > 0.0) {
            Some(dt) => {
                let xi: Vector6<f64> = visnav_core::se3::se3_log(prev_from_cur) / dt;
                (
                    std::array::from_fn(|i| xi[i]),
                    row_major(&(cov / (dt * dt))),
                )
            }
            None => {
                let mut c = [0.0; 36];
                c[0] = -1.0;
                ([0.0; 6], c)
            }
        };
        Self {
            header,
            child_frame_id: child_frame_id.to_string(),
            world_from_cam: *world_from_cam,
            pose_covariance: row_major(&cov),
            twist,
            twist_covariance,
        }
    }

    /// The CDR encoding.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        let ns = self.header.stamp_ns;
        w.i32(i32::try_from(ns.div_euclid(1_000_000_000)).unwrap_or(i32::MAX));
        w.u32(u32::try_from(ns.rem_euclid(1_000_000_000)).unwrap_or(0));
        w.string(&self.header.frame_id);
        w.string(&self.child_frame_id);
        let t = self.world_from_cam.translation.vector;
        let q: UnitQuaternion<f64> = self.world_from_cam.rotation;
        for v in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
            w.f64(v);
        }
        for v in self.pose_covariance.iter().chain(&self.twist) {
            w.f64(*v);
        }
        for v in &self.twist_covariance {
            w.f64(*v);
        }
        w.finish()
    }

    /// Decodes a message.
    ///
    /// # Errors
    /// A truncated or malformed message.
    pub fn decode(data: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(data)?;
        let header = read_header(&mut r)?;
        let child_frame_id = r.string("child_frame_id")?;
        let p: [f64; 7] = r.f64_array("pose.pose")?;
        let pose_covariance = r.f64_array("pose.covariance")?;
        let twist = r.f64_array("twist.twist")?;
        let twist_covariance = r.f64_array("twist.covariance")?;
        let rotation =
            UnitQuaternion::new_normalize(nalgebra::Quaternion::new(p[6], p[3], p[4], p[5]));
        Ok(Self {
            header,
            child_frame_id,
            world_from_cam: Pose::from_parts(
                nalgebra::Translation3::new(p[0], p[1], p[2]),
                rotation,
            ),
            pose_covariance,
            twist,
            twist_covariance,
        })
    }
}

/// The ROS 2 message definition of `nav_msgs/msg/Odometry` (the schema of the output channel,
/// `ros2msg` encoding, with its dependencies as `rosbag2` writes them).
pub const ODOMETRY_DEFINITION: &str = "std_msgs/Header header\nstring child_frame_id\n\
geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n\
================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
================================================================================\n\
MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
================================================================================\n\
MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n\
================================================================================\n\
MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n\
================================================================================\n\
MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
================================================================================\n\
MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n\
================================================================================\n\
MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n\
================================================================================\n\
MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n\
================================================================================\n\
MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
