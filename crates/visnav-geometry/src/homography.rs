//! Two views of a plane: the homography `x2 ~ H x1`, its uncertainty-guided RANSAC, the model
//! selection against the fundamental matrix and the decomposition into motion and plane.
//!
//! A downward view of flat ground is the eight-point algorithm's degenerate case: every
//! correspondence also fits a one-parameter family of fundamental matrices, so the epipolar
//! geometry (and the translation direction with it) is decided by the noise. Like the monocular
//! initialisation of ORB-SLAM (Mur-Artal et al. 2015, §IV), the odometry fits both models and
//! keeps the homography when it explains the data as well; the choice is Torr's GRIC ([`gric`])
//! of the squared Mahalanobis residuals (with the flow's information matrix: the transfer error
//! in the second image for `H`, the distance to the epipolar line for `F`, eq. 11 of the
//! monocular paper). ORB-SLAM's ratio `S_H / (S_H + S_F) > 0.45` sat at 0.46–0.50 on planar
//! views with these one-sided residuals, too close to its threshold. The motion is then one of
//! the eight factorisations of the calibrated homography `K⁻¹ H K = R + t nᵀ / d` (Faugeras &
//! Lustman 1988), chosen by cheirality.

use nalgebra::{
    Matrix3, Matrix6, Point3, Rotation3, SMatrix, Translation3, Unit, UnitQuaternion, Vector2,
    Vector3, Vector6,
};
use rand::Rng;
use visnav_core::{PinholeCamera, Pose};

use crate::correspondence::Correspondence;
use crate::fundamental::{dlt_solution, hartley};
use crate::ransac::{RansacConfig, RansacProblem, RansacResult, ransac};
use crate::triangulation::in_front_of_both;

/// χ²₂ at 95 %: the homography's inlier bound on the squared transfer error.
pub const CHI2_2DOF_95: f64 = 5.99;

/// The normalised direct linear transform (Hartley & Zisserman, algorithm 4.2): `H` with
/// `p2 ~ H p1` from at least four correspondences, scaled to `‖H‖_F = 1`. `None` when
/// degenerate.
#[must_use]
pub fn homography_dlt(data: &[&Correspondence]) -> Option<Matrix3<f64>> {
    if data.len() < 4 {
        return None;
    }
    let t1 = hartley(data.iter().map(|c| &c.p1_px))?;
    let t2 = hartley(data.iter().map(|c| &c.p2_px))?;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for c in data {
        let p = t1 * Vector3::new(c.p1_px.x, c.p1_px.y, 1.0);
        let q = t2 * Vector3::new(c.p2_px.x, c.p2_px.y, 1.0);
        let rows = [
            [-p.x, -p.y, -1.0, 0.0, 0.0, 0.0, q.x * p.x, q.x * p.y, q.x],
            [0.0, 0.0, 0.0, -p.x, -p.y, -1.0, q.y * p.x, q.y * p.y, q.y],
        ];
        for r in rows {
            let r = SMatrix::<f64, 9, 1>::from_row_slice(&r);
            ata += r * r.transpose();
        }
    }
    let hn = dlt_solution(&ata)?;
    let h = t2.try_inverse()? * hn * t1;
    let norm = h.norm();
    (norm > 0.0 && h.iter().all(|v| v.is_finite())).then(|| h / norm)
}

/// Squared Mahalanobis transfer error `eᵀ Y e`, `e = p2 − H p1` (the flow's error lives in the
/// second image); infinite when `H p1` is at infinity.
#[must_use]
pub fn transfer_error_sq(h: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let p = h * Vector3::new(c.p1_px.x, c.p1_px.y, 1.0);
    if p.z.abs() < 1e-12 {
        return f64::INFINITY;
    }
    let e = nalgebra::Vector2::new(c.p2_px.x - p.x / p.z, c.p2_px.y - p.y / p.z);
    (e.transpose() * c.information * e)[0]
}

/// The uncertainty-guided RANSAC problem for `H`: four-point DLT, residual the squared
/// Mahalanobis transfer error, refit by the DLT on all inliers.
#[derive(Debug, Clone, Copy, Default)]
pub struct HomographyProblem;

