//! The procedural city: a ground plane with a road (asphalt, lane markings, kerbs, paved
//! sidewalks, verges) that follows a path, building facades with windows on both sides, boxes and
//! poles, and a sky. Geometry is f64; textures are band-limited by the pixel footprint
//! ([`crate::noise`]) and the structured patterns (markings, joints, windows) are box-filtered
//! analytically, so images are anti-aliased before supersampling.
//!
//! Frames: the world is the first camera frame (x right, y down, z forward, metres). The ground is
//! the plane `y = a x + b z + k` fitted (least squares) to the camera path and lowered by
//! `ground_depth_m` below it (and below the highest residual, so no camera is under the ground);
//! for a level path such as [`crate::drive_trajectory`] it is exactly `y = +ground_depth_m`. The
//! road follows the x–z projection of the path.
//!
//! This module is the scene's description and layout (the road, the objects placed along it, the
//! ground plane); the two things done with it are its children: `trace` casts rays through it
//! (the nearest hit), `shade` gives a hit its intensity (the band-limited textures and the
//! box-filtered patterns). They extend [`Scene`] and import from here, never the other way.

use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use visnav_core::Pose;

use crate::SynthError;
use crate::scene_config::SceneConfig;

/// A straight piece of the road centre line in the x–z plane.
#[derive(Debug, Clone, Copy)]
struct Segment {
    a: [f64; 2],
    dir: [f64; 2],
    len: f64,
    /// Arc length at `a`, metres.
    s0: f64,
}

impl Segment {
    /// (arc length, signed lateral offset (+ = right of the direction of travel), distance).
    #[inline]
    fn locate(&self, x: f64, z: f64) -> (f64, f64, f64) {
        let rx = x - self.a[0];
        let rz = z - self.a[1];
        let along = (rx * self.dir[0] + rz * self.dir[1]).clamp(0.0, self.len);
        // right of travel: the camera's +x when heading along +z is (dir_z, -dir_x)
        let lateral = rx * self.dir[1] - rz * self.dir[0];
        let ex = rx - along * self.dir[0];
        let ez = rz - along * self.dir[1];
        (self.s0 + along, lateral, (ex * ex + ez * ez).sqrt())
    }
}

/// A uniform grid over the x–z plane listing items per cell (compressed rows).
#[derive(Debug, Clone)]
struct Grid {
    x0: f64,
    z0: f64,
    cell_m: f64,
    nx: usize,
    nz: usize,
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    fn build(bounds: [f64; 4], cell_m: f64, boxes: &[[f64; 4]]) -> Self {
        // at most ~1 million cells, whatever the extent of the path
        let area = (bounds[1] - bounds[0]) * (bounds[3] - bounds[2]);
        let cell_m = cell_m.max((area / 1e6).sqrt());
        let nx = (((bounds[1] - bounds[0]) / cell_m).ceil() as usize).max(1);
        let nz = (((bounds[3] - bounds[2]) / cell_m).ceil() as usize).max(1);
        let mut cells: Vec<Vec<u32>> = vec![Vec::new(); nx * nz];
        let mut grid = Self {
            x0: bounds[0],
            z0: bounds[2],
            cell_m,
            nx,
            nz,
            offsets: Vec::new(),
            items: Vec::new(),
        };
        for (i, b) in boxes.iter().enumerate() {
            let (ix0, iz0) = grid.cell_clamped(b[0], b[2]);
            let (ix1, iz1) = grid.cell_clamped(b[1], b[3]);
            for iz in iz0..=iz1 {
                for ix in ix0..=ix1 {
                    cells[iz * nx + ix].push(i as u32);
                }
            }
        }
        grid.offsets.push(0);
        for c in &cells {
            grid.items.extend_from_slice(c);
            grid.offsets.push(grid.items.len() as u32);
        }
        grid
    }

    #[inline]
    fn cell_clamped(&self, x: f64, z: f64) -> (usize, usize) {
        let ix = ((x - self.x0) / self.cell_m)
            .floor()
            .clamp(0.0, (self.nx - 1) as f64) as usize;
        let iz = ((z - self.z0) / self.cell_m)
            .floor()
            .clamp(0.0, (self.nz - 1) as f64) as usize;
        (ix, iz)
    }

