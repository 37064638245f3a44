//! Undistortion and stereo rectification: the rotations and the common pinhole camera that make
//! a calibrated pair row-aligned, and the remap maps that resample raw images into it.
//!
//! Stereo rectification follows Bouguet's construction as in OpenCV `stereoRectify` with
//! `CALIB_ZERO_DISPARITY` and `alpha = 0`: the relative rotation `right_from_left` is split in
//! half between the two cameras (`r_half = exp(-ω/2)`), then a common rotation turns the
//! half-rotated baseline onto the x axis. The new intrinsics are shared by both cameras
//! (`fx = fy`, same principal point) and chosen so that the rectified image, of the left raw
//! image's size, shows only valid pixels of both cameras (alpha = 0). Mono undistortion is the
//! same construction with the identity rotation and one camera.
//!
//! For a chosen output size, [`cropped_pinhole`] follows DSO's `crop` rectification (Engel et al.,
//! "Direct Sparse Odometry", the camera models of its `Undistort.cpp`): the centre lines are
//! stretched as far as they stay inside the raw image, then the sides of the normalised rectangle
//! are shrunk until its whole border maps inside the raw image; `fx` and `fy` may differ. It only
//! evaluates the forward distortion, so it also serves lenses whose corners see beyond 90° (the
//! TUM monoVO FOV cameras), where [`undistorted_pinhole`] cannot invert the distortion.
//! [`full_axes_pinhole`] keeps the whole centre lines of the raw image instead (no shrinking).
//!
//! Frames: `rect_from_cam` rotates camera-frame vectors into the rectified frame of that camera;
//! the rectified right camera sits `baseline_m` metres along the rectified left +x axis.

use nalgebra::{Point2, Rotation3, Vector3};

use crate::camera::{CameraError, PinholeCamera};
use crate::distortion::CalibratedCamera;
use crate::image::GrayImage;
use crate::se3::Pose;

/// Points sampled along each image border to find the valid rectified region.
const BORDER_SAMPLES: usize = 64;
/// Step of the outward walk along the centre lines, normalised units.
const AXIS_WALK_STEP: f64 = 1e-3;
/// Farthest normalised coordinate the centre-line walk reaches (≈ 87° off axis).
const AXIS_WALK_MAX: f64 = 20.0;
/// Initial enlargement and per-iteration shrink factor of [`cropped_pinhole`] (DSO's values).
const CROP_INITIAL_GROWTH: f64 = 1.01;
const CROP_SHRINK: f64 = 0.995;
/// Iterations of [`cropped_pinhole`] before it gives up.
const CROP_MAX_ITERATIONS: usize = 2000;
/// Largest relative rotation between the two cameras of a rectifiable pair, radians (60°).
const MAX_RELATIVE_ROTATION_RAD: f64 = std::f64::consts::FRAC_PI_3;

/// A rectified stereo pair: the rotation of each camera into its rectified frame and the common
/// rectified pinhole camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRectification {
    /// Rotation of left-camera vectors into the rectified left frame (OpenCV `R1`).
    pub left_rect_from_cam: Rotation3<f64>,
    /// Rotation of right-camera vectors into the rectified right frame (OpenCV `R2`).
    pub right_rect_from_cam: Rotation3<f64>,
    /// Intrinsics of both rectified images (size of the left raw image).
    pub rectified: PinholeCamera,
    /// Distance between the two optical centres, metres, along the rectified +x axis.
    pub baseline_m: f64,
}

