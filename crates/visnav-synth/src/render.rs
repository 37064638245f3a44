//! Ray-cast rendering of a [`Scene`] and exact ground truth.
//!
//! * [`render_view`]: an anti-aliased grayscale image (textures filtered over the pixel footprint;
//!   `n x n` supersampling of pixels that straddle a geometric edge or a material boundary) and the
//!   depth `z` (metres, camera frame) of the ray through each pixel centre; `f32::INFINITY` where
//!   the centre ray sees the sky.
//! * [`render_stereo`]: the rectified pair, the right camera `baseline_m` along the left +x.
//! * [`flow_between`]: forward flow from view a to view b, `flow(p) = π(b_from_a · π⁻¹(p, z_a(p))) - p`
//!   (exact for the static scene; sky pixels move by the rotation only), and the validity mask:
//!   the target lies in image b and its inverse depth agrees with image b's inverse depth
//!   interpolated bilinearly (inverse depth is affine across a plane, so this is exact on one
//!   surface and fails across occlusion boundaries).

use nalgebra::{Point2, Point3, Translation3, Vector3};
use rayon::prelude::*;
use visnav_core::FlowField;
use visnav_core::{CalibratedCamera, GrayImage, PinholeCamera, Pose, StereoCamera};

use crate::scene::{Hit, Scene};

/// One rendered view: the image and the depth of each pixel centre.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Grayscale intensities 0..255.
    pub image: GrayImage,
    /// Row-major depth `z` in metres (camera frame); `f32::INFINITY` for the sky.
    pub depth_m: Vec<f32>,
}

impl View {
    /// Depth at pixel `(x, y)`, metres.
    #[must_use]
    pub fn depth_at(&self, x: usize, y: usize) -> f32 {
        self.depth_m[y * self.image.width() + x]
    }
}

/// Ground-truth forward flow between two views.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowGt {
    /// Flow `(u, v)` in pixels from image a to image b; geometric flow everywhere it is defined
    /// (also on occluded pixels), `1e10` (unknown) where the point is behind camera b.
    pub flow: FlowField,
    /// Row-major: the flow target is inside image b and visible there (not occluded).
    pub valid: Vec<bool>,
}

impl FlowGt {
    /// The flow with occluded / out-of-image pixels marked unknown (`1e10`), as in `.flo` files.
    #[must_use]
    pub fn masked_flow(&self) -> FlowField {
        let mut f = self.flow.clone();
        for (i, &ok) in self.valid.iter().enumerate() {
            if !ok {
                f.uv[2 * i] = UNKNOWN_FLOW;
                f.uv[2 * i + 1] = UNKNOWN_FLOW;
            }
        }
        f
    }

    /// Fraction of valid pixels.
    #[must_use]
    pub fn valid_fraction(&self) -> f64 {
        self.valid.iter().filter(|v| **v).count() as f64 / self.valid.len().max(1) as f64
    }
}

/// Surface key of the sky (no hit).
const SKY_KEY: u64 = u64::MAX;

/// The value marking unknown flow in `.flo` files.
pub const UNKNOWN_FLOW: f32 = 1e10;

/// Renders the scene seen by `cam` at `world_from_cam` (rayon over rows; deterministic).
#[must_use]
pub fn render_view(scene: &Scene, cam: &PinholeCamera, world_from_cam: &Pose) -> View {
    let ray = |u: f64, v: f64| Vector3::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
    render_rays(scene, cam, world_from_cam, ray)
}

/// Renders the raw (distorted) image of a camera with lens distortion: each pixel's ray is
/// the undistorted ray of its raw pixel ([`CalibratedCamera::undistort_px`]; where the model
/// cannot be inverted, the ray of the distorted coordinates), so the image is exact, not
/// resampled. The depth is that of the ray through each raw pixel's centre (`z`, metres).
#[must_use]
pub fn render_view_distorted(scene: &Scene, cam: &CalibratedCamera, world_from_cam: &Pose) -> View {
    render_view_through(scene, &LensRays::new(cam), world_from_cam)
}

