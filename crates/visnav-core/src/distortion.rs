//! Lens distortion models and calibrated (distorted) cameras.
//!
//! Both models act on *normalised* image coordinates `(x, y) = (X/Z, Y/Z)` of a point in the camera
//! frame (x right, y down, z forward). [`Distortion::distort`] maps the ideal pinhole coordinates to
//! the distorted ones that `K` turns into pixels; [`Distortion::undistort`] inverts it by Newton
//! iterations.
//!
//! * [`Distortion::RadialTangential`]: OpenCV / Kalibr `radtan` (Brown–Conrady),
//!   `x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)`,
//!   `y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y`, `r² = x² + y²`.
//! * [`Distortion::Equidistant`]: Kannala–Brandt as in OpenCV `fisheye` / Kalibr `equidistant`,
//!   `θ = atan(r)`, `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`, `(x_d, y_d) = (θ_d / r) (x, y)`.
//! * [`Distortion::Fov`]: the field-of-view (ATAN) model of Devernay and Faugeras ("Straight lines
//!   have to be straight", MVA 2001, eq. 13–14) as in DSO, PTAM and the TUM monoVO benchmark,
//!   `r_d = atan(2 r_u tan(ω/2)) / ω`, inverted in closed form by `r_u = tan(r_d ω) / (2 tan(ω/2))`
//!   (valid for `r_d ω < π/2`), `(x_d, y_d) = (r_d / r_u) (x, y)`.
//!
//! Neither paper calibrates cameras; these are the standard models of the datasets visnav reads
//! (EuRoC uses `radtan`, fisheye rigs `equidistant`, the TUM monoVO benchmark `fov`).

use nalgebra::{Matrix2, Point2, Point3};
use serde::{Deserialize, Serialize};

use crate::camera::PinholeCamera;

/// Newton iterations of [`Distortion::undistort`].
const UNDISTORT_MAX_ITERATIONS: usize = 30;
/// Convergence threshold of [`Distortion::undistort`] on the normalised residual.
const UNDISTORT_TOLERANCE: f64 = 1e-13;

/// A lens distortion model with its coefficients (dimensionless, on normalised coordinates).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum Distortion {
    /// An ideal pinhole: no distortion.
    #[default]
    None,
    /// Radial–tangential (OpenCV `k1 k2 p1 p2 [k3]`, Kalibr `radtan`).
    RadialTangential {
        /// Radial coefficient of r².
        k1: f64,
        /// Radial coefficient of r⁴.
        k2: f64,
        /// Tangential coefficient p1.
        p1: f64,
        /// Tangential coefficient p2.
        p2: f64,
        /// Radial coefficient of r⁶ (0 when the calibration has four coefficients).
        #[serde(default)]
        k3: f64,
    },
    /// Equidistant fisheye (Kannala–Brandt, OpenCV `fisheye`, Kalibr `equidistant`).
    Equidistant {
        /// Coefficient of θ³.
        k1: f64,
        /// Coefficient of θ⁵.
        k2: f64,
        /// Coefficient of θ⁷.
        k3: f64,
        /// Coefficient of θ⁹.
        k4: f64,
    },
    /// Field-of-view / ATAN model (Devernay–Faugeras; DSO `FOV`, Kalibr-style `fov`).
    Fov {
        /// Field of view of the ideal fisheye lens, radians (0: no distortion).
        omega: f64,
    },
}

impl Distortion {
    /// Whether any coefficient is non-zero.
    #[must_use]
    pub fn is_identity(&self) -> bool {
        match *self {
            Self::None => true,
            Self::RadialTangential { k1, k2, p1, p2, k3 } => [k1, k2, p1, p2, k3] == [0.0; 5],
            Self::Equidistant { .. } => false,
            Self::Fov { omega } => omega == 0.0,
        }
    }

    /// The coefficients, for messages and checks.
    #[must_use]
    pub fn coefficients(&self) -> Vec<f64> {
        match *self {
            Self::None => Vec::new(),
            Self::RadialTangential { k1, k2, p1, p2, k3 } => vec![k1, k2, p1, p2, k3],
            Self::Equidistant { k1, k2, k3, k4 } => vec![k1, k2, k3, k4],
            Self::Fov { omega } => vec![omega],
        }
    }