    #[inline]
    fn cell_items(&self, ix: usize, iz: usize) -> &[u32] {
        let c = iz * self.nx + ix;
        &self.items[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }

    fn x1(&self) -> f64 {
        self.x0 + self.nx as f64 * self.cell_m
    }

    fn z1(&self) -> f64 {
        self.z0 + self.nz as f64 * self.cell_m
    }
}

/// The surface pattern of an object.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Material {
    /// A building wall with a grid of windows.
    Facade {
        bay_m: f64,
        floor_m: f64,
        window_w_m: f64,
        window_h_m: f64,
    },
    /// A wooden crate / container.
    Crate,
    /// A painted pole.
    Pole,
    /// A tree crown: clumps of leaves.
    Foliage,
}

/// An upright box rotated about the vertical axis.
#[derive(Debug, Clone, Copy)]
struct Cuboid {
    centre: [f64; 2],
    /// Unit length axis in x–z; the width axis is `(-u_z, u_x)`.
    axis_u: [f64; 2],
    half_u: f64,
    half_w: f64,
    y_top: f64,
    /// Bottom, sunk below the ground so that a slightly tilted ground never shows a gap.
    y_bottom: f64,
    /// Ground height `y` at the centre: texture heights are measured from here.
    y_base: f64,
}

/// A vertical cylinder.
#[derive(Debug, Clone, Copy)]
struct Cylinder {
    centre: [f64; 2],
    radius: f64,
    y_top: f64,
    y_bottom: f64,
    y_base: f64,
}

#[derive(Debug, Clone, Copy)]
enum Shape {
    Cuboid(Cuboid),
    Cylinder(Cylinder),
}

#[derive(Debug, Clone, Copy)]
struct Object {
    shape: Shape,
    material: Material,
    /// Base albedo in 0..1.
    tone: f32,
    seed: u32,
}

/// What a ray hit and where on that surface (texture coordinates in metres).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Surface {
    Ground {
        x: f64,
        z: f64,
    },
    Object {
        index: u32,
        u: f64,
        v: f64,
        top: bool,
        /// Which face (slab axis and side; 6 for a cylinder mantle).
        face: u8,
    },
}

/// A ray hit: ray parameter, world normal, surface.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    pub t: f64,
    pub normal: Vector3<f64>,
    pub surface: Surface,
}

/// A static procedural world (see the module docs). Build it with [`Scene::city`] or
/// [`Scene::along`]; render it with [`crate::render_view`].
#[derive(Debug, Clone)]
pub struct Scene {
    config: SceneConfig,
    seed: u64,
    segments: Vec<Segment>,
    road_grid: Grid,
    objects: Vec<Object>,
    object_grid: Grid,
    /// The ground plane.
    ground: GroundPlane,
    /// Highest object top (most negative y).
    y_top_min: f64,
    sun: Vector3<f64>,
}

/// How far object bottoms reach below the ground, metres.
const SINK_M: f64 = 3.0;

/// The ground `y = a x + b z + k` (y down).
#[derive(Debug, Clone, Copy, PartialEq)]
struct GroundPlane {
    a: f64,
    b: f64,
    k: f64,
}

