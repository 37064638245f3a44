//! Perspective-n-point: a P3P minimal solver, PnP RANSAC and Gauss–Newton refinement on SE(3).
//!
//! **P3P** follows the structure of Lambda Twist (Persson & Nordberg, ECCV 2018). With unit
//! bearings `yᵢ` and world points `xᵢ`, the depths `Λ = (λ₁, λ₂, λ₃)` satisfy
//! `ΛᵀMᵢⱼΛ = aᵢⱼ = ‖xᵢ − xⱼ‖²` (law of cosines). The homogeneous pair
//! `D₁ = a₂₃M₁₂ − a₁₂M₂₃`, `D₂ = a₂₃M₁₃ − a₁₃M₂₃` has `ΛᵀD₁Λ = ΛᵀD₂Λ = 0`; a real root `γ` of
//! the cubic `det(D₁ + γD₂) = 0` makes `D₀ = D₁ + γD₂` degenerate, so its cone splits into two
//! planes through the origin (from its eigen-decomposition). On each plane `ΛᵀD₁Λ = 0` is a
//! quadratic in one ratio, and `ΛᵀM₁₂Λ = a₁₂` fixes the scale: up to four solutions, each polished
//! by Newton's method on the three equations. The pose follows from
//! `R = [λ₁y₁−λ₂y₂, λ₁y₁−λ₃y₃, ×] [x₁−x₂, x₁−x₃, ×]⁻¹`, `t = λ₁y₁ − R x₁`. (Cubic coefficients
//! are obtained by evaluating the determinant at four `γ`, instead of the paper's closed forms.)
//!
//! **Refinement** minimises `Σ rᵢᵀ Yᵢ rᵢ`, `rᵢ = pᵢ − π(T xᵢ)` (pixels, `Yᵢ` the flow's
//! information), with the left perturbation `T ← exp(δ) T`, `δ = (v, ω)`; the analytic Jacobian is
//! [`projection_jacobian`].

use nalgebra::{
    Matrix2, Matrix2x6, Matrix3, Matrix3x6, Matrix6, Point2, Point3, Translation3, UnitQuaternion,
    Vector2, Vector3, Vector6,
};
use rand::Rng;
use serde::{Deserialize, Serialize};
use visnav_core::se3::{project_to_so3, se3_exp, skew};
use visnav_core::{PinholeCamera, Pose};

use crate::GeometryError;
use crate::ransac::{RansacConfig, RansacProblem, ransac};

/// A 2-D–3-D correspondence for PnP.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PnpCorrespondence {
    /// The point in the world (or reference camera) frame.
    pub p_in_world: Point3<f64>,
    /// Its observation in the image, pixels.
    pub p_px: Point2<f64>,
    /// Information matrix of the observation, 1/px².
    pub information: Matrix2<f64>,
}

