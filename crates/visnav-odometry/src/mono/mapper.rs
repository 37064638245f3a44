//! The mapper (§5): what the odometry knows of the scene. It owns the depth map (fused by
//! inverse variance and propagated into the newest camera), the scale keeper ([`super::scale`]:
//! ground plane, depth ratio, the aerial rules) and the window of the last frames
//! ([`super::window`]). For a frame it scales the tracker's unit-translation motion, adjusts the
//! fused motion in the window and updates the depth map; the odometry commits the result
//! ([`MapUpdate`]) only when it accepts the frame.

use std::time::Instant;

use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use visnav_core::Pose;
use visnav_flow::DenseFlow;
use visnav_geometry::Correspondence;
use visnav_geometry::fundamental::mahalanobis_distance_sq;
use visnav_geometry::triangulation::{InverseDepthPoint, triangulate, triangulate_inverse_depth};
use visnav_image::Pyramid;

use super::context::FrameContext;
use super::correspondence::{correspondence_at, fundamental_of};
use super::depth::DepthMap;
use super::point_scale::{PointScale, scale_at_map_points};
use super::result::{PoseSource, StageTimings, ms};
use super::scale::{CellPoint, ScaleEstimate, ScaleKeeper};
use super::tracker::FusedPose;
use super::window::{MonoWindow, StepChange, WindowStep};
use crate::RelativeMotion;

/// Stage 6 (§5): the eight-point pose with its metric scale (ground plane `s = −(b·h)/d`
/// and/or median depth ratio).
pub(super) struct ScaledEightPoint {
    /// The scaled pose as the eight-point computes it, `cur_from_prev`, metres.
    pub(super) pose: Option<Pose>,
    pub(super) estimate: ScaleEstimate,
    /// `None` when no eight-point pose was scaled (the keeper is unchanged).
    pub(super) keeper: Option<ScaleKeeper>,
}

/// Stage 8 (§5): the fused depth map propagated into the current camera.
pub(super) struct DepthUpdate {
    pub(super) next: DepthMap,
    pub(super) known_cells: usize,
}

/// What an accepted frame changes in the mapper.
pub(super) struct MapUpdate {
    /// The scale keeper the frame leaves (`None`: unchanged).
    pub(super) keeper: Option<ScaleKeeper>,
    /// The window with the frame (`None`: no window).
    pub(super) window: Option<MonoWindow>,
    /// The depth map in the frame's camera.
    pub(super) depth: DepthMap,
}

/// The mapper's state.
#[derive(Debug, Clone)]
pub(super) struct Mapper {
    /// Depth map of the previous frame (propagated and fused), in the previous camera.
    prior: Option<DepthMap>,
    /// The scale stage's state.
    keeper: ScaleKeeper,
    /// The window of the last frames and their tracks (`window.mode`).
    window: Option<MonoWindow>,
}

impl Mapper {
    /// No map yet.
    pub(super) fn new(config: &super::config::MonoConfig) -> Self {
        Self {
            prior: None,
            keeper: ScaleKeeper::new(&config.scale),
            window: None,
        }
    }

    /// The depth map of the latest frame (propagated and fused), if any.
    pub(super) fn depth_map(&self) -> Option<&DepthMap> {
        self.prior.as_ref()
    }

    /// The translation bound of a frame's step, metres (see
    /// [`ScaleKeeper::max_translation_m`]).
    pub(super) fn max_translation_m(&self, ctx: &FrameContext<'_>) -> f64 {
        self.keeper.max_translation_m(ctx.config)
    }

    /// A first image, whose pose is `world_from_cam`: the depth map dropped, a new window.
    pub(super) fn start(&mut self, ctx: &FrameContext<'_>, world_from_cam: Pose) {
        self.prior = None;
        self.window = ctx
            .config
            .window
            .runs(ctx.config.scale.aerial)
            .then(|| MonoWindow::start(world_from_cam));
    }

    /// After a restart's first image: the next scale comes from the ground again.
    pub(super) fn restart_scale(&mut self) {
        self.keeper.restart();
    }

    /// Keeps what the accepted frame of motion `fused` changed.
    pub(super) fn commit(&mut self, update: MapUpdate, fused: &FusedPose) {
        if update.window.is_some() {
            self.window = update.window;
        }
        let scaled = update.keeper.is_some();
        if let Some(keeper) = update.keeper {
            self.keeper = keeper;
        }
        self.keeper.after_step(&fused.motion, scaled);
        self.prior = Some(update.depth);
    }