/// Rectifies a calibrated stereo pair (Bouguet; module doc). `right_from_left` maps points of
/// the left camera frame into the right camera frame (metres).
///
/// # Errors
/// [`CameraError::NotRectifiable`] when the images differ in size, the baseline is not mostly
/// horizontal or the right camera is not to the right of the left one, the cameras are rotated
/// by more than 60° against each other, or the two views share no valid region.
pub fn stereo_rectify(
    left: &CalibratedCamera,
    right: &CalibratedCamera,
    right_from_left: &Pose,
) -> Result<StereoRectification, CameraError> {
    let not = |reason: String| CameraError::NotRectifiable { reason };
    if (left.pinhole.width, left.pinhole.height) != (right.pinhole.width, right.pinhole.height) {
        return Err(not(format!(
            "the cameras' images differ in size ({}x{} and {}x{})",
            left.pinhole.width, left.pinhole.height, right.pinhole.width, right.pinhole.height
        )));
    }
    let rotation = right_from_left.rotation.to_rotation_matrix();
    let omega = rotation.scaled_axis();
    if omega.norm() > MAX_RELATIVE_ROTATION_RAD {
        return Err(not(format!(
            "the cameras are rotated by {:.1}° against each other (at most 60° is supported)",
            omega.norm().to_degrees()
        )));
    }
    let t = right_from_left.translation.vector;
    if !(t.norm().is_finite() && t.norm() > 1e-9) {
        return Err(not("the baseline is zero".into()));
    }
    // half rotation each: right_half_from_left = r_half, left_half_from_right = r_halfᵀ
    let r_half = Rotation3::new(-omega * 0.5);
    let t_half = r_half * t;
    if t_half.x.abs() <= t_half.y.abs() {
        return Err(not(format!(
            "the baseline ({:.4}, {:.4}, {:.4}) m is not horizontal: only left-right pairs are supported",
            t.x, t.y, t.z
        )));
    }
    if t_half.x >= 0.0 {
        return Err(not(
            "the second camera is left of the first one: swap the cameras (the first must be the left)"
                .into(),
        ));
    }
    // rotate the baseline onto -x (right camera at +x of the left one)
    let target = Vector3::new(-1.0, 0.0, 0.0);
    let axis = t_half.cross(&target);
    let angle = (t_half.x.abs() / t_half.norm()).clamp(-1.0, 1.0).acos();
    let w_r = if axis.norm() > 1e-15 {
        Rotation3::new(axis.normalize() * angle)
    } else {
        Rotation3::identity()
    };
    let left_rect_from_cam = w_r * r_half.inverse();
    let right_rect_from_cam = w_r * r_half;
    let baseline_m = -(right_rect_from_cam * t).x;
    let rectified = common_pinhole(&[(left, left_rect_from_cam), (right, right_rect_from_cam)])?;
    Ok(StereoRectification {
        left_rect_from_cam,
        right_rect_from_cam,
        rectified,
        baseline_m,
    })
}

/// The undistorted pinhole camera of a single camera (no rotation, alpha = 0: every pixel of the
/// undistorted image is seen by the raw image).
///
/// # Errors
/// [`CameraError::NotRectifiable`] when the distortion leaves no valid region.
pub fn undistorted_pinhole(camera: &CalibratedCamera) -> Result<PinholeCamera, CameraError> {
    common_pinhole(&[(camera, Rotation3::identity())])
}