/// Real roots of `c3 x³ + c2 x² + c1 x + c0` (degrading to lower degree).
fn real_roots_cubic(c3: f64, c2: f64, c1: f64, c0: f64) -> Vec<f64> {
    let scale = c3.abs().max(c2.abs()).max(c1.abs()).max(c0.abs());
    if scale == 0.0 {
        return Vec::new();
    }
    let mut roots = Vec::new();
    if c3.abs() < 1e-12 * scale {
        if c2.abs() < 1e-12 * scale {
            if c1 != 0.0 {
                roots.push(-c0 / c1);
            }
            return roots;
        }
        let disc = c1 * c1 - 4.0 * c2 * c0;
        if disc >= 0.0 {
            let q = -0.5 * (c1 + c1.signum() * disc.sqrt());
            roots.push(q / c2);
            if q != 0.0 {
                roots.push(c0 / q);
            }
        }
        return roots;
    }
    // depressed cubic x = t − b/3
    let (b, c, d) = (c2 / c3, c1 / c3, c0 / c3);
    let p = c - b * b / 3.0;
    let q = 2.0 * b * b * b / 27.0 - b * c / 3.0 + d;
    let disc = q * q / 4.0 + p * p * p / 27.0;
    if disc > 0.0 {
        let s = disc.sqrt();
        roots.push((-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt() - b / 3.0);
    } else {
        let r = (-p / 3.0).max(0.0).sqrt();
        let arg = if r > 0.0 {
            (3.0 * q / (2.0 * p * r)).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        let phi = arg.acos() / 3.0;
        for k in 0..3 {
            roots.push(
                2.0 * r * (phi - 2.0 * std::f64::consts::PI * f64::from(k) / 3.0).cos() - b / 3.0,
            );
        }
    }
    // Newton polish
    for x in &mut roots {
        for _ in 0..3 {
            let f = ((c3 * *x + c2) * *x + c1) * *x + c0;
            let df = (3.0 * c3 * *x + 2.0 * c2) * *x + c1;
            if df.abs() > 1e-300 {
                *x -= f / df;
            }
        }
    }
    roots
}

/// Newton's method on the three law-of-cosines equations.
fn polish_depths(lambda: &mut Vector3<f64>, cos: &[f64; 3], a: &[f64; 3]) {
    // cos = (c12, c13, c23), a = (a12, a13, a23)
    for _ in 0..5 {
        let (l1, l2, l3) = (lambda.x, lambda.y, lambda.z);
        let r = Vector3::new(
            l1 * l1 + l2 * l2 - 2.0 * cos[0] * l1 * l2 - a[0],
            l1 * l1 + l3 * l3 - 2.0 * cos[1] * l1 * l3 - a[1],
            l2 * l2 + l3 * l3 - 2.0 * cos[2] * l2 * l3 - a[2],
        );
        let j = Matrix3::new(
            2.0 * l1 - 2.0 * cos[0] * l2,
            2.0 * l2 - 2.0 * cos[0] * l1,
            0.0,
            2.0 * l1 - 2.0 * cos[1] * l3,
            0.0,
            2.0 * l3 - 2.0 * cos[1] * l1,
            0.0,
            2.0 * l2 - 2.0 * cos[2] * l3,
            2.0 * l3 - 2.0 * cos[2] * l2,
        );
        let Some(step) = j.lu().solve(&r) else {
            return;
        };
        *lambda -= step;
    }
}

/// All poses `cam_from_world` consistent with three bearings (any length, pointing at the points)
/// and three world points; empty when degenerate (collinear points, coincident bearings).
#[must_use]
pub fn p3p(bearings: &[Vector3<f64>; 3], points: &[Point3<f64>; 3]) -> Vec<Pose> {
    let y = bearings.map(|b| b.normalize());
    if y.iter().any(|v| !v.iter().all(|c| c.is_finite())) {
        return Vec::new();
    }
    let cos = [y[0].dot(&y[1]), y[0].dot(&y[2]), y[1].dot(&y[2])];
    let d12 = points[0] - points[1];
    let d13 = points[0] - points[2];
    let d23 = points[1] - points[2];
    let a = [d12.norm_squared(), d13.norm_squared(), d23.norm_squared()];
    let n = d12.cross(&d13);
    if n.norm_squared() < 1e-20 * a[0] * a[1] || a.iter().any(|&v| v <= 0.0) {
        return Vec::new();
    }
    let m12 = Matrix3::new(1.0, -cos[0], 0.0, -cos[0], 1.0, 0.0, 0.0, 0.0, 0.0);
    let m13 = Matrix3::new(1.0, 0.0, -cos[1], 0.0, 0.0, 0.0, -cos[1], 0.0, 1.0);
    let m23 = Matrix3::new(0.0, 0.0, 0.0, 0.0, 1.0, -cos[2], 0.0, -cos[2], 1.0);
    let d1 = m12 * a[2] - m23 * a[0];
    let d2 = m13 * a[2] - m23 * a[1];
    let det = |g: f64| (d1 + d2 * g).determinant();
    let (p0, p1, pm, p2) = (det(0.0), det(1.0), det(-1.0), det(2.0));
    let c0 = p0;
    let c2 = 0.5 * (p1 + pm) - c0;
    let odd = 0.5 * (p1 - pm);
    let q = 0.5 * (p2 - c0 - 4.0 * c2);
    let c3 = (q - odd) / 3.0;
    let c1 = odd - c3;
    let x_mat = Matrix3::from_columns(&[d12, d13, n]);
    let Some(x_inv) = x_mat.try_inverse() else {
        return Vec::new();
    };
    let mut poses = Vec::new();
    for gamma in real_roots_cubic(c3, c2, c1, c0) {
        let d0 = d1 + d2 * gamma;
        let eig = d0.symmetric_eigen();
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&i, &j| {
            eig.eigenvalues[i]
                .abs()
                .total_cmp(&eig.eigenvalues[j].abs())
        });
        let e0: Vector3<f64> = eig.eigenvectors.column(idx[0]).into_owned();
        let (sa, sb) = (eig.eigenvalues[idx[1]], eig.eigenvalues[idx[2]]);
        let ea: Vector3<f64> = eig.eigenvectors.column(idx[1]).into_owned();
        let eb: Vector3<f64> = eig.eigenvectors.column(idx[2]).into_owned();
        if sa * sb >= 0.0 {
            continue;
        }
        let s = (-sa / sb).sqrt();
        let mut found = false;
        for sign in [1.0, -1.0] {
            // σa (eaᵀΛ)² + σb (ebᵀΛ)² = 0  ⇔  ebᵀΛ = ±s eaᵀΛ
            let normal = eb - ea * (sign * s);
            let w = normal.cross(&e0);
            if w.norm_squared() < 1e-20 {
                continue;
            }
            let w = w.normalize();
            // restricted quadratic form of D1 (or D2 when D1 vanishes on the plane)
            let form = |m: &Matrix3<f64>| (e0.dot(&(m * e0)), e0.dot(&(m * w)), w.dot(&(m * w)));
            let f1 = form(&d1);
            let f2 = form(&d2);
            let mag = |f: &(f64, f64, f64)| f.0.abs() + f.1.abs() + f.2.abs();
            let (q11, q12, q22) = if mag(&f1) >= mag(&f2) { f1 } else { f2 };
            let disc = q12 * q12 - q11 * q22;
            if disc < -1e-9 * (q12 * q12 + (q11 * q22).abs()) {
                continue;
            }
            let sd = disc.max(0.0).sqrt();
            let dirs: Vec<Vector3<f64>> = if q11.abs() > q22.abs() {
                [(-q12 + sd) / q11, (-q12 - sd) / q11]
                    .iter()
                    .map(|tau| e0 * *tau + w)
                    .collect()
            } else if q22.abs() > 0.0 {
                [(-q12 + sd) / q22, (-q12 - sd) / q22]
                    .iter()
                    .map(|tau| e0 + w * *tau)
                    .collect()
            } else {
                // q12 αβ = 0: α = 0 or β = 0
                vec![e0, w]
            };
            for dir in dirs {
                let norm12 = dir.dot(&(m12 * dir));
                if norm12 <= 0.0 {
                    continue;
                }
                let mut lambda = dir * (a[0] / norm12).sqrt();
                if lambda.x < 0.0 {
                    lambda = -lambda;
                }
                polish_depths(&mut lambda, &cos, &a);
                if lambda.iter().any(|&l| l <= 0.0 || !l.is_finite()) {
                    continue;
                }
                let v12 = y[0] * lambda.x - y[1] * lambda.y;
                let v13 = y[0] * lambda.x - y[2] * lambda.z;
                let y_mat = Matrix3::from_columns(&[v12, v13, v12.cross(&v13)]);
                let rot = project_to_so3(&(y_mat * x_inv));
                let t = y[0] * lambda.x - rot * points[0].coords;
                poses.push(Pose::from_parts(
                    Translation3::from(t),
                    UnitQuaternion::from_rotation_matrix(&rot),
                ));
                found = true;
            }
        }
        if found {
            break;
        }
    }
    poses
}

/// `∂π(p)/∂δ` for `p = exp(δ) T x` at `δ = 0`, `p = p_in_cam`: `J_π(p) [I | −[p]ₓ]` (2×6, pixels
/// per unit twist; the twist is `(v, ω)`).
#[must_use]
pub fn projection_jacobian(camera: &PinholeCamera, p_in_cam: &Point3<f64>) -> Matrix2x6<f64> {
    let z_inv = 1.0 / p_in_cam.z;
    let j_pi = nalgebra::Matrix2x3::new(
        camera.fx * z_inv,
        0.0,
        -camera.fx * p_in_cam.x * z_inv * z_inv,
        0.0,
        camera.fy * z_inv,
        -camera.fy * p_in_cam.y * z_inv * z_inv,
    );
    let mut j_p = Matrix3x6::zeros();
    j_p.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j_p.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&p_in_cam.coords)));
    j_pi * j_p
}