    /// Scale stage (§5): the unit-scale dense triangulation, then the scale
    /// ([`ScaleKeeper::choose`]); the eight-point pose scaled by it.
    pub(super) fn scaled_eight_point(
        &self,
        ctx: &FrameContext<'_>,
        (flow, unit_pose, pnp_pose): (&DenseFlow, Option<Pose>, Option<Pose>),
        rng: &mut visnav_geometry::ChaCha8Rng,
        timings: &mut StageTimings,
    ) -> ScaledEightPoint {
        let Some(unit) = unit_pose else {
            return ScaledEightPoint {
                pose: None,
                estimate: ScaleEstimate::none(),
                keeper: None,
            };
        };
        // the metric depth limit in units of this frame's translation, predicted from the
        // previous translation length (far points only add noise to the scale)
        let unit_max_depth = self.keeper.max_depth_m(ctx.config)
            / ctx.last_motion.map_or(1.0, |m| m.length_m()).max(1e-3);
        let t = Instant::now();
        let cells = triangulate_cells(ctx, flow, &unit, unit_max_depth);
        timings.triangulation_ms += ms(t);
        let t = Instant::now();
        let pnp_scale = pnp_pose.map(|p| p.translation.vector.norm());
        let at_points = self.scale_at_points(ctx, flow, &unit);
        let (estimate, keeper) = self.keeper.choose(
            ctx,
            (self.prior.as_ref(), &cells),
            pnp_scale,
            at_points,
            rng,
        );
        let pose = estimate.scale_m.map(|s| {
            let mut p = unit;
            p.translation.vector *= s;
            p
        });
        timings.scale_ms = ms(t);
        ScaledEightPoint {
            pose,
            estimate,
            keeper: Some(keeper),
        }
    }

    /// The window adjustment ([`super::window`], `window.mode`): the frame joins the window,
    /// whose adjustment gives its pose (the fused one where it cannot, or where the adjusted
    /// step breaks the translation bound). A frame without a measurement (constant velocity),
    /// or one the `auto` mode does not adjust (a downward view, or before the ground is known),
    /// starts a new window at its pose. `None` when the window is off. `world_from_prev`: the
    /// previous frame's pose.
    pub(super) fn window_step(
        &self,
        ctx: &FrameContext<'_>,
        (world_from_prev, flow, images): (Pose, &DenseFlow, Option<(&Pyramid, &Pyramid)>),
        corrs: &[Correspondence],
        fused: FusedPose,
        ground_m: Option<f64>,
    ) -> (FusedPose, Option<WindowStep>) {
        let Some(window) = self.window.as_ref() else {
            return (fused, None);
        };
        let world_from_cur = world_from_prev * fused.motion.prev_from_cur();
        // (the window exists only where `window.runs`, `start`)
        if fused.source == PoseSource::ConstantVelocity {
            return (fused, Some(WindowStep::restart(world_from_cur)));
        }
        let config = ctx.config;
        let stage_sets_length = config
            .window
            .stage_sets_length(config.homography.level_ground_normal().is_some());
        let step = window.advance(
            &config.window,
            ctx.camera,
            (flow, corrs, config.grid_cell_px),
            images,
            world_from_cur,
            // a flight's height above the ground changes: no pull towards a fixed height
            (
                stage_sets_length.then(|| fused.motion.length_m()),
                ground_m.filter(|_| !config.scale.aerial),
            ),
        );
        let adjusted = if stage_sets_length {
            // the window's last step after the reported previous pose
            step.motion.map(|m| m.cur_from_prev())
        } else {
            // the newest pose as the window has it
            step.world_from_cam().map(|w| {
                let mut cur_from_prev = w.inverse() * world_from_prev;
                // the product's quaternion is off the unit sphere by the rounding of both; the
                // pose chain would square that error every frame
                cur_from_prev.rotation =
                    UnitQuaternion::new_normalize(cur_from_prev.rotation.into_inner());
                cur_from_prev
            })
        };
        let adjusted = adjusted.filter(|p| {
            let length = p.translation.vector.norm();
            length.is_finite() && length <= self.max_translation_m(ctx)
        });
        log::debug!(
            "mono frame {}: window of {} points, {:?}",
            ctx.frame,
            step.points,
            step.report
        );
        let Some(p) = adjusted else {
            return (fused, Some(step));
        };
        let change = StepChange::between(&p, &fused.motion.cur_from_prev());
        if config.window.accepts(&change) {
            return (
                FusedPose {
                    motion: RelativeMotion::from_cur_from_prev(p),
                    ..fused
                },
                Some(step),
            );
        }
        log::warn!(
            "mono frame {}: the window's step differs from the fused one by {:.2}° of rotation (window.max_rotation_change_rad) or {:.1}° of direction (window.max_direction_change_rad); the fused step stands and the window restarts",
            ctx.frame,
            change.rotation_rad.to_degrees(),
            change.direction_rad.to_degrees(),
        );
        (fused, Some(WindowStep::restart(world_from_cur)))
    }

