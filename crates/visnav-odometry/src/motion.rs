//! The relative motion between two consecutive frames: [`RelativeMotion`].

use visnav_core::Pose;

/// The rigid motion from a previous camera to the current one, metres.
///
/// The convention of the crate's interfaces (and of `visnav-pipeline`) is `prev_from_cur`: the
/// pose of the current camera in the previous camera's frame, `x_prev = prev_from_cur · x_cur`.
/// The estimators compute — and project previous points into the current image with — its
/// inverse, `cur_from_prev`. A [`Pose`] is a bare isometry, so a flipped direction would compile
/// silently: a `RelativeMotion` names the direction at every construction and every use, and
/// keeps both directions as they were first computed (an isometry inverted twice is not always
/// bit-identical to itself, and the outputs must not change with the way a motion is handed
/// around).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeMotion {
    prev_from_cur: Pose,
    cur_from_prev: Pose,
}

impl RelativeMotion {
    /// The motion whose `prev_from_cur` is the given pose.
    #[must_use]
    pub fn from_prev_from_cur(prev_from_cur: Pose) -> Self {
        Self {
            prev_from_cur,
            cur_from_prev: prev_from_cur.inverse(),
        }
    }

    /// The motion whose `cur_from_prev` (maps points of the previous camera into the current
    /// one) is the given pose.
    #[must_use]
    pub fn from_cur_from_prev(cur_from_prev: Pose) -> Self {
        Self {
            prev_from_cur: cur_from_prev.inverse(),
            cur_from_prev,
        }
    }

    /// No motion: `cur_from_prev` is the identity (and `prev_from_cur` its inverse).
    #[must_use]
    pub fn identity() -> Self {
        Self::from_cur_from_prev(Pose::identity())
    }

    /// The pose of the current camera in the previous camera's frame (the convention).
    #[must_use]
    pub fn prev_from_cur(&self) -> Pose {
        self.prev_from_cur
    }

    /// The inverse: maps points of the previous camera into the current one (for projecting
    /// them and for the epipolar geometry).
    #[must_use]
    pub fn cur_from_prev(&self) -> Pose {
        self.cur_from_prev
    }

    /// The length of the translation, metres: `cur_from_prev`'s, as the estimators measure it
    /// (mathematically the same in both directions).
    #[must_use]
    pub fn length_m(&self) -> f64 {
        self.cur_from_prev.translation.vector.norm()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn both_directions_are_inverse() {
        let p = Pose::from_parts(
            Translation3::new(0.3, -0.1, 1.2),
            UnitQuaternion::from_euler_angles(0.01, -0.2, 0.05),
        );
        let m = RelativeMotion::from_prev_from_cur(p);
        assert_eq!(m.prev_from_cur(), p);
        assert!((m.cur_from_prev() * p).translation.vector.norm() < 1e-12);
        let n = RelativeMotion::from_cur_from_prev(p);
        assert_eq!(n.cur_from_prev(), p);
        assert_eq!(n.prev_from_cur(), p.inverse());
        assert!((m.length_m() - p.translation.vector.norm()).abs() < 1e-12);
        assert_eq!(RelativeMotion::identity().cur_from_prev(), Pose::identity());
    }
}