/// [`render_view_distorted`] with the lens's rays computed once ([`LensRays::new`]), for many
/// views of one camera.
#[must_use]
pub fn render_view_through(scene: &Scene, lens: &LensRays, world_from_cam: &Pose) -> View {
    let w = lens.camera.pinhole.width as usize;
    let ray = |u: f64, v: f64| {
        // a pixel centre: the tabulated ray
        let (x, y) = (u as usize, v as usize);
        let i = y * w + x;
        if u >= 0.0 && v >= 0.0 && x as f64 == u && y as f64 == v && x < w && i < lens.centres.len()
        {
            lens.centres[i]
        } else {
            lens.ray(u, v)
        }
    };
    render_rays(scene, &lens.camera.pinhole, world_from_cam, ray)
}

/// The camera-frame rays (unit `z`) of a camera with lens distortion, those of the pixel
/// centres tabulated.
#[derive(Debug, Clone)]
pub struct LensRays {
    camera: CalibratedCamera,
    centres: Vec<Vector3<f64>>,
}

impl LensRays {
    /// Tabulates the rays of the pixel centres of `camera`.
    #[must_use]
    pub fn new(camera: &CalibratedCamera) -> Self {
        let mut lens = Self {
            camera: *camera,
            centres: Vec::new(),
        };
        let (w, h) = (
            camera.pinhole.width as usize,
            camera.pinhole.height as usize,
        );
        lens.centres = (0..w * h)
            .map(|i| lens.ray((i % w) as f64, (i / w) as f64))
            .collect();
        lens
    }

    /// The undistorted ray of raw pixel `(u, v)`; where the model cannot be inverted, the ray
    /// of the distorted coordinates.
    fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let px = Point2::new(u, v);
        let ideal = self
            .camera
            .undistort_px(&px)
            .unwrap_or_else(|| self.camera.pinhole.normalize(&px));
        Vector3::new(ideal.x, ideal.y, 1.0)
    }
}

/// The renderer of [`render_view`] with the camera-frame ray of pixel `(u, v)` (unit `z`) given
/// by `ray_in_cam`; `cam` gives the image size and the focal length of the texture filter.
fn render_rays(
    scene: &Scene,
    cam: &PinholeCamera,
    world_from_cam: &Pose,
    ray_in_cam: impl Fn(f64, f64) -> Vector3<f64> + Sync,
) -> View {
    let w = cam.width as usize;
    let h = cam.height as usize;
    let n = scene.config().supersampling.clamp(1, 8) as usize;
    let rot = world_from_cam.rotation.to_rotation_matrix();
    let origin = world_from_cam.translation.vector;
    let mut image = vec![0.0f32; w * h];
    let mut depth_m = vec![f32::INFINITY; w * h];
    let inv_n = 1.0 / n as f64;
    let weight = 1.0 / (n * n) as f32;
    let odd = n % 2 == 1;
    let ray_at = |u: f64, v: f64| rot * ray_in_cam(u, v);
    // pass 1: the surface under every pixel corner (shared by four pixels)
    let key_of = |hit: Option<Hit>| hit.map_or(SKY_KEY, |h| scene.surface_key(&h));
    // (without supersampling no pixel looks at its corners)
    let mut corner_keys = vec![SKY_KEY; if n == 1 { 0 } else { (w + 1) * (h + 1) }];
    corner_keys
        .par_chunks_mut(w + 1)
        .enumerate()
        .for_each(|(cy, row)| {
            for (cx, key) in row.iter_mut().enumerate() {
                let dir = ray_at(cx as f64 - 0.5, cy as f64 - 0.5);
                *key = key_of(scene.trace(&origin, &dir));
            }
        });
    // pass 2: one shading sample where the pixel's corners and centre see one smooth surface
    // (its texture is filtered analytically over the pixel footprint); n x n supersampling
    // elsewhere (geometric edges, material boundaries)
    image
        .par_chunks_mut(w.max(1))
        .zip(depth_m.par_chunks_mut(w.max(1)))
        .enumerate()
        .for_each(|(y, (img_row, depth_row))| {
            for x in 0..w {
                let centre_dir = ray_at(x as f64, y as f64);
                let centre_hit = scene.trace(&origin, &centre_dir);
                depth_row[x] = centre_hit.map_or(f32::INFINITY, |hit| hit.t as f32);
                let smooth = n == 1 || {
                    let key = key_of(centre_hit);
                    let corners = [
                        corner_keys[y * (w + 1) + x],
                        corner_keys[y * (w + 1) + x + 1],
                        corner_keys[(y + 1) * (w + 1) + x],
                        corner_keys[(y + 1) * (w + 1) + x + 1],
                    ];
                    corners.iter().all(|&k| k == key)
                };
                img_row[x] = if smooth {
                    shade_sample(scene, &centre_dir, centre_hit.as_ref(), cam.fx, 1.0)
                } else {
                    let mut acc = 0.0f32;
                    for sy in 0..n {
                        let v = y as f64 + (sy as f64 + 0.5) * inv_n - 0.5;
                        for sx in 0..n {
                            let u = x as f64 + (sx as f64 + 0.5) * inv_n - 0.5;
                            let is_centre = odd && sx == n / 2 && sy == n / 2;
                            let (dir, hit) = if is_centre {
                                (centre_dir, centre_hit)
                            } else {
                                let dir = ray_at(u, v);
                                (dir, scene.trace(&origin, &dir))
                            };
                            acc += shade_sample(scene, &dir, hit.as_ref(), cam.fx, inv_n);
                        }
                    }
                    acc * weight
                };
            }
        });
    View {
        image: GrayImage::from_vec(w, h, image).unwrap_or_else(|| GrayImage::new(w, h, 0.0)),
        depth_m,
    }
}