    /// Depth stage (§5): triangulate with the final pose, fuse with the prior by inverse
    /// variance, propagate into the current camera; without a baseline the prior is only
    /// propagated (a rotation moves it exactly).
    pub(super) fn depth_update(
        &self,
        ctx: &FrameContext<'_>,
        (flow, fused): (&DenseFlow, &FusedPose),
        has_baseline: bool,
        timings: &mut StageTimings,
    ) -> DepthUpdate {
        let cfg = ctx.config;
        let max_depth_m = self.keeper.max_depth_m(cfg);
        let t = Instant::now();
        let measured = fused.source != PoseSource::ConstantVelocity && has_baseline;
        let unfiltered = ctx.inverse_depth_filter();
        let cells = if measured && !unfiltered {
            triangulate_cells(ctx, flow, &fused.motion.cur_from_prev(), max_depth_m)
        } else {
            Vec::new()
        };
        let inverse = if measured && unfiltered {
            measure_inverse_depth(ctx, flow, &fused.motion.cur_from_prev())
        } else {
            Vec::new()
        };
        timings.triangulation_ms += ms(t);
        let t = Instant::now();
        let mut map = self
            .prior
            .clone()
            .unwrap_or_else(|| DepthMap::empty(flow.width, flow.height, cfg.depth_stride_px));
        let min_inverse_depth = 1.0 / max_depth_m;
        for &(cell, m) in &inverse {
            map.fuse_inverse_measurement(
                cell,
                (m.inverse_depth, m.variance),
                3.0,
                min_inverse_depth,
            );
        }
        for c in &cells {
            if cfg.inverse_depth_fusion {
                map.fuse_inverse_depth(c.cell, c.point.depth, c.point.depth_variance, 3.0);
            } else {
                map.fuse(c.cell, c.point.depth, c.point.depth_variance, 3.0);
            }
        }
        let next = map.propagate(
            ctx.camera,
            &fused.motion.cur_from_prev(),
            0.1,
            ctx.subpixel_depth(),
        );
        let known_cells = next.known();
        timings.depth_ms = ms(t);
        DepthUpdate { next, known_cells }
    }

    /// With `inverse_depth_filter`, the depth-ratio scale of the unit-translation pose `unit`
    /// measured at the previous map's points ([`scale_at_map_points`]); `None` otherwise (the
    /// ratio of the filtered triangulations, cell by cell).
    fn scale_at_points(
        &self,
        ctx: &FrameContext<'_>,
        flow: &DenseFlow,
        unit: &Pose,
    ) -> Option<PointScale> {
        if !ctx.inverse_depth_filter() {
            return None;
        }
        let prior = self.prior.as_ref()?;
        let guess = ctx.last_motion.map_or(1.0, |m| m.length_m()).max(1e-6);
        Some(scale_at_map_points(
            ctx.camera,
            flow,
            prior,
            unit,
            (
                &fundamental_of(ctx.camera, unit),
                ctx.config.eight_point.ransac.inlier_threshold,
            ),
            guess,
            ctx.config.scale.min_ratio_samples,
        ))
    }
}

/// The inverse depth (metres⁻¹) of every depth-grid cell whose flow is consistent with
/// `cur_from_prev` (the epipolar test only: no filter on the measured value, see
/// [`triangulate_inverse_depth`]).
fn measure_inverse_depth(
    ctx: &FrameContext<'_>,
    flow: &DenseFlow,
    cur_from_prev: &Pose,
) -> Vec<(usize, InverseDepthPoint)> {
    epipolar_cells(ctx, flow, cur_from_prev)
        .into_par_iter()
        .filter_map(|(cell, c)| {
            let m = triangulate_inverse_depth(ctx.camera, cur_from_prev, &c)?;
            (m.inverse_depth.is_finite() && m.variance.is_finite()).then_some((cell, m))
        })
        .collect()
}

/// The flow's correspondence at every depth-grid cell within the RANSAC threshold of
/// `cur_from_prev`'s epipolar geometry (squared Mahalanobis distance), in cell order.
fn epipolar_cells(
    ctx: &FrameContext<'_>,
    flow: &DenseFlow,
    cur_from_prev: &Pose,
) -> Vec<(usize, Correspondence)> {
    let grid = DepthMap::empty(flow.width, flow.height, ctx.config.depth_stride_px);
    let f = fundamental_of(ctx.camera, cur_from_prev);
    let threshold = ctx.config.eight_point.ransac.inlier_threshold;
    (0..grid.depth_m.len())
        .into_par_iter()
        .filter_map(|cell| {
            let px = grid.pixel_of(cell);
            let c = correspondence_at(flow, px.x as usize, px.y as usize)?;
            if mahalanobis_distance_sq(&f, &c) > threshold {
                None
            } else {
                Some((cell, c))
            }
        })
        .collect()
}

/// Triangulates the flow at every depth-grid cell consistent with `cur_from_prev`
/// (squared Mahalanobis epipolar distance within the RANSAC threshold, depth positive, relative
/// depth sigma below the limit). Depths are in the units of the pose's translation.
/// `max_depth` bounds the depth in the pose's units (infinite for a unit-translation pose).
fn triangulate_cells(
    ctx: &FrameContext<'_>,
    flow: &DenseFlow,
    cur_from_prev: &Pose,
    max_depth: f64,
) -> Vec<CellPoint> {
    let camera = *ctx.camera;
    let max_rel = ctx.config.max_relative_depth_sigma;
    epipolar_cells(ctx, flow, cur_from_prev)
        .into_par_iter()
        .filter_map(|(cell, c)| {
            let point = triangulate(&camera, cur_from_prev, &c)?;
            let ok = point.depth > 0.0
                && point.depth.is_finite()
                && point.depth_variance.sqrt() <= max_rel * point.depth;
            (ok && point.depth <= max_depth).then_some(CellPoint { cell, point })
        })
        .collect()
}
