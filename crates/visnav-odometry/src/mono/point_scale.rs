//! The depth-ratio scale (§5) measured at the depth map's own points, in inverse depth.
//!
//! The paper scales a unit-translation triangulation by the ratio of the previous depth map to
//! it. Taking that ratio between two *filtered* triangulations biases it: a triangulation kept
//! only when its depth came out positive and certain relative to itself keeps the measurements
//! whose noise enlarged the parallax, so far points come out too near, and with few points left
//! the scale falls back to PnP, whose translation a noisy map shortens (errors in the
//! regressors). Here every known point of the map is measured where it lies: the flow is read
//! there by bilinear interpolation, the point's inverse depth is triangulated with no sign or
//! size filter ([`triangulate_inverse_depth`], zero-mean noise), and each point's scale
//! `s = d_map · ρ_unit` enters a median weighted by its inverse variance, which does not depend
//! on the measured value. The filter is the epipolar test only (noise across the epipolar line,
//! independent of the noise along it).

use nalgebra::{Matrix3, Point2};
use rayon::prelude::*;
use visnav_core::bilinear::Bilinear;
use visnav_core::{PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::Correspondence;
use visnav_geometry::fundamental::mahalanobis_distance_sq;
use visnav_geometry::triangulation::triangulate_inverse_depth;

use super::depth::DepthMap;

/// The scale of a unit-translation pose from the map's points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PointScale {
    /// Weighted median of the points' scales, metres per translation unit (`None` below the
    /// sample minimum).
    pub scale_m: Option<f64>,
    /// Points measured.
    pub points: usize,
}

/// The scale of `unit` (a unit-translation `cur_from_prev`) from the known points of `prior`
/// (the map in the first camera of the pair, metres): `(fundamental, threshold)` the epipolar
/// gate, `fundamental` `unit`'s and `threshold` the squared Mahalanobis bound, `scale_guess_m`
/// the expected scale (the previous translation length) for the weights' share of the map's
/// own variance.
pub(crate) fn scale_at_map_points(
    camera: &PinholeCamera,
    flow: &DenseFlow,
    prior: &DepthMap,
    unit: &Pose,
    (fundamental, threshold): (&Matrix3<f64>, f64),
    scale_guess_m: f64,
    min_samples: usize,
) -> PointScale {
    let mut samples: Vec<(f64, f64)> = (0..prior.depth_m.len())
        .into_par_iter()
        .filter_map(|i| {
            let (d, v) = prior.get(i)?;
            let c = correspondence_at_subpixel(flow, &prior.point_pixel(i))?;
            if mahalanobis_distance_sq(fundamental, &c) > threshold {
                return None;
            }
            let m = triangulate_inverse_depth(camera, unit, &c)?;
            let s = d * m.inverse_depth;
            let variance = d * d * m.variance + scale_guess_m * scale_guess_m * v / (d * d);
            (s.is_finite() && variance > 0.0).then(|| (s, 1.0 / variance))
        })
        .collect();
    let points = samples.len();
    let scale_m = if points >= min_samples.max(1) {
        weighted_median(&mut samples)
    } else {
        None
    };
    PointScale { scale_m, points }
}

/// The correspondence of the point at `p1` (sub-pixel, inside the image): the flow sampled
/// bilinearly ([`Bilinear`]) from the four pixels around it (all valid), the information of the
/// nearest.
fn correspondence_at_subpixel(flow: &DenseFlow, p1: &Point2<f64>) -> Option<Correspondence> {
    let sample = flow_at_subpixel(flow, p1)?;
    let c = Correspondence {
        p1_px: *p1,
        p2_px: sample.target_px,
        information: flow.information_at(sample.nearest).to_matrix(),
    };
    (c.certainty() > 0.0).then_some(c)
}

/// The flow at a sub-pixel point of image 1: bilinear ([`Bilinear`], the project's one
/// sampler), only where `p1_px` lies inside the image and all four neighbours are valid.
pub(crate) struct FlowSample {
    /// `p1_px` moved by the flow, pixels of image 2 (not checked against its bounds).
    pub target_px: Point2<f64>,
    /// Index of the neighbour nearest to `p1_px` (whose information describes the sample).
    pub nearest: usize,
}

/// [`FlowSample`] of `flow` at `p1_px`, `None` outside the image or next to an invalid pixel.
pub(crate) fn flow_at_subpixel(flow: &DenseFlow, p1_px: &Point2<f64>) -> Option<FlowSample> {
    let (w, h) = (flow.width, flow.height);
    let inside = p1_px.x >= 0.0 && p1_px.y >= 0.0;
    if !(inside && p1_px.x <= (w - 1) as f64 && p1_px.y <= (h - 1) as f64) {
        return None;
    }
    let s = Bilinear::clamped_f64(p1_px.x, p1_px.y, w, h);
    let corners = [s.i00, s.i00 + s.dx, s.i00 + s.dy, s.i00 + s.dy + s.dx];
    if corners.iter().any(|&i| !flow.valid[i]) {
        return None;
    }
    let [u, v] = s.sample(&flow.flow);
    Some(FlowSample {
        target_px: Point2::new(p1_px.x + f64::from(u), p1_px.y + f64::from(v)),
        nearest: corners[usize::from(s.fy >= 0.5) * 2 + usize::from(s.fx >= 0.5)],
    })
}

