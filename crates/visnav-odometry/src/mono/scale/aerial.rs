//! The aerial scale rules (`scale.aerial`, §6.2 of the paper: a camera whose height above the
//! ground changes): the first scale from the ground plane (or a known distance), then the depth
//! ratio, combined with the ground tracked from the initialisation
//! (`scale.aerial_ground_weight`); a re-initialisation from the ground with the re-estimated
//! height where the depth maps no longer overlap; one re-anchoring on the ground over the
//! first frames; and bounds in camera heights. Everything aerial of the scale stage is here.

use nalgebra::{Point3, Vector3};
use visnav_geometry::plane::{GroundPlane, Plane, fit_plane_near};

use super::candidates::{CellPoint, ground_scale};
use crate::RelativeMotion;
use crate::mono::context::FrameContext;
use crate::mono::correspondence::median;
use crate::mono::result::ScaleSource;

/// Aerial: the ground plane as the paper's aerial mode keeps it (§6.2: the camera height
/// "updated for each motion"): its unit normal in the camera the next frame's scale refers to
/// (pointing from the camera to the ground) and that camera's height above it. The normal is
/// carried in the camera, not in the world, so that a drift of the trajectory's rotation does
/// not turn the forward motion into a climb; each frame whose ground is found replaces it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TrackedGround {
    normal_in_cam: Vector3<f64>,
    height_m: f64,
}

impl TrackedGround {
    /// After the step `motion` (metres): the camera's displacement along the normal brings it
    /// nearer the ground; the normal turns into the new camera.
    fn after_step(self, motion: &RelativeMotion) -> Self {
        let cur_in_prev = motion.prev_from_cur().translation.vector;
        Self {
            normal_in_cam: motion.cur_from_prev().rotation * self.normal_in_cam,
            height_m: self.height_m - self.normal_in_cam.dot(&cur_in_prev),
        }
    }

    /// The ground where a reconstruction at the scale `scale_m` (metres a unit of translation)
    /// expects it: a plane in the camera, unit-translation units.
    fn predicted_plane(&self, scale_m: f64) -> Plane {
        Plane {
            normal: self.normal_in_cam,
            offset: -self.height_m / scale_m,
        }
    }
}

/// The aerial rules' state (the keeper's `aerial`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct AerialScale {
    /// The first scale is set (from the ground or a known distance).
    initialised: bool,
    /// The one re-anchoring over the first frames after initialisation is done.
    anchored: bool,
    /// Camera height re-estimated from the reconstruction, metres.
    estimated_height_m: f64,
    /// The ground's normal and the camera's height above it, tracked from the initialisation
    /// (`scale.aerial_ground_weight`).
    tracked_ground: Option<TrackedGround>,
    /// The scale the last accepted frame's eight-point pose took, metres (`None` after a frame
    /// without one): the motion prior's anchor ([`Self::prior_anchor_m`]).
    anchor_m: Option<f64>,
}

/// The scale candidates the aerial rules choose from.
pub(super) struct Candidates<'a> {
    /// The fitted ground plane (unit-translation units).
    pub(super) ground: Option<&'a GroundPlane>,
    /// Scale from `scale.known_distance`, metres (first frame pair only).
    pub(super) known_m: Option<f64>,
    /// The ground-plane scale with the configured camera height, metres, if plausible.
    pub(super) s_ground: Option<f64>,
    /// The depth-ratio scale, metres, if plausible and the depth maps overlap enough
    /// (`scale.min_overlap_fraction`).
    pub(super) s_depth: Option<f64>,
    /// The unit-scale triangulation.
    pub(super) cells: &'a [CellPoint],
    /// The motion prior's gate on a candidate (`scale.max_scale_change`).
    pub(super) plausible: &'a dyn Fn(&f64) -> bool,
    /// The scale without a candidate: the PnP translation's length, else the previous one's.
    pub(super) fallback: (Option<f64>, ScaleSource),
}

impl AerialScale {
    /// Before the first frame, at the configured camera height.
    pub(super) fn new(camera_height_m: f64) -> Self {
        Self {
            initialised: false,
            anchored: false,
            estimated_height_m: camera_height_m,
            tracked_ground: None,
            anchor_m: None,
        }
    }

    /// A new map: initialise again (from the ground, with the last re-estimated height).
    pub(super) fn restart(&mut self) {
        self.initialised = false;
        self.anchored = false;
    }