/// Squared Mahalanobis reprojection error of a correspondence; infinite behind the camera.
#[must_use]
pub fn reprojection_error_sq(
    camera: &PinholeCamera,
    cam_from_world: &Pose,
    c: &PnpCorrespondence,
) -> f64 {
    match camera.project(&(cam_from_world * c.p_in_world)) {
        Some(px) => {
            let r: Vector2<f64> = c.p_px - px;
            (r.transpose() * c.information * r)[0]
        }
        None => f64::INFINITY,
    }
}

/// Gauss–Newton refinement of `cam_from_world` minimising `Σ rᵀ Y r`; `None` if the normal
/// equations are singular at the start.
#[must_use]
pub fn refine_pose(
    camera: &PinholeCamera,
    cam_from_world: &Pose,
    data: &[&PnpCorrespondence],
    iterations: usize,
) -> Option<Pose> {
    let mut pose = *cam_from_world;
    let cost = |pose: &Pose| {
        data.iter()
            .map(|c| reprojection_error_sq(camera, pose, c))
            .filter(|e| e.is_finite())
            .sum::<f64>()
    };
    let mut current = cost(&pose);
    for _ in 0..iterations {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for c in data {
            let p = pose * c.p_in_world;
            let Some(px) = camera.project(&p) else {
                continue;
            };
            let j = projection_jacobian(camera, &p);
            let r: Vector2<f64> = c.p_px - px;
            let jt_y = j.transpose() * c.information;
            h += jt_y * j;
            g += jt_y * r;
        }
        let delta = h.cholesky()?.solve(&g);
        let candidate = se3_exp(&delta) * pose;
        let next = cost(&candidate);
        if next > current {
            break;
        }
        pose = candidate;
        let done = current - next <= 1e-12 * current.max(1e-300);
        current = next;
        if done || delta.norm() < 1e-12 {
            break;
        }
    }
    Some(pose)
}