impl RansacProblem for HomographyProblem {
    type Sample = Correspondence;
    type Model = Matrix3<f64>;
    const MIN_SAMPLES: usize = 4;

    fn fit_minimal(&self, samples: &[&Correspondence]) -> Vec<Matrix3<f64>> {
        homography_dlt(samples).into_iter().collect()
    }

    fn residual_sq(&self, model: &Matrix3<f64>, sample: &Correspondence) -> f64 {
        transfer_error_sq(model, sample)
    }

    fn refit(&self, inliers: &[&Correspondence], _: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        homography_dlt(inliers)
    }
}

/// RANSAC for `H` with the sampling weighted by certainty; `config.inlier_threshold` is on the
/// squared transfer error ([`CHI2_2DOF_95`] is the usual bound).
pub fn estimate_homography<R: Rng>(
    data: &[Correspondence],
    config: &RansacConfig,
    rng: &mut R,
) -> Option<RansacResult<Matrix3<f64>>> {
    let weights: Vec<f64> = data.iter().map(Correspondence::certainty).collect();
    ransac(&HomographyProblem, data, Some(&weights), config, rng)
}

/// Torr's geometric robust information criterion (GRIC, Torr 1998) of a two-view model with
/// `model_dim` dimensions (`F`: 3, `H`: 2) and `params` parameters (`F`: 7, `H`: 8) from its
/// squared residuals in units of their variance (Mahalanobis), over correspondences of
/// dimension 4: `Σ min(e², λ₃ (4 − d)) + λ₁ d n + λ₂ k` with `λ₁ = ln 4`, `λ₂ = ln 4n`,
/// `λ₃ = 2`. The lower wins: on a plane `H` fits as well as `F` with one more residual degree
/// of freedom and two fewer structure dimensions per point (≈ 0.4 per point less); off a plane
/// its residuals hit the cap.
#[must_use]
pub fn gric(residuals_sq: impl Iterator<Item = f64>, model_dim: usize, params: usize) -> f64 {
    const R: f64 = 4.0;
    let d = model_dim as f64;
    let cap = 2.0 * (R - d);
    let (sum, n) = residuals_sq.fold((0.0, 0usize), |(s, n), e2| {
        (s + if e2.is_finite() { e2.min(cap) } else { cap }, n + 1)
    });
    let n_f = n as f64;
    sum + R.ln() * d * n_f + (R * n_f).ln() * params as f64
}

/// One factorisation of a calibrated homography `K⁻¹ H K ~ R + t nᵀ / d`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarMotion {
    /// `cam2_from_cam1`; the translation in units of the plane's distance from camera 1 (`t/d`).
    pub cam2_from_cam1: Pose,
    /// The plane's unit normal in camera 1, pointing away from the camera (`n·z > 0`).
    pub normal_in_cam1: Unit<Vector3<f64>>,
}

