//! Triangulation of a correspondence with uncertainty in the second image only.
//!
//! With `p1_px` exact (dense flow), the 3-D point lies on the ray of `p1_px`: `X(z) = z K⁻¹ x1`
//! in camera 1, `z` its depth (metres in the reconstruction's units). The depth minimising the
//! squared Mahalanobis reprojection error in image 2, `r(z)ᵀ Y r(z)` with `r = p2 − π(R X(z) + t)`,
//! is found from the linear (cross-product) solution by Gauss–Newton. First-order propagation of
//! the flow covariance `Y⁻¹` gives the depth variance `σ_z² = 1 / (Jᵀ Y J)`, `J = ∂π/∂z`. When the
//! reconstruction is scaled by `s` (§5), depth scales by `s` and its variance by `s²`.

use nalgebra::{Point2, Point3, Vector2, Vector3};
use visnav_core::{PinholeCamera, Pose};

use crate::correspondence::Correspondence;

/// A triangulated correspondence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriangulatedPoint {
    /// The point in camera 1.
    pub p_in_cam1: Point3<f64>,
    /// Depth along camera 1's optical axis (`p_in_cam1.z`).
    pub depth: f64,
    /// First-order variance of `depth` from the flow's information matrix (depth units²).
    pub depth_variance: f64,
    /// Squared Mahalanobis reprojection error in image 2 at the solution.
    pub reprojection_sq: f64,
}

/// Linear depth along the ray `r1` (camera 1) from `r2 × (z R r1 + t) = 0`; also returns the
/// sine-like parallax `|r2 × R r1|` (normalised rays). `None` without parallax.
#[must_use]
pub fn linear_depth(r1: &Vector3<f64>, r2: &Vector3<f64>, cam2_from_cam1: &Pose) -> Option<f64> {
    let a = cam2_from_cam1.rotation * r1;
    let t = cam2_from_cam1.translation.vector;
    let ra = r2.cross(&a);
    let rt = r2.cross(&t);
    let den = ra.norm_squared();
    if den < 1e-14 * a.norm_squared() * r2.norm_squared() {
        return None;
    }
    let z = -ra.dot(&rt) / den;
    z.is_finite().then_some(z)
}

/// Whether the linear triangulation lies in front of both cameras (cheirality).
#[must_use]
pub fn in_front_of_both(r1: &Vector3<f64>, r2: &Vector3<f64>, cam2_from_cam1: &Pose) -> bool {
    linear_depth(r1, r2, cam2_from_cam1).is_some_and(|z| {
        let p2 = cam2_from_cam1.rotation * (r1 * z) + cam2_from_cam1.translation.vector;
        z > 0.0 && p2.z > 0.0
    })
}

/// The projection `π(a z + t)` into image 2 and its derivative with respect to `z`: the ray's
/// point `X(z)` (`a = R r1`, pixels per depth unit), or, with `a` and `t` swapped, the point at
/// inverse depth `z` ([`triangulate_inverse_depth`]).
fn project_ray(
    camera: &PinholeCamera,
    a: &Vector3<f64>,
    t: &Vector3<f64>,
    z: f64,
) -> Option<(Point2<f64>, Vector2<f64>)> {
    let p = a * z + t;
    if p.z <= 1e-9 {
        return None;
    }
    let inv = 1.0 / p.z;
    let px = Point2::new(
        camera.fx * p.x * inv + camera.cx,
        camera.fy * p.y * inv + camera.cy,
    );
    let inv2 = inv * inv;
    let j = Vector2::new(
        camera.fx * (a.x * t.z - t.x * a.z) * inv2,
        camera.fy * (a.y * t.z - t.y * a.z) * inv2,
    );
    Some((px, j))
}