/// PnP parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PnpConfig {
    /// RANSAC; threshold on the squared Mahalanobis reprojection error, default
    /// 5.99 = χ²(2 dof, 95 %).
    pub ransac: RansacConfig,
    /// Gauss–Newton iterations of the refinement. Default 10.
    pub refine_iterations: usize,
}

impl Default for PnpConfig {
    fn default() -> Self {
        Self {
            ransac: RansacConfig {
                inlier_threshold: 5.99,
                ..RansacConfig::default()
            },
            refine_iterations: 10,
        }
    }
}

impl PnpConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`GeometryError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), GeometryError> {
        self.ransac.validate()
    }
}

/// The PnP problem for [`ransac`]: P3P hypotheses, Mahalanobis reprojection residual,
/// Gauss–Newton refit.
#[derive(Debug, Clone, Copy)]
pub struct PnpProblem {
    /// The camera.
    pub camera: PinholeCamera,
    /// Gauss–Newton iterations of the refit.
    pub refine_iterations: usize,
}

impl RansacProblem for PnpProblem {
    type Sample = PnpCorrespondence;
    type Model = Pose;
    const MIN_SAMPLES: usize = 3;

    fn fit_minimal(&self, s: &[&PnpCorrespondence]) -> Vec<Pose> {
        let bearings = [
            self.camera.ray(&s[0].p_px),
            self.camera.ray(&s[1].p_px),
            self.camera.ray(&s[2].p_px),
        ];
        p3p(
            &bearings,
            &[s[0].p_in_world, s[1].p_in_world, s[2].p_in_world],
        )
    }

    fn residual_sq(&self, model: &Pose, sample: &PnpCorrespondence) -> f64 {
        reprojection_error_sq(&self.camera, model, sample)
    }

    fn refit(&self, inliers: &[&PnpCorrespondence], initial: &Pose) -> Option<Pose> {
        refine_pose(&self.camera, initial, inliers, self.refine_iterations)
    }
}

/// Result of [`solve_pnp`].
#[derive(Debug, Clone, PartialEq)]
pub struct PnpResult {
    /// The refined pose.
    pub cam_from_world: Pose,
    /// Inlier flag per correspondence.
    pub inliers: Vec<bool>,
    /// Number of inliers.
    pub inlier_count: usize,
    /// RANSAC iterations.
    pub iterations: usize,
}

/// P3P RANSAC (samples ∝ certainty `sqrt(det Y)`) and Gauss–Newton refinement on the inliers.
pub fn solve_pnp<R: Rng>(
    camera: &PinholeCamera,
    data: &[PnpCorrespondence],
    config: &PnpConfig,
    rng: &mut R,
) -> Option<PnpResult> {
    let problem = PnpProblem {
        camera: *camera,
        refine_iterations: config.refine_iterations,
    };
    let weights: Vec<f64> = data
        .iter()
        .map(|c| c.information.determinant().max(0.0).sqrt())
        .collect();
    let r = ransac(&problem, data, Some(&weights), &config.ransac, rng)?;
    Some(PnpResult {
        cam_from_world: r.model,
        inliers: r.inliers,
        inlier_count: r.inlier_count,
        iterations: r.iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn random_pose(rng: &mut ChaCha8Rng) -> Pose {
        let xi = Vector6::from_fn(|i, _| {
            if i < 3 {
                rng.random_range(-2.0..2.0)
            } else {
                rng.random_range(-0.5..0.5)
            }
        });
        se3_exp(&xi)
    }

    #[test]
    fn p3p_exact_on_noise_free_points() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut worst: f64 = 0.0;
        for _ in 0..200 {
            let cam_from_world = random_pose(&mut rng);
            let world_from_cam = cam_from_world.inverse();
            let pts: [Point3<f64>; 3] = std::array::from_fn(|_| {
                let p_in_cam = Point3::new(
                    rng.random_range(-4.0..4.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(3.0..30.0),
                );
                world_from_cam * p_in_cam
            });
            let bearings = pts.map(|p| (cam_from_world * p).coords * 0.37);
            let sols = p3p(&bearings, &pts);
            assert!(!sols.is_empty() && sols.len() <= 8);
            let err = sols
                .iter()
                .map(|s| (s.to_homogeneous() - cam_from_world.to_homogeneous()).norm())
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(err);
        }
        assert!(worst < 1e-6, "worst pose error {worst}");
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let cam = PinholeCamera::kitti_default();
        let pose = se3_exp(&Vector6::new(0.3, -0.2, 0.5, 0.05, -0.1, 0.02));
        let x = Point3::new(1.5, -0.7, 9.0);
        let j = projection_jacobian(&cam, &(pose * x));
        let eps = 1e-6;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = eps;
            let plus = cam.project(&(se3_exp(&d) * pose * x)).unwrap();
            let minus = cam.project(&(se3_exp(&(-d)) * pose * x)).unwrap();
            let fd = (plus - minus) / (2.0 * eps);
            assert!(
                (fd - j.column(k)).norm() < 1e-4 * (1.0 + fd.norm()),
                "col {k}: {fd} vs {}",
                j.column(k)
            );
        }
    }

    #[test]
    fn pnp_ransac_with_outliers_and_refinement() {
        let cam = PinholeCamera::kitti_default();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let cam_from_world = se3_exp(&Vector6::new(0.2, 0.1, -1.0, 0.01, 0.05, -0.02));
        let world_from_cam = cam_from_world.inverse();
        let mut data = Vec::new();
        while data.len() < 300 {
            let p_in_cam = Point3::new(
                rng.random_range(-15.0..15.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(5.0..50.0),
            );
            let Some(px) = cam.project(&p_in_cam) else {
                continue;
            };
            if !cam.contains(&px, 0.0) {
                continue;
            }
            let outlier = data.len() % 4 == 0;
            let noise = Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
            let px = if outlier {
                px + Vector2::new(rng.random_range(-80.0..80.0), rng.random_range(-40.0..40.0))
            } else {
                px + noise
            };
            data.push(PnpCorrespondence {
                p_in_world: world_from_cam * p_in_cam,
                p_px: px,
                information: Matrix2::identity() * 4.0,
            });
        }
        let res = solve_pnp(&cam, &data, &PnpConfig::default(), &mut rng).unwrap();
        let err = res.cam_from_world.inverse() * cam_from_world;
        assert!(err.translation.vector.norm() < 0.05, "{err}");
        assert!(err.rotation.angle() < 2e-3);
        let outliers_flagged = data
            .iter()
            .enumerate()
            .filter(|(i, _)| i % 4 == 0 && !res.inliers[*i])
            .count();
        assert!(outliers_flagged >= 70, "{outliers_flagged}");
        assert!(res.inlier_count >= 200);
    }
}
