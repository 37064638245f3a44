//! The fundamental matrix from pixel correspondences (Ng, Li, Kim 2021, §4).
//!
//! `x2ᵀ F x1 = 0` (eq. 5) for homogeneous pixels `x1`, `x2`. Every variant stacks the rows of
//! eq. 6 in Hartley-normalised coordinates (centroid at the origin, mean distance √2) and takes
//! the null vector of `AᵀA` (the right singular vector of `A` of least singular value):
//!
//! * [`Estimator::Algebraic`]: one solve of eq. 6 (Hartley's normalised eight-point);
//! * [`Estimator::Sampson`]: iterative re-weighting of each row by `φ_i` of eq. 8 (eq. 7);
//! * [`Estimator::Mahalanobis`]: iterative re-weighting by `φ_i` of eq. 9/12 computed from the
//!   information matrix of the second pixel, so that `φ_i |x2ᵀ F x1|` is the minimum Mahalanobis
//!   distance of `x2` to the epipolar line `F x1` (eq. 11).
//!
//! The rank-2 constraint is enforced (smallest singular value zeroed) after every solve.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::correspondence::Correspondence;
use crate::ransac::{RansacConfig, RansacProblem, RansacResult, ransac};
use crate::{GeometryError, check};

/// Which eight-point variant refines `F` on the inliers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Hartley-normalised eight-point (algebraic error, eq. 6).
    Algebraic,
    /// Sampson-weighted iteratively re-weighted eight-point (eq. 7–8).
    Sampson,
    /// Mahalanobis-weighted iteratively re-weighted eight-point (eq. 9–12), the paper's method.
    #[default]
    Mahalanobis,
}

/// Parameters of the eight-point refinement and of its RANSAC.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EightPointConfig {
    /// The refinement on the inliers. Default Mahalanobis.
    pub estimator: Estimator,
    /// Maximum re-weighting iterations (Sampson / Mahalanobis). Default 10.
    pub max_reweight_iterations: usize,
    /// Stop re-weighting when `‖f_k − f_{k−1}‖` (unit vectors) falls below this. Default 1e-10.
    pub convergence_tol: f64,
    /// RANSAC; the threshold is on the squared Mahalanobis distance (eq. 11), default
    /// 3.84 = χ²(1 dof, 95 %).
    pub ransac: RansacConfig,
}

impl Default for EightPointConfig {
    fn default() -> Self {
        Self {
            estimator: Estimator::Mahalanobis,
            max_reweight_iterations: 10,
            convergence_tol: 1e-10,
            ransac: RansacConfig::default(),
        }
    }
}