impl GroundPlane {
    /// Least-squares plane `y = a x + b z + e` through the camera positions (slightly
    /// regularised towards level so that a straight path is well posed), lowered by
    /// `depth_m` plus the largest residual so that every camera is at least `depth_m` above it.
    fn fit(trajectory: &[Pose], depth_m: f64) -> Self {
        let n = trajectory.len() as f64;
        let mean = trajectory
            .iter()
            .fold(Vector3::zeros(), |acc, p| acc + p.translation.vector)
            / n;
        let (mut sxx, mut sxz, mut szz, mut sxy, mut szy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for p in trajectory {
            let d = p.translation.vector - mean;
            sxx += d.x * d.x;
            sxz += d.x * d.z;
            szz += d.z * d.z;
            sxy += d.x * d.y;
            szy += d.z * d.y;
        }
        let ridge = 1.0 + 1e-3 * (sxx + szz);
        let (sxx, szz) = (sxx + ridge, szz + ridge);
        let det = sxx * szz - sxz * sxz;
        let (a, b) = if det.abs() > 1e-12 {
            ((sxy * szz - szy * sxz) / det, (szy * sxx - sxy * sxz) / det)
        } else {
            (0.0, 0.0)
        };
        let e = mean.y - a * mean.x - b * mean.z;
        let lift = trajectory
            .iter()
            .map(|p| {
                let t = p.translation.vector;
                t.y - (a * t.x + b * t.z + e)
            })
            .fold(0.0, f64::max);
        Self {
            a,
            b,
            k: e + depth_m + lift,
        }
    }

    /// Ground `y` at `(x, z)`.
    #[inline]
    fn y_at(&self, x: f64, z: f64) -> f64 {
        self.a * x + self.b * z + self.k
    }

    /// Unit normal pointing up (towards -y).
    #[inline]
    fn normal_up(&self) -> Vector3<f64> {
        Vector3::new(self.a, -1.0, self.b).normalize()
    }
}

/// Longest road a scene is laid out along, metres: the objects placed grow with it (1e7 m took
/// 9 s and 0.8 GB, a thousandth of that per km); the longest KITTI sequence drives about 5 km.
pub const MAX_ROAD_M: f64 = 1_000_000.0;

/// Distance from the centre line within which ground points look up road segments, metres.
const ROAD_INFLUENCE_M: f64 = 12.0;
const CELL_M: f64 = 8.0;

impl Scene {
    /// The default world: a straight road along +z (from 60 m behind the origin to 650 m ahead)
    /// lined with buildings, boxes and poles, with the defaults of [`SceneConfig`].
    #[must_use]
    pub fn city(seed: u64) -> Self {
        let path = [Pose::identity(), Isometry3::translation(0.0, 0.0, 400.0)];
        Self::along_with(&path, seed, SceneConfig::default()).unwrap_or_else(|_| fallback_city())
    }

    /// A world whose road follows the x–z projection of a trajectory (`world_from_cam` poses,
    /// e.g. [`crate::drive_trajectory`] or a KITTI ground-truth file), extended before the
    /// first and after the last pose, with the defaults of [`SceneConfig`].
    ///
    /// # Errors
    /// [`SynthError::EmptyTrajectory`] or [`SynthError::NonFinitePose`].
    pub fn along(trajectory: &[Pose], seed: u64) -> Result<Self, SynthError> {
        Self::along_with(trajectory, seed, SceneConfig::default())
    }