/// Intensity of one ray (the camera-frame ray has unit z, so `hit.t` is the depth `z`). The
/// pixel footprint on the surface is `z |dir| / fx` divided by the cosine of the incidence angle
/// (clamped), used to band-limit the texture; `sub` scales it for the box-filtered patterns
/// (1 when one sample stands for the pixel, `1/n` for an `n x n` subsample).
#[inline]
fn shade_sample(scene: &Scene, dir: &Vector3<f64>, hit: Option<&Hit>, fx: f64, sub: f64) -> f32 {
    match hit {
        None => scene.sky(dir),
        Some(hit) => {
            let norm = dir.norm();
            let cos = (hit.normal.dot(dir).abs() / norm).max(0.2);
            let pixel_m = hit.t * norm / (fx * cos);
            scene.shade(hit, pixel_m, pixel_m * sub)
        }
    }
}

/// Renders a rectified stereo pair: (left, right) with the right camera `baseline_m` metres
/// along the left camera's +x axis.
#[must_use]
pub fn render_stereo(scene: &Scene, rig: &StereoCamera, world_from_left: &Pose) -> (View, View) {
    let world_from_right = world_from_left * Translation3::new(rig.baseline_m, 0.0, 0.0);
    let (left, right) = rayon::join(
        || render_view(scene, &rig.left, world_from_left),
        || render_view(scene, &rig.left, &world_from_right),
    );
    (left, right)
}