/// Triangulates `c` given the relative pose (any translation scale); `None` without parallax or
/// when the point is not in front of both cameras.
#[must_use]
pub fn triangulate(
    camera: &PinholeCamera,
    cam2_from_cam1: &Pose,
    c: &Correspondence,
) -> Option<TriangulatedPoint> {
    let r1 = camera.ray(&c.p1_px);
    let r2 = camera.ray(&c.p2_px);
    let mut z = linear_depth(&r1, &r2, cam2_from_cam1)?;
    if z <= 0.0 {
        return None;
    }
    let a = cam2_from_cam1.rotation * r1;
    let t = cam2_from_cam1.translation.vector;
    let y = &c.information;
    for _ in 0..5 {
        let (px, j) = project_ray(camera, &a, &t, z)?;
        let r = c.p2_px - px;
        let h = (j.transpose() * y * j)[0];
        if h <= 0.0 {
            return None;
        }
        let step = (j.transpose() * y * r)[0] / h;
        // keep the depth positive: at most halve it per step
        z = (z + step).max(0.5 * z);
        if step.abs() < 1e-12 * z {
            break;
        }
    }
    let (px, j) = project_ray(camera, &a, &t, z)?;
    let h = (j.transpose() * y * j)[0];
    if h <= 0.0 || !z.is_finite() {
        return None;
    }
    let r = c.p2_px - px;
    Some(TriangulatedPoint {
        p_in_cam1: Point3::from(r1 * z),
        depth: z,
        depth_variance: 1.0 / h,
        reprojection_sq: (r.transpose() * y * r)[0],
    })
}

/// A correspondence triangulated in inverse depth (see [`triangulate_inverse_depth`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseDepthPoint {
    /// Inverse depth `ρ = 1 / z` along camera 1's optical axis, 1 / (translation units); zero
    /// at infinity, negative where the flow points the wrong way along the epipolar line.
    pub inverse_depth: f64,
    /// First-order variance of `inverse_depth` from the flow's information matrix.
    pub variance: f64,
}