    /// [`Scene::along`] with explicit parameters.
    ///
    /// # Errors
    /// An empty trajectory, a non-finite pose, a road longer than [`MAX_ROAD_M`], or an invalid
    /// config.
    pub fn along_with(
        trajectory: &[Pose],
        seed: u64,
        config: SceneConfig,
    ) -> Result<Self, SynthError> {
        config.validate()?;
        if trajectory.is_empty() {
            return Err(SynthError::EmptyTrajectory);
        }
        if let Some(index) = trajectory
            .iter()
            .position(|p| !p.to_homogeneous().iter().all(|v| v.is_finite()))
        {
            return Err(SynthError::NonFinitePose { index });
        }
        let segments = road_segments(trajectory, &config);
        let length_m = segments.last().map_or(0.0, |s| s.s0 + s.len);
        // NaN and inf lengths fail too
        let fits = length_m <= MAX_ROAD_M;
        if !fits {
            let p0 = trajectory[0].translation.vector;
            let (index, distance_m) = trajectory
                .iter()
                .map(|p| (p.translation.vector - p0).norm())
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((0, 0.0));
            return Err(SynthError::TrajectoryTooLong {
                length_m,
                limit_m: MAX_ROAD_M,
                index,
                distance_m,
            });
        }
        let mut bounds = [f64::MAX, f64::MIN, f64::MAX, f64::MIN];
        let reach = config.setback_max_m + 25.0;
        for s in &segments {
            for (x, z) in [
                (s.a[0], s.a[1]),
                (s.a[0] + s.len * s.dir[0], s.a[1] + s.len * s.dir[1]),
            ] {
                bounds[0] = bounds[0].min(x - reach);
                bounds[1] = bounds[1].max(x + reach);
                bounds[2] = bounds[2].min(z - reach);
                bounds[3] = bounds[3].max(z + reach);
            }
        }
        let seg_boxes: Vec<[f64; 4]> = segments
            .iter()
            .map(|s| {
                let bx = s.a[0] + s.len * s.dir[0];
                let bz = s.a[1] + s.len * s.dir[1];
                [
                    s.a[0].min(bx) - ROAD_INFLUENCE_M,
                    s.a[0].max(bx) + ROAD_INFLUENCE_M,
                    s.a[1].min(bz) - ROAD_INFLUENCE_M,
                    s.a[1].max(bz) + ROAD_INFLUENCE_M,
                ]
            })
            .collect();
        let road_grid = Grid::build(bounds, CELL_M, &seg_boxes);
        let ground = GroundPlane::fit(trajectory, config.ground_depth_m);
        let mut scene = Self {
            ground,
            config,
            seed,
            segments,
            road_grid,
            objects: Vec::new(),
            object_grid: Grid::build(bounds, CELL_M, &[]),
            y_top_min: 0.0,
            sun: Vector3::new(0.4, -0.75, -0.5).normalize(),
        };
        scene.objects = scene.place_objects();
        let boxes: Vec<[f64; 4]> = scene.objects.iter().map(footprint_aabb).collect();
        scene.object_grid = Grid::build(bounds, CELL_M, &boxes);
        scene.y_top_min = scene
            .objects
            .iter()
            .map(|o| match o.shape {
                Shape::Cuboid(c) => c.y_top,
                Shape::Cylinder(c) => c.y_top,
            })
            .fold(f64::INFINITY, f64::min);
        Ok(scene)
    }

    /// A copy rendered with `n` x `n` samples per pixel (clamped to 1..=8).
    #[must_use]
    pub fn with_supersampling(mut self, n: u32) -> Self {
        self.config.supersampling = n.clamp(1, 8);
        self
    }

    /// The parameters of this scene.
    #[must_use]
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

    /// The seed the scene was generated with.
    #[must_use]
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Number of objects (buildings, boxes, poles).
    #[must_use]
    pub fn object_count(&self) -> usize {
        self.objects.len()
    }