    /// After the accepted step `motion` (metres; `scaled`: the frame scaled an eight-point
    /// pose, and this state is its keeper's).
    pub(super) fn after_step(&mut self, motion: &RelativeMotion, scaled: bool) {
        self.tracked_ground = self.tracked_ground.map(|t| t.after_step(motion));
        if !scaled {
            self.anchor_m = None;
        }
    }

    /// The motion prior's anchor (`scale.max_scale_change`), metres: the scale the last
    /// frame's eight-point pose took, not the length of the step (which may be PnP's); none
    /// after a frame without an eight-point pose. PnP against the depth map of a nearly
    /// fronto-parallel floor confuses a sideways translation with a rotation: on the
    /// rendered indoor flight the steps at the start of a leg after a hover came out at 0.1–0.2
    /// of their length with 0.1–0.7° of false rotation, and anchored on them the prior dropped
    /// the depth ratio of the first eight-point frames (0.6–0.8 of the true length) as a
    /// change of speed, so that the leg kept PnP's scale.
    pub(super) fn prior_anchor_m(&self) -> Option<f64> {
        self.anchor_m
    }

    /// The camera's height above the tracked ground, metres (`None` before the first ground).
    pub(super) fn tracked_height_m(&self) -> Option<f64> {
        self.tracked_ground.map(|t| t.height_m)
    }

    /// The frame's chosen scale, metres: the next frame's anchor (in `next`, the frame's copy).
    pub(super) fn chose(&mut self, scale_m: Option<f64>) {
        self.anchor_m = scale_m;
    }

    /// `vehicle_m`, at least `heights` camera heights (the height the reconstruction last saw).
    pub(super) fn bound(&self, vehicle_m: f64, heights: f64) -> f64 {
        vehicle_m.max(heights * self.estimated_height_m)
    }

    /// Whether the first ground (of the flight or of a new map) is still to be found.
    pub(super) fn initialising(&self) -> bool {
        !self.initialised
    }

    /// Whether the ground re-anchors the scale (once, after the initialisation).
    pub(super) fn reanchors(&self) -> bool {
        self.initialised && !self.anchored
    }

    /// The re-anchoring is done.
    pub(super) fn anchored(&mut self) {
        self.anchored = true;
    }

    /// The aerial rule: before the initialisation the known distance, else the ground; after it,
    /// over a level flight's takeoff (a ground normal given, the re-anchoring window), the ground
    /// at the tracked height; else the depth ratio (with the tracked ground,
    /// [`Self::with_tracked_ground`]), else a re-initialisation from the ground with the
    /// re-estimated height; else `fallback`. `self` is the state before the frame, `next` the
    /// frame's copy.
    pub(super) fn choose(
        &self,
        ctx: &FrameContext<'_>,
        next: &mut AerialScale,
        candidates: Candidates<'_>,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> (Option<f64>, ScaleSource) {
        let cfg = ctx.config.scale;
        let height_m = self.tracked_height_m().unwrap_or(next.estimated_height_m);
        let s_reinit = candidates
            .ground
            .map(|g| ground_scale(g, height_m, cfg.ground_search.dominant(true)))
            .filter(|s| s.is_finite() && *s > 0.0);
        if !next.initialised {
            match (candidates.known_m, candidates.s_ground) {
                (Some(s), _) => {
                    next.initialised = true;
                    // the ground's re-anchoring would undo the known distance
                    next.anchored = true;
                    (Some(s), ScaleSource::KnownDistance)
                }
                (None, Some(s)) => {
                    next.initialised = true;
                    (Some(s), ScaleSource::Ground)
                }
                (None, None) => candidates.fallback,
            }
        } else if let Some(s) = s_reinit.filter(|_| self.reanchors() && level_normal(ctx).is_some())
        {
            // a level flight's takeoff (the re-anchoring window): every frame's ground at the
            // tracked height, not the depth ratio, which carries the first frame's scale along
            // (a first step of 2 mm at 0.1 m scaled 5.3x on a rendered indoor flight kept the
            // whole flight 2.8x long with the real-time preset's flow; with its own ground each
            // frame the error stays the first step's share of the height: path 1.03x)
            (Some(s), ScaleSource::TrackedGround)
        } else if let Some(s) = candidates.s_depth {
            self.with_tracked_ground(ctx, s, candidates.cells, next, rng)
        } else if let Some(s) = self
            .anchor_m
            .and_then(|s| self.tracked_ground_scale(ctx, s, candidates.cells, next, rng))
        {
            (Some(s), ScaleSource::TrackedGround)
        } else if let Some(s) = s_reinit.filter(candidates.plausible) {
            (Some(s), ScaleSource::GroundReinit)
        } else {
            candidates.fallback
        }
    }