/// The eight factorisations of a homography between two views of `camera` (Faugeras & Lustman;
/// the formulation of ORB-SLAM's `ReconstructH`): `None` when two singular values of
/// `K⁻¹ H K` coincide (no translation, or a degenerate `H`).
#[must_use]
pub fn decompose_homography(h: &Matrix3<f64>, camera: &PinholeCamera) -> Option<Vec<PlanarMotion>> {
    let k = camera.k();
    let mut a = k.try_inverse()? * h * k;
    // det(R + t nᵀ/d) = (distance of camera 2 from the plane) / d > 0 when both cameras see the
    // plane from the same side: fix the sign of H that the DLT leaves open
    if a.determinant() < 0.0 {
        a = -a;
    }
    let svd = a.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut order: Vec<usize> = (0..3).collect();
    order.sort_by(|&i, &j| svd.singular_values[j].total_cmp(&svd.singular_values[i]));
    let (u, v_t, sv) = (
        Matrix3::from_columns(&order.iter().map(|&i| u.column(i)).collect::<Vec<_>>()),
        Matrix3::from_rows(&order.iter().map(|&i| v_t.row(i)).collect::<Vec<_>>()),
        order
            .iter()
            .map(|&i| svd.singular_values[i])
            .collect::<Vec<_>>(),
    );
    // the Euclidean homography has the middle singular value 1: then t is t/d. Two equal
    // singular values (a motion along the plane's normal, t ∥ n) are the formulas' limit
    // (x1 or x3 = 0, a rotation of 0 in the primed frame); three (no translation) leave t/d and
    // n undetermined
    let (d1, d2, d3) = (sv[0] / sv[1], 1.0, sv[2] / sv[1]);
    if d1 / d3 < 1.00001 || !d3.is_finite() {
        return None;
    }
    let s = u.determinant() * v_t.determinant();
    let v = v_t.transpose();
    let aux1 = ((d1 * d1 - d2 * d2) / (d1 * d1 - d3 * d3)).sqrt();
    let aux3 = ((d2 * d2 - d3 * d3) / (d1 * d1 - d3 * d3)).sqrt();
    let signs = [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)];
    let root = ((d1 * d1 - d2 * d2) * (d2 * d2 - d3 * d3)).sqrt();
    let mut out = Vec::with_capacity(8);
    // d' = d2 > 0: a rotation about y by θ
    let (c_theta, s_theta) = (
        (d2 * d2 + d1 * d3) / ((d1 + d3) * d2),
        root / ((d1 + d3) * d2),
    );
    // d' = −d2 < 0: a reflection-rotation by φ
    let (c_phi, s_phi) = (
        (d1 * d3 - d2 * d2) / ((d1 - d3) * d2),
        root / ((d1 - d3) * d2),
    );
    for (e1, e3) in signs {
        let (x1, x3) = (e1 * aux1, e3 * aux3);
        let st = e1 * e3 * s_theta;
        let rp = Matrix3::new(c_theta, 0.0, -st, 0.0, 1.0, 0.0, st, 0.0, c_theta);
        let tp = Vector3::new(x1, 0.0, -x3) * (d1 - d3);
        out.push((rp, tp, Vector3::new(x1, 0.0, x3)));
        let sp = e1 * e3 * s_phi;
        let rp = Matrix3::new(c_phi, 0.0, sp, 0.0, -1.0, 0.0, sp, 0.0, -c_phi);
        let tp = Vector3::new(x1, 0.0, x3) * (d1 + d3);
        out.push((rp, tp, Vector3::new(x1, 0.0, x3)));
    }
    Some(
        out.into_iter()
            .filter_map(|(rp, tp, np)| {
                let r = s * u * rp * v_t;
                // t/d with d the distance of camera 1 from the plane along n
                let t = u * tp;
                let mut n = v * np;
                if n.z < 0.0 {
                    n = -n;
                }
                let rotation =
                    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
                (r.iter().all(|x| x.is_finite()) && t.iter().all(|x| x.is_finite())).then(|| {
                    PlanarMotion {
                        cam2_from_cam1: Pose::from_parts(Translation3::from(t), rotation),
                        normal_in_cam1: Unit::new_normalize(n),
                    }
                })
            })
            .collect(),
    )
}

/// Two factorisations whose rotations differ by less than this, radians, and whose translations
/// point the same way are one motion for [`relative_pose_from_homography`] (the pair of
/// solutions merges as `t` turns parallel to `n`).
const SAME_ROTATION_RAD: f64 = 1e-3;