/// Triangulates `c` in inverse depth: the `ρ` minimising the Mahalanobis reprojection error of
/// `π(R r1 + ρ t)` (the ray's point `r1 / ρ` seen from camera 2, scaled by `ρ`) by Gauss–Newton
/// from the linear solution of `r2 × (R r1 + ρ t) = 0`, with no sign or size constraint.
///
/// Unlike [`triangulate`] it keeps every measurement: near the point at infinity the image
/// position is almost linear in `ρ`, so zero-mean flow noise gives zero-mean `ρ` noise whose
/// variance does not depend on the measured value. A filter that drops what came out negative
/// or uncertain *relative to the measured depth* keeps the measurements whose noise made the
/// parallax larger, and so its depths come out too near (the inverse-depth filter of Civera,
/// Davison and Montiel 2008 for the same reason). `None` only at the epipole or behind
/// camera 2's image plane.
#[must_use]
pub fn triangulate_inverse_depth(
    camera: &PinholeCamera,
    cam2_from_cam1: &Pose,
    c: &Correspondence,
) -> Option<InverseDepthPoint> {
    let r1 = camera.ray(&c.p1_px);
    let r2 = camera.ray(&c.p2_px);
    let a = cam2_from_cam1.rotation * r1;
    let t = cam2_from_cam1.translation.vector;
    let rt = r2.cross(&t);
    let den = rt.norm_squared();
    if den < 1e-14 * t.norm_squared() * r2.norm_squared() {
        return None;
    }
    let mut rho = -r2.cross(&a).dot(&rt) / den;
    let y = &c.information;
    // the image-2 position `π(a + ρ t)` and its derivative with respect to ρ: the ray's
    // projection with the roles of the direction and the offset swapped
    let project = |rho: f64| project_ray(camera, &t, &a, rho);
    for _ in 0..5 {
        let (px, j) = project(rho)?;
        let h = (j.transpose() * y * j)[0];
        if h <= 0.0 {
            return None;
        }
        let step = (j.transpose() * y * (c.p2_px - px))[0] / h;
        rho += step;
        if step.abs() < 1e-12 * rho.abs().max(1e-12) {
            break;
        }
    }
    let (_, j) = project(rho)?;
    let h = (j.transpose() * y * j)[0];
    (h > 0.0 && rho.is_finite()).then(|| InverseDepthPoint {
        inverse_depth: rho,
        variance: 1.0 / h,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Translation3, UnitQuaternion};

    /// A camera, a relative pose, a point 15 m ahead and its exact correspondence.
    fn fixture() -> (PinholeCamera, Pose, Point3<f64>, Correspondence) {
        let cam = PinholeCamera::kitti_default();
        let pose = Pose::from_parts(
            Translation3::new(0.1, -0.05, -1.0),
            UnitQuaternion::from_euler_angles(0.01, 0.03, -0.02),
        );
        let p1 = Point3::new(3.0, 1.0, 15.0);
        let c = Correspondence {
            p1_px: cam.project(&p1).unwrap(),
            p2_px: cam.project(&(pose * p1)).unwrap(),
            information: Matrix2::new(2.0, 0.5, 0.5, 1.0),
        };
        (cam, pose, p1, c)
    }

    #[test]
    fn exact_and_variance_matches_finite_difference() {
        let (cam, pose, p1, c) = fixture();
        let (x1, x2, y) = (c.p1_px, c.p2_px, c.information);
        let tp = triangulate(&cam, &pose, &c).unwrap();
        assert!((tp.p_in_cam1 - p1).norm() < 1e-8);
        assert!(tp.reprojection_sq < 1e-12);
        // variance: dz/dp2 by finite differences, σ² = g Y⁻¹ gᵀ
        let eps = 1e-4;
        let mut g = nalgebra::RowVector2::zeros();
        for k in 0..2 {
            let mut cp = c;
            let mut cm = c;
            cp.p2_px[k] += eps;
            cm.p2_px[k] -= eps;
            let zp = triangulate(&cam, &pose, &cp).unwrap().depth;
            let zm = triangulate(&cam, &pose, &cm).unwrap().depth;
            g[k] = (zp - zm) / (2.0 * eps);
        }
        let var = (g * y.try_inverse().unwrap() * g.transpose())[0];
        assert!(
            (var - tp.depth_variance).abs() < 1e-3 * var,
            "{var} vs {}",
            tp.depth_variance
        );
        // behind the camera: rejected
        let behind = Correspondence {
            p2_px: x1,
            p1_px: x2,
            ..c
        };
        let inv = pose.inverse();
        assert!(triangulate(&cam, &inv, &behind).is_some());
        assert!(!in_front_of_both(
            &cam.ray(&x1),
            &cam.ray(&x2),
            &pose.inverse()
        ));
    }

    #[test]
    fn inverse_depth_agrees_with_depth_and_passes_through_infinity() {
        let (cam, pose, p1, c) = fixture();
        let x2 = c.p2_px;
        let d = triangulate(&cam, &pose, &c).unwrap();
        let r = triangulate_inverse_depth(&cam, &pose, &c).unwrap();
        assert!((r.inverse_depth - 1.0 / 15.0).abs() < 1e-10, "{r:?}");
        // first order: σ_ρ = σ_z / z²
        let expected = d.depth_variance / d.depth.powi(4);
        assert!((r.variance - expected).abs() < 1e-3 * expected);
        // the point at infinity, and one "beyond" it (flow reversed along the epipolar line)
        let at_infinity = cam.project(&(pose.rotation * p1)).unwrap();
        let inf = triangulate_inverse_depth(
            &cam,
            &pose,
            &Correspondence {
                p2_px: at_infinity,
                ..c
            },
        )
        .unwrap();
        assert!(inf.inverse_depth.abs() < 1e-10, "{inf:?}");
        let beyond = at_infinity + (at_infinity - x2) * 0.1;
        let neg =
            triangulate_inverse_depth(&cam, &pose, &Correspondence { p2_px: beyond, ..c }).unwrap();
        assert!(neg.inverse_depth < 0.0, "{neg:?}");
        assert!(triangulate(&cam, &pose, &Correspondence { p2_px: beyond, ..c }).is_none());
    }
}