/// The normalised extent `(x_lo, x_hi, y_lo, y_hi)` of the raw image's centre lines: how far the
/// ideal ray can move left, right, up and down from the optical axis while its distorted pixel
/// stays inside the raw image (bisected to 1e-12 after a walk in [`AXIS_WALK_STEP`] steps, capped
/// at [`AXIS_WALK_MAX`]).
fn centre_line_extent(camera: &CalibratedCamera) -> Result<[f64; 4], CameraError> {
    let (w, h) = (
        f64::from(camera.pinhole.width) - 1.0,
        f64::from(camera.pinhole.height) - 1.0,
    );
    let inside = |dir: (f64, f64), t: f64| {
        let px = camera.distort_normalized(&Point2::new(dir.0 * t, dir.1 * t));
        if dir.0 == 0.0 {
            (0.0..=h).contains(&px.y)
        } else {
            (0.0..=w).contains(&px.x)
        }
    };
    if !camera
        .pinhole
        .contains(&Point2::new(camera.pinhole.cx, camera.pinhole.cy), 0.0)
    {
        return Err(CameraError::NotRectifiable {
            reason: format!(
                "the principal point ({:.1}, {:.1}) lies outside the {}x{} image",
                camera.pinhole.cx, camera.pinhole.cy, camera.pinhole.width, camera.pinhole.height
            ),
        });
    }
    let mut extent = [0.0; 4];
    for (e, dir) in extent
        .iter_mut()
        .zip([(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)])
    {
        let mut lo = 0.0;
        let mut hi = None;
        let mut t = AXIS_WALK_STEP;
        while t <= AXIS_WALK_MAX {
            if !inside(dir, t) {
                hi = Some(t);
                break;
            }
            lo = t;
            t += AXIS_WALK_STEP;
        }
        if let Some(mut hi) = hi {
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if inside(dir, mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        *e = if dir.0 + dir.1 < 0.0 { -lo } else { lo };
    }
    if extent[0] >= extent[1] || extent[2] >= extent[3] {
        return Err(CameraError::NotRectifiable {
            reason: "the centre lines of the image have no extent".into(),
        });
    }
    Ok(extent)
}

/// The pinhole camera of a `width` x `height` output whose pixel grid spans the normalised
/// rectangle `[x_lo, x_hi] x [y_lo, y_hi]` (pixel 0 and `width - 1` on its sides).
fn pinhole_of_rectangle(
    [x_lo, x_hi, y_lo, y_hi]: [f64; 4],
    width: u32,
    height: u32,
) -> Result<PinholeCamera, CameraError> {
    let fx = (f64::from(width) - 1.0) / (x_hi - x_lo);
    let fy = (f64::from(height) - 1.0) / (y_hi - y_lo);
    PinholeCamera::new(fx, fy, -x_lo * fx, -y_lo * fy, width, height)
}

/// DSO's `crop` output camera of size `width` x `height` (module doc): the largest normalised
/// rectangle around the optical axis, found by shrinking the centre lines' extent, whose border
/// maps inside the raw image. Every output pixel then reads a raw pixel.
///
/// # Errors
/// [`CameraError::NotRectifiable`] when the principal point lies outside the raw image, the
/// output is smaller than 2x2 pixels, or no valid rectangle is found.
pub fn cropped_pinhole(
    camera: &CalibratedCamera,
    width: u32,
    height: u32,
) -> Result<PinholeCamera, CameraError> {
    check_output_size(width, height)?;
    let mut r = centre_line_extent(camera)?.map(|e| e * CROP_INITIAL_GROWTH);
    let (w_raw, h_raw) = (
        f64::from(camera.pinhole.width) - 1.0,
        f64::from(camera.pinhole.height) - 1.0,
    );
    for _ in 0..CROP_MAX_ITERATIONS {
        let [x_lo, x_hi, y_lo, y_hi] = r;
        // [left, right, top, bottom]: the side has a border point outside the raw image
        let mut out = [false; 4];
        for k in 0..height {
            let y = y_lo + (y_hi - y_lo) * f64::from(k) / (f64::from(height) - 1.0);
            for (side, x) in [(0, x_lo), (1, x_hi)] {
                let px = camera.distort_normalized(&Point2::new(x, y));
                out[side] |= !(0.0..=w_raw).contains(&px.x);
            }
        }
        for k in 0..width {
            let x = x_lo + (x_hi - x_lo) * f64::from(k) / (f64::from(width) - 1.0);
            for (side, y) in [(2, y_lo), (3, y_hi)] {
                let px = camera.distort_normalized(&Point2::new(x, y));
                out[side] |= !(0.0..=h_raw).contains(&px.y);
            }
        }
        if out == [false; 4] {
            return pinhole_of_rectangle(r, width, height);
        }
        // both directions out: shrink the wider one only (DSO)
        if (out[0] || out[1]) && (out[2] || out[3]) {
            if x_hi - x_lo > y_hi - y_lo {
                out[2] = false;
                out[3] = false;
            } else {
                out[0] = false;
                out[1] = false;
            }
        }
        for (e, o) in r.iter_mut().zip(out) {
            if o {
                *e *= CROP_SHRINK;
            }
        }
    }
    Err(CameraError::NotRectifiable {
        reason: format!(
            "no cropped rectangle maps inside the raw image after {CROP_MAX_ITERATIONS} iterations"
        ),
    })
}

/// A `full` output camera of size `width` x `height`: the output's centre lines span the raw
/// image's centre lines from border to border (DSO leaves `full` unimplemented; this is visnav's
/// choice). With barrel distortion the output corners still read raw pixels; with pincushion
/// distortion they may fall outside the raw image and stay black.
///
/// # Errors
/// As [`cropped_pinhole`].
pub fn full_axes_pinhole(
    camera: &CalibratedCamera,
    width: u32,
    height: u32,
) -> Result<PinholeCamera, CameraError> {
    check_output_size(width, height)?;
    pinhole_of_rectangle(centre_line_extent(camera)?, width, height)
}

fn check_output_size(width: u32, height: u32) -> Result<(), CameraError> {
    if width < 2 || height < 2 {
        return Err(CameraError::NotRectifiable {
            reason: format!("the output size {width}x{height} must be at least 2x2 pixels"),
        });
    }
    Ok(())
}

/// The largest-magnification pinhole (fx = fy) whose image of the first camera's size lies inside
/// the valid rectified region of every camera (OpenCV alpha = 0).
fn common_pinhole(
    cameras: &[(&CalibratedCamera, Rotation3<f64>)],
) -> Result<PinholeCamera, CameraError> {
    let not = |reason: String| CameraError::NotRectifiable { reason };
    let (w, h) = (cameras[0].0.pinhole.width, cameras[0].0.pinhole.height);
    let (wf, hf) = (f64::from(w) - 1.0, f64::from(h) - 1.0);
    let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (f64::MIN, f64::MAX, f64::MIN, f64::MAX);
    for (cam, rect_from_cam) in cameras {
        let (cw, ch) = (
            f64::from(cam.pinhole.width) - 1.0,
            f64::from(cam.pinhole.height) - 1.0,
        );
        for k in 0..=BORDER_SAMPLES {
            let s = k as f64 / BORDER_SAMPLES as f64;
            let rect = |px: Point2<f64>| -> Result<Point2<f64>, CameraError> {
                let x = cam.undistort_px(&px).ok_or_else(|| {
                    not(format!(
                        "the distortion model cannot be inverted at pixel ({:.0}, {:.0})",
                        px.x, px.y
                    ))
                })?;
                let ray = rect_from_cam * Vector3::new(x.x, x.y, 1.0);
                if ray.z <= 1e-6 {
                    return Err(not("a border ray points behind the rectified camera".into()));
                }
                Ok(Point2::new(ray.x / ray.z, ray.y / ray.z))
            };
            x_lo = x_lo.max(rect(Point2::new(0.0, s * ch))?.x);
            x_hi = x_hi.min(rect(Point2::new(cw, s * ch))?.x);
            y_lo = y_lo.max(rect(Point2::new(s * cw, 0.0))?.y);
            y_hi = y_hi.min(rect(Point2::new(s * cw, ch))?.y);
        }
    }
    if !(x_hi > x_lo && y_hi > y_lo) {
        return Err(not(
            "the views share no valid region after rectification".into()
        ));
    }
    let f = (wf / (x_hi - x_lo)).max(hf / (y_hi - y_lo));
    let cx = wf / 2.0 - f * (x_lo + x_hi) / 2.0;
    let cy = hf / 2.0 - f * (y_lo + y_hi) / 2.0;
    PinholeCamera::new(f, f, cx, cy, w, h)
}

/// A per-pixel resampling map: for each pixel of the output (rectified or undistorted) image,
/// the raw-image pixel to sample (NaN where no raw pixel projects). Built once per sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct RemapMap {
    width: usize,
    height: usize,
    src_u_px: Vec<f32>,
    src_v_px: Vec<f32>,
    raw_width: usize,
    raw_height: usize,
}

impl RemapMap {
    /// The map from the `rectified` pinhole image to the raw image of `camera`, for the rotation
    /// `rect_from_cam` (identity for plain undistortion).
    #[must_use]
    pub fn new(
        camera: &CalibratedCamera,
        rect_from_cam: &Rotation3<f64>,
        rectified: &PinholeCamera,
    ) -> Self {
        let (width, height) = (rectified.width as usize, rectified.height as usize);
        let mut src_u_px = Vec::with_capacity(width * height);
        let mut src_v_px = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                let p = source_px(
                    camera,
                    rect_from_cam,
                    rectified,
                    &Point2::new(u as f64, v as f64),
                );
                let (su, sv) = p.map_or((f32::NAN, f32::NAN), |p| (p.x as f32, p.y as f32));
                src_u_px.push(su);
                src_v_px.push(sv);
            }
        }
        Self {
            width,
            height,
            src_u_px,
            src_v_px,
            raw_width: camera.pinhole.width as usize,
            raw_height: camera.pinhole.height as usize,
        }
    }

    /// Size of the raw images this map reads, `(width, height)`.
    #[must_use]
    pub fn raw_size(&self) -> (usize, usize) {
        (self.raw_width, self.raw_height)
    }

    /// The raw pixel sampled for output pixel `(u, v)`, `None` outside the map or where no raw
    /// pixel projects.
    #[must_use]
    pub fn source(&self, u: usize, v: usize) -> Option<Point2<f64>> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let i = v * self.width + u;
        let (su, sv) = (self.src_u_px[i], self.src_v_px[i]);
        (su.is_finite() && sv.is_finite()).then(|| Point2::new(f64::from(su), f64::from(sv)))
    }

    /// Resamples a raw image (bilinear; border pixels clamped, 0 where nothing projects). The
    /// caller checks that `raw` has [`Self::raw_size`].
    #[must_use]
    pub fn apply(&self, raw: &GrayImage) -> GrayImage {
        let mut data = Vec::with_capacity(self.width * self.height);
        for (&su, &sv) in self.src_u_px.iter().zip(&self.src_v_px) {
            data.push(if su.is_finite() && sv.is_finite() {
                raw.bilinear_clamped(f64::from(su), f64::from(sv))
            } else {
                0.0
            });
        }
        GrayImage::from_vec(self.width, self.height, data)
            .unwrap_or_else(|| GrayImage::new(self.width, self.height, 0.0))
    }
}

