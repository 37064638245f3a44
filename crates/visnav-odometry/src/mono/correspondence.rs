//! The dense flow as correspondences (§5 step 1) and the measurements taken on them: the grid
//! subsampling by certainty, the flow magnitude's percentile of the parallax test, the
//! translational parallax, and the fundamental matrix of a relative pose.

use nalgebra::{Matrix3, Point2, Point3, UnitQuaternion};
use rayon::prelude::*;
use visnav_core::se3::skew;
use visnav_core::{PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::Correspondence;

/// The correspondence of pixel `(x, y)` if its flow is valid, lands inside the image and has a
/// positive-definite information matrix.
pub(super) fn correspondence_at(flow: &DenseFlow, x: usize, y: usize) -> Option<Correspondence> {
    let i = y * flow.width + x;
    if !flow.valid[i] {
        return None;
    }
    let [u, v] = flow.flow[i];
    let (x2, y2) = (x as f64 + f64::from(u), y as f64 + f64::from(v));
    if !(x2 >= 0.0 && y2 >= 0.0 && x2 <= (flow.width - 1) as f64 && y2 <= (flow.height - 1) as f64)
    {
        return None;
    }
    let c = Correspondence {
        p1_px: Point2::new(x as f64, y as f64),
        p2_px: Point2::new(x2, y2),
        information: flow.information_at(i).to_matrix(),
    };
    (c.certainty() > 0.0).then_some(c)
}

/// Grid subsampling of dense flow: in each `cell_px` x `cell_px` cell, the valid pixel of
/// highest certainty `sqrt(det Y)` (ties: the first in row-major order).
#[must_use]
pub fn correspondences_from_flow(flow: &DenseFlow, cell_px: usize) -> Vec<Correspondence> {
    let cell = cell_px.max(1);
    let cols = flow.width.div_ceil(cell);
    let rows = flow.height.div_ceil(cell);
    (0..rows)
        .into_par_iter()
        .flat_map_iter(|cy| {
            (0..cols).filter_map(move |cx| {
                let mut best: Option<Correspondence> = None;
                for y in cy * cell..((cy + 1) * cell).min(flow.height) {
                    for x in cx * cell..((cx + 1) * cell).min(flow.width) {
                        if let Some(c) = correspondence_at(flow, x, y)
                            && best.as_ref().is_none_or(|b| c.certainty() > b.certainty())
                        {
                            best = Some(c);
                        }
                    }
                }
                best
            })
        })
        .collect()
}

/// The `q`-quantile (0..1) of the magnitude of the valid flow, pixels (every other pixel in
/// both directions); 0 without valid flow.
#[must_use]
pub fn flow_percentile_px(flow: &DenseFlow, q: f64) -> f64 {
    let mut mags: Vec<f32> = (0..flow.height)
        .step_by(2)
        .flat_map(|y| (0..flow.width).step_by(2).map(move |x| y * flow.width + x))
        .filter(|&i| flow.valid[i])
        .map(|i| flow.flow[i][0].hypot(flow.flow[i][1]))
        .collect();
    if mags.is_empty() {
        return 0.0;
    }
    let k = ((mags.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    f64::from(*mags.select_nth_unstable_by(k, f32::total_cmp).1)
}

/// Median translational parallax of `corrs`, pixels: `‖p₂ − π(R K⁻¹ p̃₁)‖`, i.e. the displacement
/// left after the rotation `cur_from_prev_rotation` is removed through the infinite homography
/// `K R K⁻¹` (points at infinity move by the rotation alone). Near zero when the camera stands
/// still or rotates on the spot, where the eight-point translation direction is undefined and a
/// triangulation has no baseline. `None` without correspondences.
#[must_use]
pub fn translational_parallax_px(
    camera: &PinholeCamera,
    corrs: &[Correspondence],
    cur_from_prev_rotation: &UnitQuaternion<f64>,
) -> Option<f64> {
    let mut residuals: Vec<f64> = corrs
        .iter()
        .filter_map(|c| {
            let ray_in_cur = cur_from_prev_rotation * camera.ray(&c.p1_px);
            camera
                .project(&Point3::from(ray_in_cur))
                .map(|px| (c.p2_px - px).norm())
        })
        .collect();
    median(&mut residuals)
}

/// The median of `values` (reordered; the upper one of an even count); `None` when empty.
pub(super) fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    Some(*values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The fundamental matrix of a relative pose: `F = K⁻ᵀ [t]ₓ R K⁻¹`.
pub(crate) fn fundamental_of(camera: &PinholeCamera, cur_from_prev: &Pose) -> Matrix3<f64> {
    let k_inv = camera.k_inv();
    let e = skew(&cur_from_prev.translation.vector)
        * cur_from_prev.rotation.to_rotation_matrix().matrix();
    k_inv.transpose() * e * k_inv
}

/// A dense flow of `w` x `h` pixels whose pixel `(x, y)` has the flow, information
/// `[a, b, c]` and validity `f(x, y)` (tests).
#[cfg(test)]
pub(super) fn flow_of(
    w: usize,
    h: usize,
    f: impl Fn(usize, usize) -> ([f32; 2], [f32; 3], bool),
) -> DenseFlow {
    let mut flow = Vec::new();
    let mut information = Vec::new();
    let mut valid = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (uv, info, ok) = f(x, y);
            flow.push(uv);
            information.push(info);
            valid.push(ok);
        }
    }
    DenseFlow {
        width: w,
        height: h,
        flow,
        information,
        valid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_keeps_the_most_certain_valid_pixel_per_cell() {
        // certainty grows with x inside each 4-px cell; pixel x%4 == 3 is invalid
        let flow = flow_of(16, 8, |x, _| {
            let c = 1.0 + (x % 4) as f32;
            ([1.0, 0.5], [c, 0.0, c], x % 4 != 3)
        });
        let corrs = correspondences_from_flow(&flow, 4);
        assert_eq!(corrs.len(), 8);
        assert!(corrs.iter().all(|c| c.p1_px.x as usize % 4 == 2));
        assert!(
            corrs
                .iter()
                .all(|c| (c.p2_px - c.p1_px - nalgebra::Vector2::new(1.0, 0.5)).norm() < 1e-9)
        );
        // flow leaving the image is dropped
        let out = flow_of(8, 8, |_, _| ([100.0, 0.0], [1.0, 0.0, 1.0], true));
        assert!(correspondences_from_flow(&out, 4).is_empty());
    }

    #[test]
    fn translational_parallax_vanishes_under_pure_rotation() {
        let cam = PinholeCamera::new(500.0, 500.0, 320.0, 240.0, 640, 480).unwrap();
        let rotation = UnitQuaternion::from_euler_angles(0.01, 0.05, -0.02);
        let corr = |p_in_prev: Point3<f64>, cur_from_prev: &Pose| Correspondence {
            p1_px: cam.project(&p_in_prev).unwrap(),
            p2_px: cam.project(&(cur_from_prev * p_in_prev)).unwrap(),
            information: nalgebra::Matrix2::identity(),
        };
        let points: Vec<Point3<f64>> = (0..50)
            .map(|i| {
                let i = f64::from(i);
                Point3::new((i * 0.37).sin() * 3.0, (i * 0.71).cos(), 5.0 + i * 0.3)
            })
            .collect();
        let spin = Pose::from_parts(nalgebra::Translation3::identity(), rotation);
        let corrs: Vec<Correspondence> = points.iter().map(|p| corr(*p, &spin)).collect();
        // large flow (the rotation moves every pixel by ~25 px), no translational parallax
        assert!(corrs.iter().all(|c| (c.p2_px - c.p1_px).norm() > 10.0));
        let tp = translational_parallax_px(&cam, &corrs, &rotation).unwrap();
        assert!(tp < 1e-9, "{tp}");
        // the same rotation with 0.5 m forward motion: parallax of several pixels
        let drive = Pose::from_parts(nalgebra::Translation3::new(0.0, 0.0, -0.5), rotation);
        let corrs: Vec<Correspondence> = points.iter().map(|p| corr(*p, &drive)).collect();
        let tp = translational_parallax_px(&cam, &corrs, &rotation).unwrap();
        assert!(tp > 2.0, "{tp}");
        assert!(translational_parallax_px(&cam, &[], &rotation).is_none());
    }

    #[test]
    fn flow_percentile_ignores_invalid_pixels() {
        let flow = flow_of(20, 20, |x, y| {
            let m = (x + 20 * y) as f32 * 0.01;
            ([m, 0.0], [1.0, 0.0, 1.0], y < 10)
        });
        let p75 = flow_percentile_px(&flow, 0.75);
        // valid rows 0..10 (even), magnitudes 0..~1.98, 75th percentile ≈ 1.4
        assert!(p75 > 1.2 && p75 < 1.6, "{p75}");
        let none = flow_of(4, 4, |_, _| ([9.0, 0.0], [1.0, 0.0, 1.0], false));
        assert!(flow_percentile_px(&none, 0.75).abs() < 1e-12);
    }
}