impl EightPointConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`GeometryError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check(
            self.convergence_tol >= 0.0,
            "eight_point.convergence_tol",
            self.convergence_tol,
            ">= 0",
        )?;
        self.ransac.validate()
    }
}

/// Hartley normalisation `T` (centroid to origin, mean distance √2); `None` if degenerate.
pub(crate) fn hartley<'a>(
    points: impl Iterator<Item = &'a nalgebra::Point2<f64>> + Clone,
) -> Option<Matrix3<f64>> {
    let mut n = 0.0;
    let mut c = nalgebra::Vector2::zeros();
    for p in points.clone() {
        c += p.coords;
        n += 1.0;
    }
    if n < 1.0 {
        return None;
    }
    c /= n;
    let mean_dist = points.map(|p| (p.coords - c).norm()).sum::<f64>() / n;
    if mean_dist <= 1e-12 || !mean_dist.is_finite() {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean_dist;
    Some(Matrix3::new(
        s,
        0.0,
        -s * c.x,
        0.0,
        s,
        -s * c.y,
        0.0,
        0.0,
        1.0,
    ))
}

/// Zeroes the smallest singular value (rank-2 constraint).
#[must_use]
pub fn enforce_rank2(f: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = f.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return *f;
    };
    let mut s = svd.singular_values;
    // nalgebra sorts singular values in decreasing order
    s[2] = 0.0;
    u * Matrix3::from_diagonal(&s) * v_t
}

/// The epipolar line `l = F x1 = (a, b, c)` in image 2.
#[inline]
fn line2(f: &Matrix3<f64>, c: &Correspondence) -> Vector3<f64> {
    f * Vector3::new(c.p1_px.x, c.p1_px.y, 1.0)
}

/// Algebraic residual `x2ᵀ F x1`.
#[inline]
#[must_use]
pub fn algebraic_residual(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let l = line2(f, c);
    l.x * c.p2_px.x + l.y * c.p2_px.y + l.z
}

/// `φ` of eq. 8 (Sampson weight); 0 when undefined.
#[must_use]
pub fn sampson_weight(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let l2 = line2(f, c);
    let l1 = f.transpose() * Vector3::new(c.p2_px.x, c.p2_px.y, 1.0);
    let den = l2.x * l2.x + l2.y * l2.y + l1.x * l1.x + l1.y * l1.y;
    if den > 0.0 { 1.0 / den.sqrt() } else { 0.0 }
}

/// `φ` of eq. 9 / eq. 12 (Mahalanobis weight) for the line `F x1 = (a, b, c)`:
/// `sqrt((YxxYyy − Yxy²) / (a²Yyy + b²Yxx − 2abYxy))`; 0 when undefined.
#[must_use]
pub fn mahalanobis_weight(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let l = line2(f, c);
    let y = &c.information;
    let (yxx, yxy, yyy) = (y[(0, 0)], 0.5 * (y[(0, 1)] + y[(1, 0)]), y[(1, 1)]);
    let det = yxx * yyy - yxy * yxy;
    let den = l.x * l.x * yyy + l.y * l.y * yxx - 2.0 * l.x * l.y * yxy;
    if det > 0.0 && den > 0.0 {
        (det / den).sqrt()
    } else {
        0.0
    }
}

/// Squared minimum Mahalanobis distance of `p2_px` to the epipolar line `F p1_px` (eq. 11²),
/// dimensionless (χ² with one degree of freedom under the flow's Gaussian model).
#[must_use]
pub fn mahalanobis_distance_sq(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let r = algebraic_residual(f, c) * mahalanobis_weight(f, c);
    if r.is_finite() { r * r } else { f64::INFINITY }
}

/// The null vector of the 9x9 `AᵀA` of a direct linear transform
/// ([`crate::smallest_eigenvector`])
/// as the 3x3 matrix it stands for (row-major).
pub(crate) fn dlt_solution(ata: &SMatrix<f64, 9, 9>) -> Option<Matrix3<f64>> {
    let v = crate::smallest_eigenvector(ata)?;
    Some(Matrix3::new(
        v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8],
    ))
}

/// Weighted normalised eight-point: null vector of `Σ φ_i² a_i a_iᵀ` (rows of eq. 6/7) in
/// Hartley coordinates, rank 2, returned in pixels and scaled to unit Frobenius norm.
fn solve_weighted(
    data: &[&Correspondence],
    weights: Option<&[f64]>,
    t1: &Matrix3<f64>,
    t2: &Matrix3<f64>,
) -> Option<Matrix3<f64>> {
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (i, c) in data.iter().enumerate() {
        let w = weights.map_or(1.0, |w| w[i]);
        if w <= 0.0 || !w.is_finite() {
            continue;
        }
        let a = t1 * Vector3::new(c.p1_px.x, c.p1_px.y, 1.0);
        let b = t2 * Vector3::new(c.p2_px.x, c.p2_px.y, 1.0);
        let row = SVector::<f64, 9>::from_column_slice(&[
            b.x * a.x,
            b.x * a.y,
            b.x,
            b.y * a.x,
            b.y * a.y,
            b.y,
            a.x,
            a.y,
            1.0,
        ]);
        ata += (w * w) * row * row.transpose();
    }
    let f_norm = dlt_solution(&ata)?;
    let f_px = t2.transpose() * enforce_rank2(&f_norm) * t1;
    let n = f_px.norm();
    (n > 0.0 && n.is_finite()).then(|| f_px / n)
}

/// Fundamental matrix (unit Frobenius norm, rank 2, in pixels) from ≥ 8 correspondences with the
/// chosen estimator; `None` when degenerate.
#[must_use]
pub fn eight_point(
    data: &[&Correspondence],
    estimator: Estimator,
    max_iterations: usize,
    convergence_tol: f64,
) -> Option<Matrix3<f64>> {
    if data.len() < 8 {
        return None;
    }
    let t1 = hartley(data.iter().map(|c| &c.p1_px))?;
    let t2 = hartley(data.iter().map(|c| &c.p2_px))?;
    let mut f = solve_weighted(data, None, &t1, &t2)?;
    if estimator == Estimator::Algebraic {
        return Some(f);
    }
    let mut weights = vec![0.0; data.len()];
    for _ in 0..max_iterations {
        for (w, c) in weights.iter_mut().zip(data) {
            *w = match estimator {
                Estimator::Sampson => sampson_weight(&f, c),
                _ => mahalanobis_weight(&f, c),
            };
        }
        // guard against a few near-zero lines dominating: cap at 100x the median weight
        let mut sorted = weights.clone();
        sorted.sort_by(f64::total_cmp);
        let cap = 100.0 * sorted[sorted.len() / 2];
        if cap > 0.0 {
            for w in &mut weights {
                *w = w.min(cap);
            }
        }
        let next = solve_weighted(data, Some(&weights), &t1, &t2)?;
        // F and −F are the same model
        let delta = (next - f).norm().min((next + f).norm());
        f = next;
        if delta < convergence_tol {
            break;
        }
    }
    Some(f)
}

/// The uncertainty-guided RANSAC problem for `F`: minimal fits by the algebraic eight-point,
/// residual the squared Mahalanobis distance to the epipolar line (eq. 11), refit with `estimator`.
#[derive(Debug, Clone, Copy)]
pub struct FundamentalProblem {
    /// Refinement estimator.
    pub estimator: Estimator,
    /// Maximum re-weighting iterations.
    pub max_reweight_iterations: usize,
    /// Re-weighting convergence tolerance.
    pub convergence_tol: f64,
}

impl RansacProblem for FundamentalProblem {
    type Sample = Correspondence;
    type Model = Matrix3<f64>;
    const MIN_SAMPLES: usize = 8;

    fn fit_minimal(&self, samples: &[&Correspondence]) -> Vec<Matrix3<f64>> {
        eight_point(samples, Estimator::Algebraic, 0, 0.0)
            .into_iter()
            .collect()
    }

    fn residual_sq(&self, model: &Matrix3<f64>, sample: &Correspondence) -> f64 {
        mahalanobis_distance_sq(model, sample)
    }

    fn refit(&self, inliers: &[&Correspondence], _: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        eight_point(
            inliers,
            self.estimator,
            self.max_reweight_iterations,
            self.convergence_tol,
        )
    }
}

/// Result of [`estimate_fundamental`].
pub type FundamentalRansacResult = RansacResult<Matrix3<f64>>;

/// Uncertainty-guided RANSAC for `F` followed by the refinement of `config.estimator` on the
/// inliers. Samples are drawn with probability ∝ [`Correspondence::certainty`].
pub fn estimate_fundamental<R: Rng>(
    data: &[Correspondence],
    config: &EightPointConfig,
    rng: &mut R,
) -> Option<FundamentalRansacResult> {
    let problem = FundamentalProblem {
        estimator: config.estimator,
        max_reweight_iterations: config.max_reweight_iterations,
        convergence_tol: config.convergence_tol,
    };
    let weights: Vec<f64> = data.iter().map(Correspondence::certainty).collect();
    ransac(&problem, data, Some(&weights), &config.ransac, rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Point2};

    #[test]
    fn mahalanobis_distance_matches_brute_force() {
        // line x + 2y - 3 = 0 through F with F x1 = l for x1 = (0,0,1): third column = l
        let f = Matrix3::new(0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, -3.0);
        let y = Matrix2::new(4.0, 1.0, 1.0, 0.5);
        let c = Correspondence {
            p1_px: Point2::new(0.0, 0.0),
            p2_px: Point2::new(2.0, 3.0),
            information: y,
        };
        let d2 = mahalanobis_distance_sq(&f, &c);
        // brute force: minimise over points on the line
        let mut best = f64::INFINITY;
        for i in -200_000..200_000 {
            let x = f64::from(i) * 1e-4;
            let yy = (3.0 - x) / 2.0;
            let e = nalgebra::Vector2::new(x - 2.0, yy - 3.0);
            best = best.min((e.transpose() * y * e)[0]);
        }
        assert!((d2 - best).abs() < 1e-6, "{d2} vs {best}");
        // isotropic information reduces to the scaled Euclidean distance
        let iso = Correspondence::isotropic(c.p1_px, c.p2_px, 2.0);
        let e = (2.0 + 6.0 - 3.0_f64) / 5.0_f64.sqrt();
        assert!((mahalanobis_distance_sq(&f, &iso) - e * e / 4.0).abs() < 1e-12);
    }

    #[test]
    fn rank2_and_serde() {
        let f = enforce_rank2(&Matrix3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0));
        assert!(f.determinant().abs() < 1e-9);
        let cfg: EightPointConfig = serde_json::from_str(r#"{"estimator":"sampson"}"#).unwrap();
        assert_eq!(cfg.estimator, Estimator::Sampson);
        assert!(serde_json::from_str::<EightPointConfig>(r#"{"bogus":1}"#).is_err());
        assert!(cfg.validate().is_ok());
    }
}
