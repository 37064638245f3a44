//! Affine Lucas–Kanade alignment of one patch (Lucas & Kanade 1981; Shi & Tomasi 1994, "Good
//! features to track", §4: the affine model that monitors a feature against its *first*
//! appearance). A track chained frame to frame by translation-only Lucas–Kanade drifts by a
//! random walk of its per-frame errors; aligning the current image with the patch of the frame
//! where the track began does not accumulate, but over several frames the patch deforms (a road
//! patch foreshortens, every patch grows as the camera approaches), so the warp must be affine.
//!
//! The warp maps an offset `x` of the anchor patch to `t + A x` in the current image; the six
//! parameters `(a11, a12, a21, a22, tx, ty)` minimise `Σ (I(t + A x) − T(x))²` over a `(2r+1)²`
//! window, by inverse-compositional Gauss–Newton ([`align_affine`]).

use nalgebra::{Matrix2, Matrix6, Point2, Vector6};
use visnav_core::GrayImage;

/// Settings of [`align_affine`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineConfig {
    /// Half-size of the patch, pixels (window `2r+1` square).
    pub radius: usize,
    /// Gauss–Newton iterations at most.
    pub max_iterations: usize,
    /// Convergence: the translation update below this, pixels.
    pub epsilon_px: f64,
    /// Reject an alignment whose mean absolute residual exceeds this (0..255).
    pub max_residual: f32,
}

impl Default for AffineConfig {
    fn default() -> Self {
        Self {
            radius: 7,
            max_iterations: 15,
            epsilon_px: 0.01,
            max_residual: 15.0,
        }
    }
}

/// A converged alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineAlignment {
    /// Where the anchor point lies in the current image, pixels.
    pub position: Point2<f64>,
    /// The linear part `A` of the warp (anchor offsets to current offsets).
    pub linear: Matrix2<f64>,
    /// Mean absolute intensity residual over the patch (0..255).
    pub residual: f32,
}

/// Aligns the `(2r+1)²` patch of `anchor` around `anchor_px` with `current`, starting from the
/// warp `(guess_px, guess_linear)`. Inverse compositional (Baker & Matthews 2004, affine warp):
/// the template's steepest-descent images and its 6x6 Hessian are computed once, each iteration
/// samples `current` once a pixel and composes the inverse of the template-side update into the
/// warp. `None` when the patch leaves either image, the Hessian is singular, the iterations do
/// not converge or the residual is too large.
#[must_use]
pub fn align_affine(
    anchor: &GrayImage,
    anchor_px: Point2<f64>,
    current: &GrayImage,
    (guess_px, guess_linear): (Point2<f64>, Matrix2<f64>),
    cfg: &AffineConfig,
) -> Option<AffineAlignment> {
    let template = Template::sample(anchor, anchor_px, cfg.radius)?;
    let h_inv = template.hessian.try_inverse()?;
    let mut t = guess_px.coords;
    let mut a = guess_linear;
    for _ in 0..cfg.max_iterations {
        let mut b = Vector6::<f64>::zeros();
        for (k, &((dx, dy), tv)) in template.values.iter().enumerate() {
            let x = t.x + a[(0, 0)] * dx + a[(0, 1)] * dy;
            let y = t.y + a[(1, 0)] * dx + a[(1, 1)] * dy;
            let e = f64::from(current.bilinear(x, y)? - tv);
            b += template.steepest[k] * e;
        }
        // the template-side update W(x; Δ) = (I + ΔA) x + Δt, composed inversely:
        // A ← A (I + ΔA)⁻¹, t ← t − A (I + ΔA)⁻¹ Δt
        let step = h_inv * b;
        let da = Matrix2::new(1.0 + step[0], step[1], step[2], 1.0 + step[3]);
        let a_new = a * da.try_inverse()?;
        let dt = nalgebra::Vector2::new(step[4], step[5]);
        let shift = a_new * dt;
        t -= shift;
        a = a_new;
        if !(t.x.is_finite() && t.y.is_finite()) {
            return None;
        }
        if shift.norm() < cfg.epsilon_px {
            let residual = mean_residual(current, &template.values, t.into(), &a)?;
            return (residual <= cfg.max_residual).then_some(AffineAlignment {
                position: t.into(),
                linear: a,
                residual,
            });
        }
    }
    None
}