    fn place_objects(&self) -> Vec<Object> {
        let cfg = &self.config;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0xc17e_5eed);
        let total = self.segments.last().map_or(0.0, |s| s.s0 + s.len);
        let mut objects = Vec::new();
        let edge = cfg.road_half_width_m + cfg.kerb_width_m;
        for side in [-1.0f64, 1.0] {
            if cfg.forest_depth_m > 0.0 {
                self.place_trees(side, total, &mut rng, &mut objects);
            }
            // buildings
            let mut s = rng.random_range(0.0..6.0);
            while s < total && cfg.forest_depth_m <= 0.0 {
                let length = rng.random_range(8.0..22.0);
                let depth = rng.random_range(8.0..16.0);
                let setback = rng.random_range(cfg.setback_min_m..=cfg.setback_max_m);
                let height =
                    rng.random_range(cfg.building_min_height_m..=cfg.building_max_height_m);
                let (p, dir) = self.point_at(s + 0.5 * length);
                let normal = [dir[1] * side, -dir[0] * side];
                let off = setback + 0.5 * depth;
                let centre = [p[0] + normal[0] * off, p[1] + normal[1] * off];
                let y_base = self.ground.y_at(centre[0], centre[1]);
                let cuboid = Cuboid {
                    centre,
                    axis_u: dir,
                    half_u: 0.5 * length,
                    half_w: 0.5 * depth,
                    y_top: y_base - height,
                    y_bottom: y_base + SINK_M,
                    y_base,
                };
                let floor_m = rng.random_range(2.8..3.6);
                let bay_m = rng.random_range(2.2..4.0);
                let material = Material::Facade {
                    bay_m,
                    floor_m,
                    window_w_m: bay_m * rng.random_range(0.35..0.6),
                    window_h_m: floor_m * rng.random_range(0.35..0.55),
                };
                let obj = Object {
                    shape: Shape::Cuboid(cuboid),
                    material,
                    tone: rng.random_range(0.3..0.8),
                    seed: rng.random(),
                };
                if self.clear_of_road(&obj, cfg.setback_min_m - 1.0) {
                    objects.push(obj);
                }
                s += length + rng.random_range(0.0..5.0);
            }
            // boxes on the verge / sidewalk
            let mut s = rng.random_range(5.0..25.0);
            while s < total {
                let size = rng.random_range(0.8..2.2);
                let (p, dir) = self.point_at(s);
                let normal = [dir[1] * side, -dir[0] * side];
                let off = edge + rng.random_range(1.0..(cfg.setback_min_m - edge - 0.5).max(1.5));
                let yaw = rng.random_range(-0.5..0.5f64);
                let (sy, cy) = yaw.sin_cos();
                let axis = [dir[0] * cy - dir[1] * sy, dir[0] * sy + dir[1] * cy];
                let centre = [p[0] + normal[0] * off, p[1] + normal[1] * off];
                let y_base = self.ground.y_at(centre[0], centre[1]);
                let obj = Object {
                    shape: Shape::Cuboid(Cuboid {
                        centre,
                        axis_u: axis,
                        half_u: 0.5 * size * rng.random_range(1.0..2.0),
                        half_w: 0.5 * size,
                        y_top: y_base - size * rng.random_range(0.6..1.2),
                        y_bottom: y_base + SINK_M,
                        y_base,
                    }),
                    material: Material::Crate,
                    tone: rng.random_range(0.3..0.65),
                    seed: rng.random(),
                };
                if self.clear_of_road(&obj, edge + 0.3) {
                    objects.push(obj);
                }
                s += rng.random_range(12.0..35.0);
            }
            // poles at the kerb
            let mut s = rng.random_range(0.0..15.0);
            while s < total {
                let (p, dir) = self.point_at(s);
                let normal = [dir[1] * side, -dir[0] * side];
                let off = edge + 0.4;
                let centre = [p[0] + normal[0] * off, p[1] + normal[1] * off];
                let y_base = self.ground.y_at(centre[0], centre[1]);
                let obj = Object {
                    shape: Shape::Cylinder(Cylinder {
                        centre,
                        radius: rng.random_range(0.08..0.16),
                        y_top: y_base - rng.random_range(3.5..7.0),
                        y_bottom: y_base + SINK_M,
                        y_base,
                    }),
                    material: Material::Pole,
                    tone: rng.random_range(0.3..0.7),
                    seed: rng.random(),
                };
                if self.clear_of_road(&obj, edge + 0.2) {
                    objects.push(obj);
                }
                s += rng.random_range(14.0..30.0);
            }
        }
        objects
    }