    /// Distorts ideal normalised coordinates (module doc for the formulas).
    #[must_use]
    pub fn distort(&self, x_ideal: &Point2<f64>) -> Point2<f64> {
        self.distort_with_jacobian(x_ideal).0
    }

    /// Distortion and its 2x2 Jacobian `∂x_d/∂x` (analytic).
    #[must_use]
    pub fn distort_with_jacobian(&self, x_ideal: &Point2<f64>) -> (Point2<f64>, Matrix2<f64>) {
        let (x, y) = (x_ideal.x, x_ideal.y);
        match *self {
            Self::None => (*x_ideal, Matrix2::identity()),
            Self::RadialTangential { k1, k2, p1, p2, k3 } => {
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                // d radial / d r2
                let d_radial = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);
                let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
                let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
                let j = Matrix2::new(
                    radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
                    2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
                    2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
                    radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
                );
                (Point2::new(xd, yd), j)
            }
            Self::Equidistant { k1, k2, k3, k4 } => {
                let r = (x * x + y * y).sqrt();
                if r < 1e-12 {
                    // θ_d / r → 1 at the centre
                    return (*x_ideal, Matrix2::identity());
                }
                let (theta_d, d_theta_d) = equidistant_theta_d([k1, k2, k3, k4], r.atan());
                let s = theta_d / r;
                // ds/dr = (θ_d' θ' r - θ_d) / r², θ' = 1 / (1 + r²)
                let ds_dr = (d_theta_d / (1.0 + r * r) * r - theta_d) / (r * r);
                radial_scaling(x_ideal, r, s, ds_dr)
            }
            Self::Fov { omega } => distort_fov(omega, x_ideal),
        }
    }

    /// Inverts [`Self::distort`] by Newton iterations started at the distorted point; `None` when
    /// they do not converge (a point outside the model's invertible region).
    #[must_use]
    pub fn undistort(&self, x_distorted: &Point2<f64>) -> Option<Point2<f64>> {
        if matches!(self, Self::None) {
            return Some(*x_distorted);
        }
        if let Self::Equidistant { k1, k2, k3, k4 } = *self {
            return undistort_equidistant([k1, k2, k3, k4], x_distorted);
        }
        if let Self::Fov { omega } = *self {
            return undistort_fov(omega, x_distorted);
        }
        let target = x_distorted.coords;
        let mut x = *x_distorted;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let (xd, j) = self.distort_with_jacobian(&x);
            let residual = xd.coords - target;
            if residual.norm() < UNDISTORT_TOLERANCE {
                return Some(x);
            }
            let step = j.try_inverse()? * residual;
            // damp steps that would jump far (keeps Newton in the monotonic region)
            let step = if step.norm() > 0.5 {
                step * (0.5 / step.norm())
            } else {
                step
            };
            x -= step;
        }
        let (xd, _) = self.distort_with_jacobian(&x);
        ((xd.coords - target).norm() < 1e-9).then_some(x)
    }
}

/// `r_d / r_u` of the FOV model at radius `r_u` and its derivative by `r_u`.
fn fov_scale(omega: f64, r_u: f64) -> (f64, f64) {
    let a = 2.0 * (omega / 2.0).tan();
    if r_u < 1e-8 {
        // atan(a r) / (ω r) = (a / ω) (1 - a² r² / 3 + …)
        return (a / omega, -2.0 * a * a * a * r_u / (3.0 * omega));
    }
    let r_d = (a * r_u).atan() / omega;
    let d_r_d = a / (omega * (1.0 + a * a * r_u * r_u));
    (r_d / r_u, (d_r_d * r_u - r_d) / (r_u * r_u))
}

/// The FOV distortion and its Jacobian.
fn distort_fov(omega: f64, x_ideal: &Point2<f64>) -> (Point2<f64>, Matrix2<f64>) {
    if omega == 0.0 {
        return (*x_ideal, Matrix2::identity());
    }
    let (x, y) = (x_ideal.x, x_ideal.y);
    let r = (x * x + y * y).sqrt();
    let (s, ds_dr) = fov_scale(omega, r);
    radial_scaling(x_ideal, r, s, ds_dr)
}

