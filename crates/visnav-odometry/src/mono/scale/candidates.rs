//! The scale candidates of a frame (§5 step 4): the ground plane `s = −(b·h)/d` fitted to the
//! unit-scale triangulation, the median depth ratio against the previous depth map, and the
//! known distance of the first frame pair.

use nalgebra::{Point2, Point3};
use visnav_geometry::plane::{GroundPlane, fit_dominant_plane, fit_ground_plane};
use visnav_geometry::triangulation::TriangulatedPoint;

use crate::mono::config::KnownDistance;
use crate::mono::context::FrameContext;
use crate::mono::correspondence::median;
use crate::mono::depth::{DepthMap, InterpolatedDepth};
use crate::mono::point_scale::PointScale;

/// The depth-ratio scale reads the new triangulation between four cells whose inverse depths
/// are within 10 % of each other (on one surface).
const RATIO_MAX_SPREAD: f64 = 0.1;

/// A dense triangulation on the depth grid.
pub(in crate::mono) struct CellPoint {
    /// The depth-grid cell.
    pub(in crate::mono) cell: usize,
    /// The point triangulated at the cell's pixel, in the previous camera.
    pub(in crate::mono) point: TriangulatedPoint,
}

/// The scale candidates of a frame (§5), before the motion-prior gate.
pub(super) struct ScaleCandidates {
    /// The fitted ground plane (unit-translation units).
    pub(super) ground: Option<GroundPlane>,
    /// Ground-plane scale `s = −(b·h)/d` with the configured camera height, metres.
    pub(super) ground_m: Option<f64>,
    /// Median depth ratio against the previous depth map, metres.
    pub(super) depth_m: Option<f64>,
    /// Share of the triangulated cells the previous depth map also has.
    pub(super) overlap: f64,
    /// Scale from `scale.known_distance`, metres (first frame pair only).
    pub(super) known_m: Option<f64>,
}

/// The scale candidates (§5): the ground plane `s = −(b·h)/d` (with the fitted plane) and
/// the median ratio of the previous depth map `prior` to the unit-scale depths.
///
/// The aerial dominant plane is bounded in roll (`ground.max_roll_rad`, no facade beside the
/// camera) while `initialising` (the first ground, and a new map's): later frames' dominant
/// planes only re-estimate the height and re-anchor once on a median, where a single facade
/// weighs little.
pub(super) fn scale_candidates(
    ctx: &FrameContext<'_>,
    (prior, cells): (Option<&DepthMap>, &[CellPoint]),
    at_points: Option<PointScale>,
    initialising: bool,
    rng: &mut visnav_geometry::ChaCha8Rng,
) -> ScaleCandidates {
    let cfg = ctx.config.scale;
    let grid = DepthMap::empty(
        ctx.camera.width as usize,
        ctx.camera.height as usize,
        ctx.config.depth_stride_px,
    );
    let points: Vec<Point3<f64>> = cells.iter().map(|c| c.point.p_in_cam1).collect();
    let pixels: Vec<Point2<f64>> = cells.iter().map(|c| grid.pixel_of(c.cell)).collect();
    let dominant = cfg.ground_search.dominant(cfg.aerial);
    let ground = if dominant {
        let any_roll = visnav_geometry::plane::GroundPlaneConfig {
            max_roll_rad: std::f64::consts::FRAC_PI_2,
            ..cfg.ground
        };
        let ground_cfg = if initialising { &cfg.ground } else { &any_roll };
        fit_dominant_plane(&points, ground_cfg, rng)
    } else {
        fit_ground_plane(ctx.camera, &points, &pixels, &cfg.ground, rng)
    };
    let (depth_m, overlap) = match (at_points, prior) {
        (Some(at), Some(prior)) => (at.scale_m, at.points as f64 / prior.known().max(1) as f64),
        (None, Some(prior)) => {
            let mut ratios: Vec<f64> = if ctx.subpixel_depth() {
                let unit =
                    InterpolatedDepth::new(&grid, cells.iter().map(|c| (c.cell, c.point.depth)));
                prior.ratios_to(&unit, RATIO_MAX_SPREAD)
            } else {
                cells
                    .iter()
                    .filter_map(|c| prior.get(c.cell).map(|(d, _)| d / c.point.depth))
                    .filter(|r| r.is_finite() && *r > 0.0)
                    .collect()
            };
            let overlap = ratios.len() as f64 / cells.len().max(1) as f64;
            let depth_m = (ratios.len() >= cfg.min_ratio_samples)
                .then(|| median(&mut ratios))
                .flatten();
            (depth_m, overlap)
        }
        (_, None) => (None, 0.0),
    };
    let ground_m = ground
        .as_ref()
        .map(|g| ground_scale(g, cfg.camera_height_m, dominant))
        .filter(|s| s.is_finite() && *s > 0.0);
    let known_m = cfg
        .known_distance
        .filter(|_| ctx.frame == 1)
        .and_then(|k| known_distance_scale(&k, cells, &grid, 2.0 * grid.stride as f64));
    ScaleCandidates {
        ground,
        ground_m,
        depth_m,
        overlap,
        known_m,
    }
}

/// The scale that makes the two known points of the first image `distance_m` apart: each point
/// is the mean of the triangulated cells within `radius_px` of it (symmetric around it, so a
/// locally planar surface keeps its position and the cells' noise averages), `None` if either
/// has none.
fn known_distance_scale(
    known: &KnownDistance,
    cells: &[CellPoint],
    grid: &DepthMap,
    radius_px: f64,
) -> Option<f64> {
    let near = |px: [f64; 2]| {
        let (sum, n) = cells
            .iter()
            .filter(|c| {
                let p = grid.pixel_of(c.cell);
                (p.x - px[0]).hypot(p.y - px[1]) <= radius_px
            })
            .fold((nalgebra::Vector3::zeros(), 0_usize), |(s, n), c| {
                (s + c.point.p_in_cam1.coords, n + 1)
            });
        (n > 0).then(|| sum / n as f64)
    };
    let unit = (near(known.a_px)? - near(known.b_px)?).norm();
    let s = known.distance_m / unit;
    (s.is_finite() && s > 0.0).then_some(s)
}

/// The scale that puts the camera `height_m` above `ground`: along the camera y axis
/// (`s = −(b·h)/d`, §5) or, for the dominant plane of `GroundSearch::Dominant`, along the
/// plane's normal (`s = h/|d|`).
pub(super) fn ground_scale(ground: &GroundPlane, height_m: f64, dominant: bool) -> f64 {
    if dominant {
        ground.scale_by_distance(height_m)
    } else {
        ground.scale(height_m)
    }
}