/// The raw pixel of `camera` seen at pixel `px_rect` of the rectified camera.
#[must_use]
pub fn source_px(
    camera: &CalibratedCamera,
    rect_from_cam: &Rotation3<f64>,
    rectified: &PinholeCamera,
    px_rect: &Point2<f64>,
) -> Option<Point2<f64>> {
    let ray_cam = rect_from_cam.inverse() * rectified.ray(px_rect);
    if ray_cam.z <= 1e-9 {
        return None;
    }
    Some(camera.distort_normalized(&Point2::new(ray_cam.x / ray_cam.z, ray_cam.y / ray_cam.z)))
}

/// The rectified pixel of a raw pixel of `camera` (undistort, rotate, project); `None` where
/// the model cannot be inverted or the ray points behind the rectified camera.
#[must_use]
pub fn rectify_px(
    camera: &CalibratedCamera,
    rect_from_cam: &Rotation3<f64>,
    rectified: &PinholeCamera,
    px_raw: &Point2<f64>,
) -> Option<Point2<f64>> {
    let x = camera.undistort_px(px_raw)?;
    let ray = rect_from_cam * Vector3::new(x.x, x.y, 1.0);
    rectified.project(&nalgebra::Point3::from(ray))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distortion::Distortion;
    use nalgebra::{Point3, Translation3, UnitQuaternion};

    fn cam(fx: f64, cx: f64, distortion: Distortion) -> CalibratedCamera {
        CalibratedCamera {
            pinhole: PinholeCamera::new(fx, fx * 1.002, cx, 241.0, 752, 480).unwrap(),
            distortion,
        }
    }

    /// A pair like EuRoC's: different intrinsics and distortion, a few degrees of relative
    /// rotation, an 11 cm baseline with small y and z components.
    fn synthetic_pair() -> (CalibratedCamera, CalibratedCamera, Pose) {
        let left = cam(
            458.0,
            367.0,
            Distortion::RadialTangential {
                k1: -0.28,
                k2: 0.07,
                p1: 2e-4,
                p2: 2e-5,
                k3: 0.0,
            },
        );
        let right = cam(
            457.0,
            379.0,
            Distortion::RadialTangential {
                k1: -0.29,
                k2: 0.08,
                p1: -6e-5,
                p2: -1e-5,
                k3: 0.0,
            },
        );
        let right_from_left = Pose::from_parts(
            Translation3::new(-0.110, 0.0004, -0.0009),
            UnitQuaternion::from_euler_angles(0.02, -0.035, 0.015),
        );
        (left, right, right_from_left)
    }

    #[test]
    fn rectified_epipolar_lines_are_horizontal() {
        let (left, right, right_from_left) = synthetic_pair();
        let rect = stereo_rectify(&left, &right, &right_from_left).unwrap();
        assert!((rect.baseline_m - right_from_left.translation.vector.norm()).abs() < 1e-12);
        let mut checked = 0;
        // a grid of 3-D points at several depths, seen by both raw cameras
        for ix in -6..=6 {
            for iy in -4..=4 {
                for z_m in [1.5, 4.0, 12.0] {
                    let p_in_left =
                        Point3::new(f64::from(ix) * 0.1 * z_m, f64::from(iy) * 0.1 * z_m, z_m);
                    let p_in_right = right_from_left * p_in_left;
                    let (Some(l_raw), Some(r_raw)) =
                        (left.project(&p_in_left), right.project(&p_in_right))
                    else {
                        continue;
                    };
                    if !(left.pinhole.contains(&l_raw, 0.0) && right.pinhole.contains(&r_raw, 0.0))
                    {
                        continue;
                    }
                    let l = rectify_px(&left, &rect.left_rect_from_cam, &rect.rectified, &l_raw)
                        .unwrap();
                    let r = rectify_px(&right, &rect.right_rect_from_cam, &rect.rectified, &r_raw)
                        .unwrap();
                    assert!(
                        (l.y - r.y).abs() < 0.1,
                        "epipolar offset {} px at {p_in_left}",
                        l.y - r.y
                    );
                    // the disparity gives back the depth along the rectified axis
                    let z_rect = (rect.left_rect_from_cam * p_in_left.coords).z;
                    let d = l.x - r.x;
                    assert!(
                        (rect.rectified.fx * rect.baseline_m / d - z_rect).abs() < 1e-6 * z_rect
                    );
                    // the remap map samples the raw pixel that rectifies to this one
                    let back =
                        source_px(&left, &rect.left_rect_from_cam, &rect.rectified, &l).unwrap();
                    assert!(nalgebra::distance(&back, &l_raw) < 1e-6);
                    checked += 1;
                }
            }
        }
        assert!(checked > 100, "only {checked} points checked");
    }

    #[test]
    fn alpha_zero_maps_only_valid_pixels() {
        let (left, right, right_from_left) = synthetic_pair();
        let rect = stereo_rectify(&left, &right, &right_from_left).unwrap();
        for (c, r) in [
            (&left, rect.left_rect_from_cam),
            (&right, rect.right_rect_from_cam),
        ] {
            let map = RemapMap::new(c, &r, &rect.rectified);
            let (w, h) = (
                rect.rectified.width as usize,
                rect.rectified.height as usize,
            );
            let mut inside = 0usize;
            for v in 0..h {
                for u in 0..w {
                    let s = map.source(u, v).unwrap();
                    if c.pinhole.contains(&s, -0.5) {
                        inside += 1;
                    }
                }
            }
            // every rectified pixel reads the raw image (up to the border sampling's slack)
            assert!(
                inside as f64 > 0.999 * (w * h) as f64,
                "{inside} of {}",
                w * h
            );
        }
        // the raw image resamples into the rectified size; a constant image stays constant
        let map = RemapMap::new(&left, &rect.left_rect_from_cam, &rect.rectified);
        let out = map.apply(&GrayImage::new(752, 480, 100.0));
        assert_eq!((out.width(), out.height()), (752, 480));
        assert!(out.data().iter().all(|&x| (x - 100.0).abs() < 1e-3));
    }

    #[test]
    fn undistortion_without_distortion_is_identity() {
        let c = cam(450.0, 375.5, Distortion::None);
        let pin = undistorted_pinhole(&c).unwrap();
        assert!((pin.fx - c.pinhole.fx.max(c.pinhole.fy)).abs() < 1e-6 * pin.fx);
        let map = RemapMap::new(&c, &Rotation3::identity(), &pin);
        let s = map.source(375, 241).unwrap();
        assert!(
            nalgebra::distance(&s, &Point2::new(375.0, 241.0)) < 0.01,
            "{s}"
        );
    }

    /// A TUM monoVO-like FOV camera (sequence 01's relative calibration) at 320x256.
    fn fov_camera() -> CalibratedCamera {
        let (w, h) = (320.0, 256.0);
        CalibratedCamera {
            pinhole: PinholeCamera::new(
                0.349_153 * w,
                0.436_593 * h,
                0.493_140 * w - 0.5,
                0.499_021 * h - 0.5,
                320,
                256,
            )
            .unwrap(),
            distortion: Distortion::Fov { omega: 0.933_271 },
        }
    }

    #[test]
    fn crop_reads_only_raw_pixels_and_touches_the_border() {
        let c = fov_camera();
        // the corners of this lens see beyond 90°: the alpha = 0 construction cannot invert them
        assert!(undistorted_pinhole(&c).is_err());
        let out = cropped_pinhole(&c, 160, 120).unwrap();
        assert_eq!((out.width, out.height), (160, 120));
        let map = RemapMap::new(&c, &Rotation3::identity(), &out);
        let mut margin = f64::MAX;
        for v in 0..120 {
            for u in 0..160 {
                let s = map.source(u, v).unwrap();
                assert!(c.pinhole.contains(&s, -1e-3), "({u}, {v}) reads {s}");
                margin = margin.min(s.x).min(s.y).min(319.0 - s.x).min(255.0 - s.y);
            }
        }
        // as large as allowed: one shrink step (0.5 %) from the raw border
        assert!(margin < 2.0, "{margin} px from the border");
        // the full output spans the raw centre lines from border to border
        let full = full_axes_pinhole(&c, 160, 120).unwrap();
        assert!(full.fx < out.fx && full.fy < out.fy);
        let at = |u: f64, v: f64| source_px(&c, &Rotation3::identity(), &full, &Point2::new(u, v));
        let (l, r) = (at(0.0, full.cy).unwrap(), at(159.0, full.cy).unwrap());
        let (t, b) = (at(full.cx, 0.0).unwrap(), at(full.cx, 119.0).unwrap());
        assert!(l.x.abs() < 1e-6 && (r.x - 319.0).abs() < 1e-6, "{l} {r}");
        assert!(t.y.abs() < 1e-6 && (b.y - 255.0).abs() < 1e-6, "{t} {b}");
        // a principal point outside the image is an error, as is a 1-pixel output
        let mut off = c;
        off.pinhole.cx = -10.0;
        assert!(cropped_pinhole(&off, 160, 120).is_err());
        assert!(cropped_pinhole(&c, 1, 120).is_err());
    }

    #[test]
    fn non_rectifiable_pairs_are_errors() {
        let (left, right, right_from_left) = synthetic_pair();
        // vertical baseline
        let vertical =
            Pose::from_parts(Translation3::new(0.0, -0.1, 0.0), right_from_left.rotation);
        let e = stereo_rectify(&left, &right, &vertical)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not horizontal"), "{e}");
        // cameras swapped
        let e = stereo_rectify(&right, &left, &right_from_left.inverse())
            .unwrap_err()
            .to_string();
        assert!(e.contains("swap"), "{e}");
        // cameras looking 90° apart
        let turned = Pose::from_parts(
            right_from_left.translation,
            UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0),
        );
        assert!(stereo_rectify(&left, &right, &turned).is_err());
        // different image sizes
        let mut small = right;
        small.pinhole.width = 640;
        let e = stereo_rectify(&left, &small, &right_from_left)
            .unwrap_err()
            .to_string();
        assert!(e.contains("differ in size"), "{e}");
    }
}