/// Ground-truth forward flow from view a (at `world_from_a`) to view b (see the module docs).
/// `_scene` is unused today (the flow follows from depth and poses) but keeps the signature
/// ready for moving objects.
#[must_use]
pub fn flow_between(
    _scene: &Scene,
    cam: &PinholeCamera,
    world_from_a: &Pose,
    view_a: &View,
    world_from_b: &Pose,
    view_b: &View,
) -> FlowGt {
    let w = cam.width as usize;
    let h = cam.height as usize;
    let b_from_a = world_from_b.inverse() * world_from_a;
    let mut flow = FlowField::zeros(w, h);
    let mut valid = vec![false; w * h];
    flow.uv
        .par_chunks_mut(2 * w.max(1))
        .zip(valid.par_chunks_mut(w.max(1)))
        .enumerate()
        .for_each(|(y, (flow_row, valid_row))| {
            for x in 0..w {
                let z_a = f64::from(view_a.depth_m[y * w + x]);
                let px = Point2::new(x as f64, y as f64);
                let ray = cam.ray(&px);
                // a point at depth z, or a direction (point at infinity) for the sky
                let (p_in_b, inv_depth_scale) = if z_a.is_finite() {
                    (b_from_a * Point3::from(ray * z_a), 1.0)
                } else {
                    (Point3::from(b_from_a.rotation * ray), 0.0)
                };
                let Some(target) = cam.project(&p_in_b) else {
                    flow_row[2 * x] = UNKNOWN_FLOW;
                    flow_row[2 * x + 1] = UNKNOWN_FLOW;
                    continue;
                };
                flow_row[2 * x] = (target.x - px.x) as f32;
                flow_row[2 * x + 1] = (target.y - px.y) as f32;
                let expected_inv_depth = inv_depth_scale / p_in_b.z;
                valid_row[x] = visible_in(view_b, &target, expected_inv_depth);
            }
        });
    FlowGt { flow, valid }
}

/// Whether a point projecting to `target` with inverse depth `inv_depth` (1/m, 0 at infinity)
/// is the surface seen in `view`: all four bilinear neighbours exist and the bilinearly
/// interpolated inverse depth agrees to 1 % (plus 1e-5 /m).
///
/// Not `visnav_core::bilinear::Bilinear`: it interpolates `1/depth` in `f64` from an `f32`
/// depth map and refuses the border (no clamping: a point whose neighbourhood leaves the view is
/// not visible there), which the ground-truth occlusion test needs.
fn visible_in(view: &View, target: &Point2<f64>, inv_depth: f64) -> bool {
    let w = view.image.width();
    let h = view.image.height();
    if !(target.x >= 0.0 && target.y >= 0.0) {
        return false;
    }
    let x0 = target.x.floor() as usize;
    let y0 = target.y.floor() as usize;
    if x0 + 1 >= w || y0 + 1 >= h {
        return false;
    }
    let fx = target.x - x0 as f64;
    let fy = target.y - y0 as f64;
    let inv = |x: usize, y: usize| 1.0 / f64::from(view.depth_m[y * w + x]);
    let top = inv(x0, y0) * (1.0 - fx) + inv(x0 + 1, y0) * fx;
    let bottom = inv(x0, y0 + 1) * (1.0 - fx) + inv(x0 + 1, y0 + 1) * fx;
    let interp = top * (1.0 - fy) + bottom * fy;
    (interp - inv_depth).abs() <= 0.01 * inv_depth + 1e-5
}

/// Backward warp: `out(p) = image_b(p + flow(p))` (bilinear), `None` where the flow is unknown
/// or leaves image b. Warping frame b by the flow a→b reproduces frame a on valid pixels.
#[must_use]
pub fn warp_by_flow(image_b: &GrayImage, flow: &FlowField) -> Vec<Option<f32>> {
    let w = flow.width;
    (0..flow.width * flow.height)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            if !flow.is_known(x, y) {
                return None;
            }
            let (u, v) = flow.get(x, y);
            image_b.bilinear(x as f64 + f64::from(u), y as f64 + f64::from(v))
        })
        .collect()
}

/// A camera with KITTI's field of view (the intrinsics of [`PinholeCamera::kitti_default`]
/// rescaled) at any image size, e.g. 320x96 for fast tests.
#[must_use]
pub fn kitti_like_camera(width: u32, height: u32) -> PinholeCamera {
    let k = PinholeCamera::kitti_default();
    let sx = f64::from(width) / f64::from(k.width);
    let sy = f64::from(height) / f64::from(k.height);
    PinholeCamera {
        fx: k.fx * sx,
        fy: k.fy * sy,
        cx: (k.cx + 0.5) * sx - 0.5,
        cy: (k.cy + 0.5) * sy - 0.5,
        width,
        height,
    }
}

/// KITTI's stereo baseline, metres.
pub const KITTI_BASELINE_M: f64 = 0.537;