/// The motion of a homography chosen by cheirality: the factorisation that puts the most
/// correspondences in front of both cameras; `None` when none does or when the best is not
/// clearly ahead of every factorisation with a different motion, a translation direction or
/// rotation of its own (fewer than `margin` times its count).
#[must_use]
pub fn relative_pose_from_homography(
    h: &Matrix3<f64>,
    camera: &PinholeCamera,
    data: &[&Correspondence],
    margin: f64,
) -> Option<(PlanarMotion, usize)> {
    let candidates = decompose_homography(h, camera)?;
    let rays: Vec<(Vector3<f64>, Vector3<f64>)> = data
        .iter()
        .map(|c| (camera.ray(&c.p1_px), camera.ray(&c.p2_px)))
        .collect();
    let counted: Vec<(PlanarMotion, usize)> = candidates
        .into_iter()
        .map(|m| {
            let n = rays
                .iter()
                .filter(|(r1, r2)| in_front_of_both(r1, r2, &m.cam2_from_cam1))
                .count();
            (m, n)
        })
        .collect();
    let (best, n) = counted.iter().max_by_key(|(_, n)| *n).copied()?;
    let t_best = best.cam2_from_cam1.translation.vector.normalize();
    let rival = counted
        .iter()
        .filter(|(m, _)| {
            m.cam2_from_cam1.translation.vector.normalize().dot(&t_best) < 0.999
                || (m.cam2_from_cam1.rotation.inverse() * best.cam2_from_cam1.rotation).angle()
                    > SAME_ROTATION_RAD
        })
        .map(|(_, n)| *n)
        .max()
        .unwrap_or(0);
    (n > 0 && (rival as f64) < margin * n as f64).then_some((best, n))
}

/// The plane-with-known-normal fit's settings ([`relative_pose_with_plane_normal`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownNormalFit {
    /// Gauss–Newton iterations at most.
    pub max_iterations: usize,
    /// A correspondence whose squared Mahalanobis transfer error exceeds this many times the
    /// median's is an outlier (weight 0) in an iteration.
    pub outlier_gate: f64,
}

impl Default for KnownNormalFit {
    fn default() -> Self {
        Self {
            max_iterations: 15,
            outlier_gate: 9.0,
        }
    }
}

/// The motion between two views of a plane whose unit normal in camera 1 is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownNormalMotion {
    /// `cam2_from_cam1` with a unit translation.
    pub cam2_from_cam1: Pose,
    /// The correspondences within the outlier gate at the solution.
    pub inliers: usize,
}

/// The motion between two views of the plane `nᵀX = d` (camera 1) whose unit normal `n`
/// (`normal_in_cam1`, pointing from the camera to the plane) is known: the rotation `R` and
/// `t/d` of the calibrated homography `K⁻¹ H K = R + (t/d) nᵀ` (the decomposition's model,
/// Faugeras & Lustman 1988) by Gauss–Newton from the identity on the squared Mahalanobis
/// transfer errors `eᵀ Y e`, `e = p2 − H p1` (the flow's information `Y`, as in eq. 11 of the
/// monocular paper), the worst correspondences gated out in each iteration
/// ([`KnownNormalFit::outlier_gate`]).
///
/// Six unknowns instead of the homography's eight: a downward view of flat ground, the
/// eight-point algorithm's degenerate case, leaves the homography's decomposition choosing
/// among motions that trade a translation for a rotation and a tilted normal; with the normal
/// held, the small translation of a slow flight stays a translation. `None` with fewer than
/// eight correspondences, no convergence to a finite motion, or no translation.
#[must_use]
pub fn relative_pose_with_plane_normal(
    data: &[Correspondence],
    camera: &PinholeCamera,
    normal_in_cam1: &Unit<Vector3<f64>>,
    fit: &KnownNormalFit,
) -> Option<KnownNormalMotion> {
    if data.len() < 8 {
        return None;
    }
    let rays: Vec<Vector3<f64>> = data.iter().map(|c| camera.ray(&c.p1_px)).collect();
    let mut params = Vector6::<f64>::zeros();
    let mut inliers = 0;
    for _ in 0..fit.max_iterations {
        let (step, n) = gauss_newton_step(data, &rays, camera, normal_in_cam1, &params, fit)?;
        params += step;
        inliers = n;
        if step.norm() < 1e-10 {
            break;
        }
    }
    let (rotation, t) = known_normal_motion(&params, normal_in_cam1).1;
    let length = t.norm();
    (params.iter().all(|v| v.is_finite()) && length > 0.0).then(|| KnownNormalMotion {
        cam2_from_cam1: Pose::from_parts(
            Translation3::from(t / length),
            UnitQuaternion::from_rotation_matrix(&rotation),
        ),
        inliers,
    })
}