/// A radial model's map `p ↦ s(r) p` (`r = |p|`) and its Jacobian
/// `∂(s x)/∂x = s + x s'(r) x / r` (and alike); at `r = 0` the second term vanishes.
fn radial_scaling(p: &Point2<f64>, r: f64, s: f64, ds_dr: f64) -> (Point2<f64>, Matrix2<f64>) {
    let (x, y) = (p.x, p.y);
    let (ux, uy) = if r > 0.0 { (x / r, y / r) } else { (0.0, 0.0) };
    let j = Matrix2::new(
        s + x * ds_dr * ux,
        x * ds_dr * uy,
        y * ds_dr * ux,
        s + y * ds_dr * uy,
    );
    (Point2::new(s * x, s * y), j)
}

/// The closed-form FOV inverse; `None` where `r_d ω ≥ π/2` (the ray is at or beyond 90°).
fn undistort_fov(omega: f64, x_distorted: &Point2<f64>) -> Option<Point2<f64>> {
    if omega == 0.0 {
        return Some(*x_distorted);
    }
    let a = 2.0 * (omega / 2.0).tan();
    let r_d = x_distorted.coords.norm();
    if r_d < 1e-12 {
        return Some(Point2::from(x_distorted.coords * (omega / a)));
    }
    if r_d * omega.abs() >= std::f64::consts::FRAC_PI_2 {
        return None;
    }
    let r_u = (r_d * omega).tan() / a;
    Some(Point2::from(x_distorted.coords * (r_u / r_d)))
}

/// The equidistant model's distorted angle `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)` and its
/// derivative `dθ_d/dθ`.
fn equidistant_theta_d(k: [f64; 4], theta: f64) -> (f64, f64) {
    let t2 = theta * theta;
    let theta_d = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
    let slope = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
    (theta_d, slope)
}

/// The equidistant inverse: solve `θ_d(θ) = |x_d|` for θ (1-D Newton), then scale.
///
/// Only the branch where `θ_d` still grows with `θ` is an inverse: past the fold of a strongly
/// negative polynomial two angles map to one radius, so a solution with `dθ_d/dθ ≤ 0` is refused
/// (`None`) rather than returned as one of two equally valid rays.
fn undistort_equidistant(k: [f64; 4], x_distorted: &Point2<f64>) -> Option<Point2<f64>> {
    let theta_d = x_distorted.coords.norm();
    if theta_d < 1e-12 {
        return Some(*x_distorted);
    }
    let mut theta = theta_d.min(std::f64::consts::FRAC_PI_2 - 1e-6);
    for _ in 0..UNDISTORT_MAX_ITERATIONS {
        let (at, df) = equidistant_theta_d(k, theta);
        let f = at - theta_d;
        if df.abs() < 1e-12 {
            return None;
        }
        let step = f / df;
        theta -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    if !(theta > 0.0 && theta < std::f64::consts::FRAC_PI_2) {
        return None;
    }
    let (at, slope) = equidistant_theta_d(k, theta);
    if (at - theta_d).abs() > 1e-9 || slope <= 0.0 {
        return None;
    }
    let scale = theta.tan() / theta_d;
    Some(Point2::from(x_distorted.coords * scale))
}

/// A calibrated camera: pinhole intrinsics `K` (and the raw image size) plus lens distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibratedCamera {
    /// Intrinsics and image size of the raw (distorted) images.
    pub pinhole: PinholeCamera,
    /// Lens distortion.
    pub distortion: Distortion,
}

impl CalibratedCamera {
    /// Projects a point of the camera frame to raw (distorted) pixels; `None` behind the camera.
    #[must_use]
    pub fn project(&self, p_in_cam: &Point3<f64>) -> Option<Point2<f64>> {
        if p_in_cam.z <= 1e-9 {
            return None;
        }
        Some(self.distort_normalized(&Point2::new(
            p_in_cam.x / p_in_cam.z,
            p_in_cam.y / p_in_cam.z,
        )))
    }

    /// Raw pixel of ideal normalised coordinates (distortion, then `K`).
    #[must_use]
    pub fn distort_normalized(&self, x_ideal: &Point2<f64>) -> Point2<f64> {
        let d = self.distortion.distort(x_ideal);
        Point2::new(
            self.pinhole.fx * d.x + self.pinhole.cx,
            self.pinhole.fy * d.y + self.pinhole.cy,
        )
    }