    /// The camera height `height_m` the reconstruction sees at the chosen scale above the
    /// ground of normal `normal_in_cam`: the re-estimated height, and the tracked ground's
    /// start where there is none yet.
    pub(super) fn measured_height(
        &self,
        next: &mut AerialScale,
        height_m: f64,
        normal_in_cam: Vector3<f64>,
    ) {
        if height_m.is_finite() && height_m > 0.0 {
            next.estimated_height_m = height_m;
            // the tracked ground starts where the aerial scale does
            if !self.initialised || self.tracked_ground.is_none() {
                next.tracked_ground = Some(TrackedGround {
                    normal_in_cam,
                    height_m,
                });
            }
        }
    }

    /// After the initialisation: the depth-ratio scale `s_depth`, combined with the
    /// tracked-height ground scale when that is on (`scale.aerial_ground_weight`) and the
    /// ground is found near where it is expected; the found ground's normal replaces the
    /// tracked one in `next`.
    fn with_tracked_ground(
        &self,
        ctx: &FrameContext<'_>,
        s_depth: f64,
        cells: &[CellPoint],
        next: &mut AerialScale,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> (Option<f64>, ScaleSource) {
        let w = ctx.config.scale.aerial_ground_weight;
        match self.tracked_ground_scale(ctx, s_depth, cells, next, rng) {
            Some(s_g) => (
                Some(((1.0 - w) * s_depth.ln() + w * s_g.ln()).exp()),
                ScaleSource::GroundAndDepth,
            ),
            None => (Some(s_depth), ScaleSource::DepthRatio),
        }
    }

    /// The tracked-height ground scale, metres, when that is on (`scale.aerial_ground_weight`)
    /// and the ground is found near where a reconstruction at the scale `predicted_m`
    /// expects it (the found ground's normal replaces the tracked one in `next`), or, for a
    /// level flight after the re-anchoring window, anywhere along the given normal
    /// ([`level_ground_scale`]).
    fn tracked_ground_scale(
        &self,
        ctx: &FrameContext<'_>,
        predicted_m: f64,
        cells: &[CellPoint],
        next: &mut AerialScale,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> Option<f64> {
        let cfg = ctx.config.scale;
        let tracked = self
            .tracked_ground
            .filter(|t| cfg.aerial_ground_weight > 0.0 && t.height_m > 0.0)?;
        // a level flight, after the takeoff's re-anchoring: the ground along the given normal
        if let Some(n) = level_normal(ctx).filter(|_| !self.reanchors()) {
            return level_ground_scale(ctx, tracked.height_m, &n, cells).inspect(|_| {
                next.tracked_ground = Some(TrackedGround {
                    normal_in_cam: n,
                    ..tracked
                });
            });
        }
        let predicted = tracked.predicted_plane(predicted_m);
        // the near ground: a far point's small parallax makes its depth less certain
        let max_range = cfg.aerial_ground_max_range_heights * -predicted.offset;
        let points: Vec<Point3<f64>> = cells
            .iter()
            .map(|c| c.point.p_in_cam1)
            .filter(|p| p.coords.norm() <= max_range)
            .collect();
        let ground = fit_plane_near(
            &points,
            &predicted,
            cfg.aerial_ground_max_tilt_rad,
            cfg.aerial_ground_gate,
            &cfg.ground,
            rng,
        );
        let candidate = ground
            .map(|g| (g.plane.normal, tracked.height_m / g.camera_height))
            .filter(|(_, s)| s.is_finite() && *s > 0.0)
            .map(|(found_normal_in_cam, s)| {
                next.tracked_ground = Some(TrackedGround {
                    normal_in_cam: level_normal(ctx).unwrap_or(found_normal_in_cam),
                    ..tracked
                });
                s
            });
        log::debug!(
            "mono frame {}: tracked ground height {:.3} m, scale {candidate:?} against the predicted {predicted_m:.4}",
            ctx.frame,
            tracked.height_m,
        );
        candidate
    }
}

/// The ground's normal in the camera of a level flight, when given
/// (`homography.ground_normal`): the tracked ground's, in place of a fitted plane's (a climb
/// along the optical axis triangulates the first grounds tilted by tens of degrees: 47° on the
/// rendered indoor takeoff, whose climb the tracked height then followed at 0.75 of its length).
pub(super) fn level_normal(ctx: &FrameContext<'_>) -> Option<Vector3<f64>> {
    ctx.config
        .homography
        .level_ground_normal()
        .map(nalgebra::Unit::into_inner)
}

/// A level flight's ground scale, metres a unit of translation: the tracked height `height_m`
/// over the median distance of the unit-scale triangulation `cells` along the given normal `n`
/// (points beyond `scale.aerial_ground_max_range_heights` of that distance dropped, the
/// median taken again), wherever the previous scale expects the ground: with the normal known,
/// the floor needs no plane fit, and a scale the chain has shrunk (after a turn on the spot,
/// 4x on the rendered indoor flight) is found again. Used after the re-anchoring window: over a
/// takeoff's first frames (steps of millimetres) it shortened the short CI flight's climb from
/// 0.93 to 0.88 of its length. `None` with fewer than 20 points.
fn level_ground_scale(
    ctx: &FrameContext<'_>,
    height_m: f64,
    n: &Vector3<f64>,
    cells: &[CellPoint],
) -> Option<f64> {
    const MIN_POINTS: usize = 20;
    // (range from the camera, distance along the normal) of the points below the camera
    let below: Vec<(f64, f64)> = cells
        .iter()
        .map(|c| {
            (
                c.point.p_in_cam1.coords.norm(),
                n.dot(&c.point.p_in_cam1.coords),
            )
        })
        .filter(|(_, d)| d.is_finite() && *d > 0.0)
        .collect();
    let median_of = |mut v: Vec<f64>| (v.len() >= MIN_POINTS).then(|| median(&mut v)).flatten();
    let first = median_of(below.iter().map(|(_, d)| *d).collect())?;
    let max_range = ctx.config.scale.aerial_ground_max_range_heights * first;
    let near = below
        .iter()
        .filter(|(range, _)| *range <= max_range)
        .map(|(_, d)| *d);
    let s = height_m / median_of(near.collect())?;
    log::debug!(
        "mono frame {}: level ground at {first:.4} units below, tracked height {height_m:.3} m, scale {s:.4}",
        ctx.frame
    );
    (s.is_finite() && s > 0.0).then_some(s)
}

#[cfg(test)]
mod tests {
    use nalgebra::UnitQuaternion;
    use visnav_core::Pose;

    use super::*;

    #[test]
    fn tracked_ground_follows_the_climb() {
        // a camera pitched 20° down, 30 m above flat ground (world y down); it climbs 2 m
        // while flying 5 m forward and turning 10° to the right
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -20f64.to_radians());
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 10f64.to_radians());
        let world_from_prev = Pose::from_parts(Point3::new(1.0, -30.0, 7.0).into(), pitch);
        let world_from_cur = Pose::from_parts(Point3::new(1.0, -32.0, 12.0).into(), yaw * pitch);
        let step = RelativeMotion::from_prev_from_cur(world_from_prev.inverse() * world_from_cur);
        let down_in = |world_from_cam: &Pose| world_from_cam.rotation.inverse() * Vector3::y();
        let start = TrackedGround {
            normal_in_cam: down_in(&world_from_prev),
            height_m: 30.0,
        };
        let after = start.after_step(&step);
        assert!((after.height_m - 32.0).abs() < 1e-9, "{}", after.height_m);
        assert!((after.normal_in_cam - down_in(&world_from_cur)).norm() < 1e-12);
        // the ground seen from the current camera at 4 m a unit: 8 units away; a point on the
        // ground straight below the camera lies on it
        let plane = after.predicted_plane(4.0);
        assert!((plane.offset + 8.0).abs() < 1e-12, "{}", plane.offset);
        let below = world_from_cur.inverse() * Point3::new(1.0, 0.0, 12.0);
        assert!(plane.distance(&Point3::from(below.coords / 4.0)).abs() < 1e-9);
    }
}