/// The weighted median of `(value, weight)` pairs (positive weights): the smallest value whose
/// cumulative weight reaches half the total.
fn weighted_median(samples: &mut [(f64, f64)]) -> Option<f64> {
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = samples.iter().map(|s| s.1).sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let mut acc = 0.0;
    samples.iter().find_map(|&(value, weight)| {
        acc += weight;
        (acc >= 0.5 * total).then_some(value)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A camera 30 m above flat ground, pitched 20° down, 1.5 m forward: the map of the ground
    /// (true depths at the cells' pixels, moved by a fraction of a pixel as a propagated map's
    /// are) against the flow of the step. Exact flow gives the step exactly; flow with 0.3 px
    /// of Gaussian noise gives it within 1 % (the far ground, up to 400 m, has under a pixel of
    /// parallax a frame).
    #[test]
    fn the_scale_at_the_map_points_is_the_step_length() {
        let cam = PinholeCamera::new(360.0, 360.0, 310.0, 94.0, 620, 188).unwrap();
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -20f64.to_radians());
        let world_from_cam = |z: f64| Pose::from_parts(Translation3::new(0.0, 0.0, z), pitch);
        let (prev, cur) = (world_from_cam(0.0), world_from_cam(1.5));
        let cur_from_prev = cur.inverse() * prev;
        let depth = |px: &Point2<f64>| {
            let ray = cam.unproject(px, 1.0).coords;
            let r = prev.rotation * ray;
            (r.y > 1e-6)
                .then(|| 30.0 / r.y * ray.z)
                .filter(|d| *d < 400.0)
        };
        let mut map = DepthMap::empty(620, 188, 4);
        for i in 0..map.depth_m.len() {
            let p = map.pixel_of(i);
            let off = [
                ((i * 7) % 5) as f64 * 0.3 - 0.6,
                ((i * 3) % 5) as f64 * 0.3 - 0.6,
            ];
            let q = Point2::new((p.x + off[0]).max(0.0), (p.y + off[1]).max(0.0));
            if let Some(d) = depth(&q) {
                map.set(i, d, 0.01 * d * d);
                map.offset_px[i] = [(q.x - p.x) as f32, (q.y - p.y) as f32];
            }
        }
        let flow_with = |sigma: f32| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let noise = Normal::new(0.0f32, sigma.max(1e-9)).unwrap();
            let (w, h) = (620, 188);
            let mut f = DenseFlow {
                width: w,
                height: h,
                flow: vec![[0.0; 2]; w * h],
                information: vec![[4.0, 0.0, 4.0]; w * h],
                valid: vec![false; w * h],
            };
            for y in 0..h {
                for x in 0..w {
                    let p1 = Point2::new(x as f64, y as f64);
                    let Some(d) = depth(&p1) else { continue };
                    let Some(p2) = cam.project(&(cur_from_prev * cam.unproject(&p1, d))) else {
                        continue;
                    };
                    let k = y * w + x;
                    let n = [noise.sample(&mut rng), noise.sample(&mut rng)];
                    let n = if sigma > 0.0 { n } else { [0.0; 2] };
                    f.flow[k] = [(p2.x - p1.x) as f32 + n[0], (p2.y - p1.y) as f32 + n[1]];
                    f.valid[k] = true;
                }
            }
            f
        };
        let mut unit = cur_from_prev;
        unit.translation.vector /= unit.translation.vector.norm();
        let f = crate::mono::correspondence::fundamental_of(&cam, &unit);
        for (sigma, tolerance) in [(0.0f32, 1e-3), (0.3, 0.01)] {
            let s = scale_at_map_points(&cam, &flow_with(sigma), &map, &unit, (&f, 1e9), 1.5, 30);
            let scale = s.scale_m.unwrap();
            eprintln!(
                "flow noise {sigma} px: scale {scale:.5} m from {} points",
                s.points
            );
            assert!(s.points > 3000, "{s:?}");
            assert!(
                (scale / 1.5 - 1.0).abs() < tolerance,
                "noise {sigma}: {scale}"
            );
        }
    }

    #[test]
    fn weighted_median_follows_the_weight() {
        let mut s = vec![(3.0, 1.0), (1.0, 1.0), (2.0, 1.0)];
        assert_eq!(weighted_median(&mut s), Some(2.0));
        let mut s = vec![(1.0, 5.0), (2.0, 1.0), (3.0, 1.0)];
        assert_eq!(weighted_median(&mut s), Some(1.0));
        assert_eq!(weighted_median(&mut []), None);
    }
}