    /// The forest on one side of the road (`SceneConfig::forest_depth_m`): a crown every 7 m
    /// along and across the road (jittered by up to 2.5 m, one in five left out) from the
    /// setback to the forest's depth.
    fn place_trees(&self, side: f64, total: f64, rng: &mut ChaCha8Rng, objects: &mut Vec<Object>) {
        const SPACING_M: f64 = 7.0;
        let cfg = &self.config;
        let mut s = 0.0;
        while s < total {
            let (p, dir) = self.point_at(s);
            let normal = [dir[1] * side, -dir[0] * side];
            let mut off = cfg.setback_min_m;
            while off < cfg.forest_depth_m {
                let radius = rng.random_range(1.5..3.5);
                let (ja, jo) = (rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5));
                let along = [p[0] + dir[0] * ja, p[1] + dir[1] * ja];
                let o = off + radius + jo;
                let centre = [along[0] + normal[0] * o, along[1] + normal[1] * o];
                let y_base = self.ground.y_at(centre[0], centre[1]);
                let obj = Object {
                    shape: Shape::Cylinder(Cylinder {
                        centre,
                        radius,
                        y_top: y_base - rng.random_range(8.0..25.0),
                        y_bottom: y_base + SINK_M,
                        y_base,
                    }),
                    material: Material::Foliage,
                    tone: rng.random_range(0.2..0.45),
                    seed: rng.random(),
                };
                if rng.random_range(0.0..1.0) > 0.2
                    && self.clear_of_road(&obj, cfg.setback_min_m - 1.0)
                {
                    objects.push(obj);
                }
                off += SPACING_M;
            }
            s += SPACING_M;
        }
    }

    /// Point and unit direction of the centre line at arc length `s`.
    fn point_at(&self, s: f64) -> ([f64; 2], [f64; 2]) {
        let idx = self
            .segments
            .partition_point(|seg| seg.s0 + seg.len < s)
            .min(self.segments.len().saturating_sub(1));
        let seg = self.segments[idx];
        let along = (s - seg.s0).clamp(0.0, seg.len);
        (
            [seg.a[0] + along * seg.dir[0], seg.a[1] + along * seg.dir[1]],
            seg.dir,
        )
    }

    /// Whether every point of the centre line keeps `clearance_m` from the object's footprint.
    fn clear_of_road(&self, obj: &Object, clearance_m: f64) -> bool {
        let b = footprint_aabb(obj);
        let (ix0, iz0) = self.road_grid.cell_clamped(b[0], b[2]);
        let (ix1, iz1) = self.road_grid.cell_clamped(b[1], b[3]);
        for iz in iz0..=iz1 {
            for ix in ix0..=ix1 {
                for &si in self.road_grid.cell_items(ix, iz) {
                    let seg = self.segments[si as usize];
                    // only the stretch of the segment within reach of the object
                    let (cx, cz) = (0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3]));
                    let reach = 0.5 * (b[1] - b[0]).hypot(b[3] - b[2]) + clearance_m;
                    let along = (cx - seg.a[0]) * seg.dir[0] + (cz - seg.a[1]) * seg.dir[1];
                    let lo = (along - reach).clamp(0.0, seg.len);
                    let hi = (along + reach).clamp(0.0, seg.len);
                    let steps = ((hi - lo) / 0.25).ceil().max(1.0) as usize;
                    for k in 0..=steps {
                        let a = lo + (hi - lo) * k as f64 / steps as f64;
                        let x = seg.a[0] + a * seg.dir[0];
                        let z = seg.a[1] + a * seg.dir[1];
                        if footprint_distance(obj, x, z) < clearance_m {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// Road coordinates (arc length, signed lateral offset) of a ground point, if near the road.
    #[inline]
    fn road_coords(&self, x: f64, z: f64) -> Option<(f64, f64)> {
        let g = &self.road_grid;
        if x < g.x0 || z < g.z0 || x >= g.x1() || z >= g.z1() {
            return None;
        }
        let (ix, iz) = g.cell_clamped(x, z);
        let mut best: Option<(f64, f64, f64)> = None;
        for &si in g.cell_items(ix, iz) {
            let (s, lat, dist) = self.segments[si as usize].locate(x, z);
            if best.is_none_or(|b| dist < b.2) {
                best = Some((s, lat, dist));
            }
        }
        best.filter(|b| b.2 < ROAD_INFLUENCE_M).map(|b| (b.0, b.1))
    }
}

fn fallback_city() -> Scene {
    // `Scene::city` only fails on an empty path or invalid defaults, neither of which happens;
    // build the minimal scene by hand so that the function never panics.
    let config = SceneConfig::default();
    let config_depth = config.ground_depth_m;
    let bounds = [-50.0, 50.0, -50.0, 50.0];
    Scene {
        config,
        seed: 0,
        segments: Vec::new(),
        road_grid: Grid::build(bounds, CELL_M, &[]),
        objects: Vec::new(),
        object_grid: Grid::build(bounds, CELL_M, &[]),
        ground: GroundPlane {
            a: 0.0,
            b: 0.0,
            k: config_depth,
        },
        y_top_min: 0.0,
        sun: Vector3::new(0.4, -0.75, -0.5).normalize(),
    }
}

/// Axis-aligned x–z bounds `[x0, x1, z0, z1]` of an object's footprint.
fn footprint_aabb(obj: &Object) -> [f64; 4] {
    match obj.shape {
        Shape::Cuboid(c) => {
            let ex = (c.half_u * c.axis_u[0]).abs() + (c.half_w * c.axis_u[1]).abs();
            let ez = (c.half_u * c.axis_u[1]).abs() + (c.half_w * c.axis_u[0]).abs();
            [
                c.centre[0] - ex,
                c.centre[0] + ex,
                c.centre[1] - ez,
                c.centre[1] + ez,
            ]
        }
        Shape::Cylinder(c) => [
            c.centre[0] - c.radius,
            c.centre[0] + c.radius,
            c.centre[1] - c.radius,
            c.centre[1] + c.radius,
        ],
    }
}

/// Distance in the x–z plane from a point to an object's footprint (0 inside).
fn footprint_distance(obj: &Object, x: f64, z: f64) -> f64 {
    match obj.shape {
        Shape::Cuboid(c) => {
            let rx = x - c.centre[0];
            let rz = z - c.centre[1];
            let pu = rx * c.axis_u[0] + rz * c.axis_u[1];
            let pw = -rx * c.axis_u[1] + rz * c.axis_u[0];
            let du = (pu.abs() - c.half_u).max(0.0);
            let dw = (pw.abs() - c.half_w).max(0.0);
            (du * du + dw * dw).sqrt()
        }
        Shape::Cylinder(c) => ((x - c.centre[0]).hypot(z - c.centre[1]) - c.radius).max(0.0),
    }
}

/// The road centre line from the x–z projection of a trajectory: positions at least 2 m apart,
/// extended backwards along the first heading and forwards along the last one.
fn road_segments(trajectory: &[Pose], cfg: &SceneConfig) -> Vec<Segment> {
    let heading = |p: &Pose| {
        let f = p.rotation * Vector3::z();
        let n = f.x.hypot(f.z);
        if n < 1e-9 {
            [0.0, 1.0]
        } else {
            [f.x / n, f.z / n]
        }
    };
    let first = &trajectory[0];
    let last = &trajectory[trajectory.len() - 1];
    let h0 = heading(first);
    let h1 = heading(last);
    let p0 = [first.translation.x, first.translation.z];
    let mut points = vec![[p0[0] - cfg.lead_in_m * h0[0], p0[1] - cfg.lead_in_m * h0[1]]];
    points.push(p0);
    for p in trajectory {
        let q = [p.translation.x, p.translation.z];
        let prev = points[points.len() - 1];
        if (q[0] - prev[0]).hypot(q[1] - prev[1]) >= 2.0 {
            points.push(q);
        }
    }
    let pl = [last.translation.x, last.translation.z];
    let prev = points[points.len() - 1];
    if (pl[0] - prev[0]).hypot(pl[1] - prev[1]) > 1e-6 {
        points.push(pl);
    }
    points.push([
        pl[0] + cfg.lead_out_m * h1[0],
        pl[1] + cfg.lead_out_m * h1[1],
    ]);
    let mut segments = Vec::with_capacity(points.len());
    let mut s0 = 0.0;
    for w in points.windows(2) {
        let dx = w[1][0] - w[0][0];
        let dz = w[1][1] - w[0][1];
        let len = dx.hypot(dz);
        if len < 1e-9 {
            continue;
        }
        segments.push(Segment {
            a: w[0],
            dir: [dx / len, dz / len],
            len,
            s0,
        });
        s0 += len;
    }
    if segments.is_empty() {
        segments.push(Segment {
            a: p0,
            dir: h0,
            len: 1.0,
            s0: 0.0,
        });
    }
    segments
}

mod shade;
mod trace;

#[cfg(test)]
#[path = "scene_tests.rs"]
mod scene_tests;
