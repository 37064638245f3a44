//! Helpers shared by the integration tests on real sequences.

use visnav_core::Pose;
use visnav_io::Sequence;
use visnav_io::trajectory::read_kitti;

/// The shared KITTI 00 clip and its full ground truth (`world_from_cam` per frame); `None`
/// without the data (a failure instead where `VISNAV_REQUIRE_DATA` is set).
pub fn kitti_00() -> Option<(Sequence, Vec<Pose>)> {
    let root = visnav_core::testdata::shared_data("kitti/odometry/sequences/00")?;
    let poses = visnav_core::testdata::shared_data("kitti/odometry/poses/00.txt")?;
    Some((Sequence::open(&root).unwrap(), read_kitti(&poses).unwrap()))
}

/// One estimated step (`prev_from_cur`) against the ground truth's.
#[derive(Debug, Clone, Copy)]
pub struct StepError {
    /// Angle of the rotation between the two steps' rotations, degrees.
    pub rotation_deg: f64,
    /// Angle between the two steps' translation directions, degrees.
    pub direction_deg: f64,
    /// Estimated step length over the true one.
    pub length_ratio: f64,
}

impl StepError {
    /// The error of `est_prev_from_cur` against the step from `gt_prev` to `gt_cur`
    /// (`world_from_cam` poses of the ground truth).
    pub fn of(gt_prev: &Pose, gt_cur: &Pose, est_prev_from_cur: &Pose) -> Self {
        let gt_step = gt_prev.inverse() * gt_cur;
        let (t_est, t_gt) = (
            est_prev_from_cur.translation.vector,
            gt_step.translation.vector,
        );
        Self {
            rotation_deg: (gt_step.rotation.inverse() * est_prev_from_cur.rotation)
                .angle()
                .to_degrees(),
            direction_deg: t_est
                .normalize()
                .dot(&t_gt.normalize())
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees(),
            length_ratio: t_est.norm() / t_gt.norm(),
        }
    }
}

impl std::fmt::Display for StepError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "rotation error {:.3} deg, direction error {:.2} deg, length ratio {:.3}",
            self.rotation_deg, self.direction_deg, self.length_ratio
        )
    }
}