    /// Ideal normalised coordinates of a raw pixel (`K⁻¹`, then undistortion); `None` where the
    /// model cannot be inverted.
    #[must_use]
    pub fn undistort_px(&self, px_raw: &Point2<f64>) -> Option<Point2<f64>> {
        self.distortion.undistort(&self.pinhole.normalize(px_raw))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn euroc_cam0() -> CalibratedCamera {
        CalibratedCamera {
            pinhole: PinholeCamera::new(458.654, 457.296, 367.215, 248.375, 752, 480).unwrap(),
            distortion: Distortion::RadialTangential {
                k1: -0.283_408_11,
                k2: 0.073_959_07,
                p1: 0.000_193_59,
                p2: 1.761_871_14e-5,
                k3: 0.0,
            },
        }
    }

    fn numeric_jacobian(d: &Distortion, x: &Point2<f64>) -> Matrix2<f64> {
        let h = 1e-7;
        let mut j = Matrix2::zeros();
        for c in 0..2 {
            let mut a = *x;
            let mut b = *x;
            a[c] += h;
            b[c] -= h;
            let diff = (d.distort(&a).coords - d.distort(&b).coords) / (2.0 * h);
            j.set_column(c, &diff);
        }
        j
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let models = [
            euroc_cam0().distortion,
            Distortion::RadialTangential {
                k1: 0.1,
                k2: -0.05,
                p1: 0.01,
                p2: -0.02,
                k3: 0.01,
            },
            Distortion::Equidistant {
                k1: -0.01,
                k2: 0.02,
                k3: -0.003,
                k4: 0.001,
            },
            Distortion::Fov { omega: 0.933_271 },
        ];
        for d in models {
            for x in [
                Point2::new(1e-9, 0.0),
                Point2::new(0.3, -0.2),
                Point2::new(-0.7, 0.5),
                Point2::new(0.05, 0.9),
            ] {
                let (_, j) = d.distort_with_jacobian(&x);
                let jn = numeric_jacobian(&d, &x);
                assert!((j - jn).abs().max() < 1e-6, "{d:?} at {x}: {j} vs {jn}");
            }
        }
    }

    #[test]
    fn fov_matches_the_closed_form() {
        let omega = 0.933_271;
        let d = Distortion::Fov { omega };
        let a = 2.0 * (omega / 2.0_f64).tan();
        for r_u in [1e-10, 0.1, 0.8, 2.5, 40.0] {
            let x = Point2::new(r_u * 0.6, r_u * 0.8);
            let r_d = d.distort(&x).coords.norm();
            assert!(((a * r_u).atan() / omega - r_d).abs() < 1e-12, "{r_u}");
            let back = d.undistort(&d.distort(&x)).unwrap();
            assert!((back - x).norm() < 1e-9 * r_u.max(1.0), "{r_u}");
        }
        // rays at 90° and beyond the lens' field are not invertible
        let edge = std::f64::consts::FRAC_PI_2 / omega;
        assert!(d.undistort(&Point2::new(edge, 0.0)).is_none());
        assert!(d.undistort(&Point2::new(0.0, edge * 0.999)).is_some());
        // ω = 0 is the identity
        let p = Point2::new(0.4, -0.3);
        assert_eq!(Distortion::Fov { omega: 0.0 }.distort(&p), p);
        assert!(Distortion::Fov { omega: 0.0 }.is_identity());
    }

    #[test]
    fn euroc_corners_round_trip_in_pixels() {
        let cam = euroc_cam0();
        for px in [
            Point2::new(0.0, 0.0),
            Point2::new(751.0, 0.0),
            Point2::new(0.0, 479.0),
            Point2::new(751.0, 479.0),
            Point2::new(367.0, 248.0),
        ] {
            let x = cam.undistort_px(&px).expect("corner undistorts");
            assert!(
                nalgebra::distance(&cam.distort_normalized(&x), &px) < 1e-6,
                "{px}"
            );
        }
        // strong barrel distortion: the corner lies further out once undistorted
        let corner = cam.undistort_px(&Point2::new(0.0, 0.0)).unwrap();
        let distorted = cam.pinhole.normalize(&Point2::new(0.0, 0.0));
        assert!(corner.coords.norm() > distorted.coords.norm() * 1.2);
    }

    #[test]
    fn equidistant_past_the_fold_is_not_inverted_to_the_far_ray() {
        // a polynomial whose θ_d(θ) turns down before θ = 1.288 (found by the round-trip property):
        // the radius of that ray has a nearer pre-image, and the far one must not be returned
        let k = [-0.0400, -0.0148, -0.0093, -0.0047];
        let distortion = Distortion::Equidistant {
            k1: k[0],
            k2: k[1],
            k3: k[2],
            k4: k[3],
        };
        let far = Point2::new(1.288f64.tan(), 0.0);
        let distorted = distortion.distort(&far);
        match distortion.undistort(&distorted) {
            None => {}
            Some(back) => {
                assert!(back.x < far.x * 0.99, "{back} is the ray past the fold");
                assert!(nalgebra::distance(&distortion.distort(&back), &distorted) < 1e-9);
            }
        }
    }

    proptest! {
        #[test]
        fn radtan_round_trip(
            k1 in -0.3f64..0.3, k2 in -0.08f64..0.08, p1 in -0.002f64..0.002,
            p2 in -0.002f64..0.002, k3 in -0.02f64..0.02,
            x in -0.6f64..0.6, y in -0.45f64..0.45,
        ) {
            let cam = CalibratedCamera {
                pinhole: PinholeCamera::new(450.0, 455.0, 370.0, 245.0, 752, 480).unwrap(),
                distortion: Distortion::RadialTangential { k1, k2, p1, p2, k3 },
            };
            // pixel → normalised → pixel
            let px = cam.distort_normalized(&Point2::new(x, y));
            let back = cam.undistort_px(&px).expect("converges");
            prop_assert!(nalgebra::distance(&cam.distort_normalized(&back), &px) < 1e-6);
            prop_assert!((back - Point2::new(x, y)).norm() < 1e-9);
        }

        #[test]
        fn fov_round_trip(
            omega in 0.05f64..1.5, theta in 0.0f64..1.45, phi in -3.2f64..3.2,
        ) {
            // the TUM monoVO cameras: 1280x1024, fx ≈ fy ≈ 447 px, ω ≈ 0.93
            let cam = CalibratedCamera {
                pinhole: PinholeCamera::new(446.9, 447.1, 630.7, 510.5, 1280, 1024).unwrap(),
                distortion: Distortion::Fov { omega },
            };
            let r = theta.tan();
            let x = Point2::new(r * phi.cos(), r * phi.sin());
            let px = cam.distort_normalized(&x);
            let back = cam.undistort_px(&px).expect("a ray within 90° undistorts");
            prop_assert!(nalgebra::distance(&cam.distort_normalized(&back), &px) < 1e-6);
            prop_assert!((back - x).norm() < 1e-9 * (1.0 + r * r));
        }

        #[test]
        fn equidistant_round_trip(
            k1 in -0.05f64..0.05, k2 in -0.02f64..0.02, k3 in -0.01f64..0.01,
            k4 in -0.005f64..0.005, theta in 0.0f64..1.3, phi in -3.2f64..3.2,
        ) {
            let cam = CalibratedCamera {
                pinhole: PinholeCamera::new(190.0, 190.0, 254.0, 256.0, 512, 512).unwrap(),
                distortion: Distortion::Equidistant { k1, k2, k3, k4 },
            };
            // only where θ_d(θ) is one-to-one on [0, θ] is there a unique inverse
            let slope = |t: f64| equidistant_theta_d([k1, k2, k3, k4], t).1;
            prop_assume!((0..=64).all(|i| slope(theta * f64::from(i) / 64.0) > 0.05));
            let r = theta.tan();
            let x = Point2::new(r * phi.cos(), r * phi.sin());
            let px = cam.distort_normalized(&x);
            let back = cam.undistort_px(&px).expect("converges");
            prop_assert!(nalgebra::distance(&cam.distort_normalized(&back), &px) < 1e-6);
            prop_assert!((back - x).norm() < 1e-6 * (1.0 + r * r));
        }
    }
}