/// `K⁻¹ H K = R + t nᵀ` of the parameters (the rotation's axis-angle, `t/d`), and `(R, t)`.
fn known_normal_motion(
    params: &Vector6<f64>,
    n: &Unit<Vector3<f64>>,
) -> (Matrix3<f64>, (Rotation3<f64>, Vector3<f64>)) {
    let rotation = Rotation3::new(params.fixed_rows::<3>(0).into_owned());
    let t: Vector3<f64> = params.fixed_rows::<3>(3).into_owned();
    (rotation.matrix() + t * n.transpose(), (rotation, t))
}

/// One Gauss–Newton step of [`relative_pose_with_plane_normal`] (forward-difference Jacobian
/// of the transfer error, inliers within the gate) and the inliers' count.
fn gauss_newton_step(
    data: &[Correspondence],
    rays: &[Vector3<f64>],
    camera: &PinholeCamera,
    n: &Unit<Vector3<f64>>,
    params: &Vector6<f64>,
    fit: &KnownNormalFit,
) -> Option<(Vector6<f64>, usize)> {
    const DELTA: f64 = 1e-7;
    let transfer = |h: &Matrix3<f64>, ray: &Vector3<f64>| camera.project(&Point3::from(h * ray));
    let h0 = known_normal_motion(params, n).0;
    let perturbed: Vec<Matrix3<f64>> = (0..6)
        .map(|k| {
            let mut p = *params;
            p[k] += DELTA;
            known_normal_motion(&p, n).0
        })
        .collect();
    let errors: Vec<Option<(Vector2<f64>, f64)>> = data
        .iter()
        .zip(rays)
        .map(|(c, ray)| {
            let e = c.p2_px - transfer(&h0, ray)?;
            Some((e, e.dot(&(c.information * e))))
        })
        .collect();
    let mut squared: Vec<f64> = errors.iter().flatten().map(|(_, sq)| *sq).collect();
    if squared.len() < 8 {
        return None;
    }
    let mid = squared.len() / 2;
    let gate = fit.outlier_gate
        * squared
            .select_nth_unstable_by(mid, f64::total_cmp)
            .1
            .max(1e-14);
    let (mut jtj, mut jtr, mut inliers) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros(), 0);
    for ((c, ray), error) in data.iter().zip(rays).zip(&errors) {
        let Some((e, _)) = error.filter(|(_, sq)| *sq <= gate) else {
            continue;
        };
        let transferred = c.p2_px - e;
        let mut jac = SMatrix::<f64, 2, 6>::zeros();
        for (k, h) in perturbed.iter().enumerate() {
            // e = p2 − H p1: its derivative is minus the transfer's
            let Some(moved) = transfer(h, ray) else {
                continue;
            };
            jac.set_column(k, &(-(moved - transferred) / DELTA));
        }
        let jty = jac.transpose() * c.information;
        jtj += jty * jac;
        jtr += jty * e;
        inliers += 1;
    }
    let step = jtj.cholesky()?.solve(&(-jtr));
    step.iter()
        .all(|v| v.is_finite())
        .then_some((step, inliers))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    fn camera() -> PinholeCamera {
        PinholeCamera::new(360.0, 360.0, 310.0, 94.0, 620, 188).unwrap()
    }

    /// Correspondences of points on the plane `n·X = d` (camera 1) seen after `cam2_from_cam1`.
    fn plane_views(cam2_from_cam1: &Pose, n: &Vector3<f64>, d: f64) -> Vec<Correspondence> {
        let cam = camera();
        let mut out = Vec::new();
        for gy in 0..12 {
            for gx in 0..20 {
                let px = Point2::new(15.0 + 30.0 * f64::from(gx), 8.0 + 15.0 * f64::from(gy));
                let ray = cam.ray(&px);
                let depth_along_ray = d / n.dot(&ray);
                if depth_along_ray <= 0.0 {
                    continue;
                }
                let p1 = nalgebra::Point3::from(ray * depth_along_ray);
                let p2 = cam2_from_cam1 * p1;
                if let Some(q) = cam.project(&p2) {
                    out.push(Correspondence::isotropic(px, q, 0.5));
                }
            }
        }
        out
    }

    #[test]
    fn a_plane_seen_twice_gives_its_motion_and_normal_back() {
        let cam = camera();
        // a downward camera 30 m above the ground, moving 1.5 m forward and 0.3 m down, turning
        let n = Vector3::new(0.1, 0.2, 1.0).normalize();
        let d = 30.0;
        let pose = Pose::from_parts(
            Translation3::new(0.4, -1.5, 0.3),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 0.03),
        );
        let data = plane_views(&pose, &n, d);
        let refs: Vec<&Correspondence> = data.iter().collect();
        let h = homography_dlt(&refs).unwrap();
        assert!(data.iter().all(|c| transfer_error_sq(&h, c) < 1e-10));
        // any scale and sign of H decomposes alike
        for scale in [1.0, -3.0] {
            let candidates = decompose_homography(&(h * scale), &cam).unwrap();
            assert_eq!(candidates.len(), 8);
            let hit = candidates.iter().any(|m| {
                (m.cam2_from_cam1.rotation.inverse() * pose.rotation).angle() < 1e-6
                    && (m.cam2_from_cam1.translation.vector - pose.translation.vector / d).norm()
                        < 1e-6
                    && (m.normal_in_cam1.into_inner() - n).norm() < 1e-6
            });
            assert!(hit, "{candidates:?}");
            let (best, in_front) = relative_pose_from_homography(&(h * scale), &cam, &refs, 0.9)
                .expect("a clear winner");
            assert_eq!(in_front, data.len());
            assert!((best.cam2_from_cam1.rotation.inverse() * pose.rotation).angle() < 1e-6);
            let t = best.cam2_from_cam1.translation.vector;
            assert!((t - pose.translation.vector / d).norm() < 1e-6, "{t}");
        }
    }

    #[test]
    fn ransac_finds_the_plane_among_outliers_and_the_score_prefers_it() {
        let n = Vector3::new(0.0, 0.0, 1.0);
        let pose = Pose::from_parts(
            Translation3::new(0.0, -1.0, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.02),
        );
        let mut data = plane_views(&pose, &n, 30.0);
        let clean = data.len();
        for (i, c) in data.iter_mut().enumerate().filter(|(i, _)| i % 5 == 0) {
            c.p2_px.x += 7.0 + (i % 3) as f64;
        }
        let mut rng = crate::seeded_rng(1);
        let config = RansacConfig {
            inlier_threshold: CHI2_2DOF_95,
            ..RansacConfig::default()
        };
        let r = estimate_homography(&data, &config, &mut rng).unwrap();
        assert_eq!(r.inlier_count, clean - clean.div_ceil(5));
        // GRIC prefers the fitted homography to one that explains nothing
        let g = |h: &Matrix3<f64>| gric(data.iter().map(|c| transfer_error_sq(h, c)), 2, 8);
        let off = Matrix3::new(1.0, 0.0, 50.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(g(&r.model) < g(&off));
        // degenerate input: fewer than four points, or all points on one line
        assert!(homography_dlt(&data.iter().take(3).collect::<Vec<_>>()).is_none());
    }

    #[test]
    fn a_motion_along_the_plane_normal_decomposes() {
        // descending straight onto the plane: t ∥ n, two singular values equal
        let n = Vector3::new(0.0, 0.0, 1.0);
        let pose = Pose::from_parts(
            Translation3::new(0.0, 0.0, -2.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.0),
        );
        let data = plane_views(&pose, &n, 20.0);
        let refs: Vec<&Correspondence> = data.iter().collect();
        let h = homography_dlt(&refs).unwrap();
        let candidates = decompose_homography(&h, &camera()).unwrap();
        assert!(candidates.iter().any(|m| {
            m.cam2_from_cam1.rotation.angle() < 1e-6
                && (m.cam2_from_cam1.translation.vector - pose.translation.vector / 20.0).norm()
                    < 1e-6
        }));
        let (best, _) = relative_pose_from_homography(&h, &camera(), &refs, 0.75).unwrap();
        assert!((best.cam2_from_cam1.translation.vector.normalize() - -n).norm() < 1e-6);
    }

    #[test]
    fn a_plane_with_its_normal_known_gives_small_steps_and_turns_back_among_outliers() {
        // a low downward camera: a 1.5 % (of the height) sideways step with a 0.3° yaw, a
        // climb along the normal, and a turn on the spot with a barely measurable step
        let n = Unit::new_normalize(Vector3::new(0.05, -0.1, 1.0));
        let steps = [
            (Translation3::new(0.015, 0.004, 0.0), (0.0, 0.0, 0.005)),
            (Translation3::new(0.0, 0.0, -0.02), (0.002, -0.001, 0.0)),
            (Translation3::new(0.001, 0.0, 0.0), (0.0, 0.0, 0.05)),
        ];
        for (t, (roll, pitch, yaw)) in steps {
            let pose = Pose::from_parts(t, UnitQuaternion::from_euler_angles(roll, pitch, yaw));
            let mut data = plane_views(&pose, &n, 1.0);
            for (i, c) in data.iter_mut().enumerate().filter(|(i, _)| i % 7 == 0) {
                c.p2_px.y -= 6.0 + (i % 4) as f64;
            }
            let fit = KnownNormalFit::default();
            let m = relative_pose_with_plane_normal(&data, &camera(), &n, &fit).unwrap();
            assert_eq!(m.inliers, data.len() - data.len().div_ceil(7));
            let rotation_error = (m.cam2_from_cam1.rotation.inverse() * pose.rotation).angle();
            assert!(rotation_error < 1e-6, "{rotation_error}");
            let direction = m.cam2_from_cam1.translation.vector;
            assert!(
                (direction - t.vector.normalize()).norm() < 1e-5,
                "{direction}"
            );
        }
        // too few correspondences
        let few = plane_views(&Pose::identity(), &n, 1.0);
        assert!(
            relative_pose_with_plane_normal(&few[..7], &camera(), &n, &KnownNormalFit::default())
                .is_none()
        );
    }

    proptest::proptest! {
        /// For any motion with a translation of 0.02–0.3 plane distances and any visible plane
        /// tilted up to 60°, the decomposition contains the true `(R, t/d, n)` (also along the
        /// normal, where two singular values are equal) and cheirality picks it whenever it is
        /// unambiguous.
        #[test]
        fn the_decomposition_contains_the_true_motion(
            rx in -0.1..0.1f64, ry in -0.1..0.1f64, rz in -0.1..0.1f64,
            tx in -1.0..1.0f64, ty in -1.0..1.0f64, tz in -1.0..1.0f64,
            t_over_d in 0.02..0.3f64,
            nx in -0.5..0.5f64, ny in -0.5..0.5f64,
            d in 5.0..500.0f64,
        ) {
            let cam = camera();
            let dir = Vector3::new(tx, ty, tz);
            proptest::prop_assume!(dir.norm() > 0.2);
            let t = dir.normalize() * t_over_d * d;
            let pose = Pose::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_euler_angles(rx, ry, rz),
            );
            let n = Vector3::new(nx, ny, 1.0).normalize();
            let data = plane_views(&pose, &n, d);
            proptest::prop_assume!(data.len() >= 20);
            let refs: Vec<&Correspondence> = data.iter().collect();
            let h = homography_dlt(&refs).unwrap();
            let candidates = decompose_homography(&h, &cam).unwrap();
            let hit = candidates.iter().any(|m| {
                (m.cam2_from_cam1.rotation.inverse() * pose.rotation).angle() < 1e-5
                    && (m.cam2_from_cam1.translation.vector - t / d).norm() < 1e-5 * (1.0 + t_over_d)
                    && (m.normal_in_cam1.into_inner() - n).norm() < 1e-4
            });
            proptest::prop_assert!(hit, "{:?}", candidates);
            // within the merging pair's tolerance (near t ∥ n both solutions are in front)
            if let Some((best, _)) = relative_pose_from_homography(&h, &cam, &refs, 0.75) {
                proptest::prop_assert!(
                    (best.cam2_from_cam1.rotation.inverse() * pose.rotation).angle()
                        < SAME_ROTATION_RAD
                );
            }
        }
    }
}