/// The anchor patch: offsets and values, the steepest-descent images `∇T ∂W/∂p` at the
/// identity warp, and their Hessian.
struct Template {
    values: Vec<((f64, f64), f32)>,
    steepest: Vec<Vector6<f64>>,
    hessian: Matrix6<f64>,
}

impl Template {
    fn sample(anchor: &GrayImage, c: Point2<f64>, radius: usize) -> Option<Self> {
        let r = radius as i64;
        let n = ((2 * r + 1) * (2 * r + 1)) as usize;
        let (mut values, mut steepest) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut hessian = Matrix6::<f64>::zeros();
        for dy in -r..=r {
            for dx in -r..=r {
                let (dx, dy) = (dx as f64, dy as f64);
                let (v, gx, gy) = sample_with_gradient(anchor, c.x + dx, c.y + dy)?;
                let j = Vector6::new(gx * dx, gx * dy, gy * dx, gy * dy, gx, gy);
                hessian += j * j.transpose();
                values.push(((dx, dy), v as f32));
                steepest.push(j);
            }
        }
        Some(Self {
            values,
            steepest,
            hessian,
        })
    }
}

/// The bilinear sample at `(x, y)` and its gradient from central differences of samples half a
/// pixel away; `None` outside the image.
fn sample_with_gradient(img: &GrayImage, x: f64, y: f64) -> Option<(f64, f64, f64)> {
    let s = |x: f64, y: f64| img.bilinear(x, y).map(f64::from);
    let v = s(x, y)?;
    let gx = s(x + 0.5, y)? - s(x - 0.5, y)?;
    let gy = s(x, y + 0.5)? - s(x, y - 0.5)?;
    Some((v, gx, gy))
}

fn mean_residual(
    current: &GrayImage,
    template: &[((f64, f64), f32)],
    t: Point2<f64>,
    a: &Matrix2<f64>,
) -> Option<f32> {
    let mut sum = 0.0;
    for &((dx, dy), tv) in template {
        let x = t.x + a[(0, 0)] * dx + a[(0, 1)] * dy;
        let y = t.y + a[(1, 0)] * dx + a[(1, 1)] * dy;
        sum += f64::from((current.bilinear(x, y)? - tv).abs());
    }
    Some((sum / template.len() as f64) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texture(x: f64, y: f64) -> f32 {
        (128.0
            + 50.0 * (0.31 * x + 0.17 * y).sin()
            + 40.0 * (0.23 * x - 0.41 * y).cos()
            + 20.0 * (0.07 * x * y / 10.0).sin()) as f32
    }

    #[test]
    fn a_sheared_and_scaled_patch_is_aligned_from_a_translation_guess() {
        let anchor = GrayImage::from_fn(120, 100, |x, y| texture(x as f64, y as f64));
        // current(p) = anchor(c + B⁻¹ (p − q)): the anchor point c appears at q, offsets map by B
        let b = Matrix2::new(1.12, 0.08, -0.05, 0.93);
        let (c, q) = (Point2::new(60.0, 50.0), Point2::new(63.4, 47.7));
        let inv = b.try_inverse().unwrap();
        let current = GrayImage::from_fn(120, 100, |x, y| {
            let o = inv * (Point2::new(x as f64, y as f64) - q);
            texture(c.x + o.x, c.y + o.y)
        });
        let cfg = AffineConfig {
            max_iterations: 30,
            ..AffineConfig::default()
        };
        let guess = (Point2::new(63.0, 48.0), Matrix2::identity());
        let aligned = align_affine(&anchor, c, &current, guess, &cfg).expect("converges");
        assert!(
            (aligned.position - q).norm() < 0.02,
            "{:?}",
            aligned.position
        );
        assert!((aligned.linear - b).norm() < 0.01, "{}", aligned.linear);
        // translation-only alignment of the same patch is off by more
        assert!(aligned.residual < 1.0, "{}", aligned.residual);
        // a patch leaving the image is refused
        assert!(align_affine(&anchor, Point2::new(2.0, 2.0), &current, guess, &cfg).is_none());
    }
}
