//! Dense Lucas–Kanade refinement at full resolution: per pixel, Gauss–Newton steps on the
//! brightness constancy over a `(2r+1)²` window (normal equations box-filtered, Tikhonov
//! damped), starting from the upsampled matching flow. Brings the 1/3-resolution matches to
//! sub-pixel accuracy.

use rayon::prelude::*;
use visnav_core::GrayImage;

use crate::config::RefinementConfig;
use crate::ops::{box_filter, gradients};

/// The images the refinement works on: `I - highpass * box_mean(I)` (or copies when
/// `highpass` is 0).
#[must_use]
pub fn prefilter(
    img1: &GrayImage,
    img2: &GrayImage,
    cfg: &RefinementConfig,
) -> (GrayImage, GrayImage) {
    let f = |img: &GrayImage| {
        if cfg.highpass <= 0.0 {
            return img.clone();
        }
        let (w, h) = (img.width(), img.height());
        let mean = box_filter(img.data(), w, h, 1, cfg.highpass_radius);
        let data = img
            .data()
            .iter()
            .zip(&mean)
            .map(|(v, m)| v - cfg.highpass * m)
            .collect();
        GrayImage::from_vec(w, h, data).unwrap_or_else(|| img.clone())
    };
    (f(img1), f(img2))
}

/// Refines `flow` (full resolution, `img1` to `img2`) in place.
pub fn refine(img1: &GrayImage, img2: &GrayImage, flow: &mut [[f32; 2]], cfg: &RefinementConfig) {
    let w = img1.width();
    let h = img1.height();
    if cfg.iterations == 0 || w < 2 || h < 2 {
        return;
    }
    let (g1x, g1y) = gradients(img1);
    let (g2x, g2y) = gradients(img2);
    let mut terms = vec![0.0_f32; w * h * 5];
    for _ in 0..cfg.iterations {
        terms
            .par_chunks_mut(w * 5)
            .zip(flow.par_chunks(w))
            .enumerate()
            .for_each(|(y, (trow, frow))| {
                for x in 0..w {
                    let [u, v] = frow[x];
                    let xs = f64::from(x as f32 + u);
                    let ys = f64::from(y as f32 + v);
                    let t = &mut trow[x * 5..x * 5 + 5];
                    if xs < 0.0 || ys < 0.0 || xs > (w - 1) as f64 || ys > (h - 1) as f64 {
                        t.fill(0.0);
                        continue;
                    }
                    let i2 = img2.bilinear_clamped(xs, ys);
                    let gx = 0.5 * (g2x.bilinear_clamped(xs, ys) + g1x.get(x, y));
                    let gy = 0.5 * (g2y.bilinear_clamped(xs, ys) + g1y.get(x, y));
                    let r = i2 - img1.get(x, y);
                    t[0] = gx * gx;
                    t[1] = gx * gy;
                    t[2] = gy * gy;
                    t[3] = gx * r;
                    t[4] = gy * r;
                }
            });
        let sums = box_filter(&terms, w, h, 5, cfg.window_radius);
        flow.par_iter_mut().enumerate().for_each(|(i, f)| {
            let s = &sums[i * 5..i * 5 + 5];
            let a = s[0] + cfg.damping;
            let b = s[1];
            let c = s[2] + cfg.damping;
            let det = a * c - b * b;
            if det <= 1e-6 {
                return;
            }
            let du = -(c * s[3] - b * s[4]) / det;
            let dv = -(a * s[4] - b * s[3]) / det;
            let norm = du.hypot(dv);
            let k = if norm > cfg.max_step_px {
                cfg.max_step_px / norm
            } else {
                1.0
            };
            f[0] += du * k;
            f[1] += dv * k;
        });
    }
}

/// Variational refinement at full resolution (in the manner of the refinement of DIS, Kroeger et
/// al. 2016, after Brox et al. 2004): minimises `Σ ψ((I2(x + u) - I1(x))²) + alpha Σ ψ(|∇u|² +
/// |∇v|²)` with Charbonnier `ψ(s²) = sqrt(s² + ε²)`, linearised around the current flow (outer
/// fixed-point iterations with re-warping and lagged robust weights) and solved for the new flow
/// `t` by red-black Gauss–Seidel sweeps: per pixel
/// `t_u (a11 + Σw) = a11 f_u + a12 f_v - b1 - a12 t_v + Σ w_j t_u,j` and symmetrically for `t_v`.
pub fn variational(
    img1: &GrayImage,
    img2: &GrayImage,
    flow: &mut [[f32; 2]],
    cfg: &RefinementConfig,
) {
    let w = img1.width();
    let h = img1.height();
    if cfg.variational_outer == 0 || w < 3 || h < 3 {
        return;
    }
    let (g1x, g1y) = gradients(img1);
    let (g2x, g2y) = gradients(img2);
    let eps2 = 1e-6_f32;
    let eps_d2 = 1.0_f32; // intensity levels²
    let alpha = cfg.variational_alpha;
    // per pixel: a11, a12, a22, c1, c2
    let mut coef = vec![[0.0_f32; 5]; w * h];
    // smoothness weight towards the right and the lower neighbour
    let mut wr = vec![0.0_f32; w * h];
    let mut wdn = vec![0.0_f32; w * h];
    let mut ws = vec![0.0_f32; w * h];
    let mut cur = vec![[0.0_f32; 2]; w * h];
    let mut next = vec![[0.0_f32; 2]; w * h];
    for _ in 0..cfg.variational_outer {
        coef.par_chunks_mut(w)
            .zip(ws.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (crow, wrow))| {
                for x in 0..w {
                    let i = y * w + x;
                    let [u, v] = flow[i];
                    let xs = f64::from(x as f32 + u);
                    let ys = f64::from(y as f32 + v);
                    let inside =
                        xs >= 0.0 && ys >= 0.0 && xs <= (w - 1) as f64 && ys <= (h - 1) as f64;
                    crow[x] = if inside {
                        let iz = img2.bilinear_clamped(xs, ys) - img1.get(x, y);
                        let ix = 0.5 * (g2x.bilinear_clamped(xs, ys) + g1x.get(x, y));
                        let iy = 0.5 * (g2y.bilinear_clamped(xs, ys) + g1y.get(x, y));
                        let wd = 0.5 / (iz * iz + eps_d2).sqrt();
                        let (a11, a12, a22) = (wd * ix * ix, wd * ix * iy, wd * iy * iy);
                        let (b1, b2) = (wd * ix * iz, wd * iy * iz);
                        [
                            a11,
                            a12,
                            a22,
                            a11 * u + a12 * v - b1,
                            a22 * v + a12 * u - b2,
                        ]
                    } else {
                        [0.0; 5]
                    };
                    let xn = (x + 1).min(w - 1);
                    let yn = (y + 1).min(h - 1);
                    let fx = flow[y * w + xn];
                    let fy = flow[yn * w + x];
                    let g2 = (fx[0] - u).powi(2)
                        + (fx[1] - v).powi(2)
                        + (fy[0] - u).powi(2)
                        + (fy[1] - v).powi(2);
                    wrow[x] = 0.5 / (g2 + eps2).sqrt().max(0.05);
                }
            });
        wr.par_chunks_mut(w)
            .zip(wdn.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (rrow, drow))| {
                for x in 0..w {
                    let i = y * w + x;
                    rrow[x] = if x + 1 < w {
                        alpha * 0.5 * (ws[i] + ws[i + 1])
                    } else {
                        0.0
                    };
                    drow[x] = if y + 1 < h {
                        alpha * 0.5 * (ws[i] + ws[i + w])
                    } else {
                        0.0
                    };
                }
            });
        cur.copy_from_slice(flow);
        for _ in 0..cfg.variational_inner {
            for colour in 0..2 {
                let src = &cur;
                next.par_chunks_mut(w).enumerate().for_each(|(y, nrow)| {
                    for (x, out) in nrow.iter_mut().enumerate() {
                        let i = y * w + x;
                        if (x + y) % 2 != colour {
                            *out = src[i];
                            continue;
                        }
                        let wl = if x > 0 { wr[i - 1] } else { 0.0 };
                        let wu = if y > 0 { wdn[i - w] } else { 0.0 };
                        let (wrr, wd) = (wr[i], wdn[i]);
                        let mut su = 0.0;
                        let mut sv = 0.0;
                        if x > 0 {
                            su += wl * src[i - 1][0];
                            sv += wl * src[i - 1][1];
                        }
                        if x + 1 < w {
                            su += wrr * src[i + 1][0];
                            sv += wrr * src[i + 1][1];
                        }
                        if y > 0 {
                            su += wu * src[i - w][0];
                            sv += wu * src[i - w][1];
                        }
                        if y + 1 < h {
                            su += wd * src[i + w][0];
                            sv += wd * src[i + w][1];
                        }
                        let sw = wl + wrr + wu + wd;
                        let [a11, a12, a22, c1, c2] = coef[i];
                        let tv_old = src[i][1];
                        let tu = (c1 - a12 * tv_old + su) / (a11 + sw + 1e-6);
                        let tv = (c2 - a12 * tu + sv) / (a22 + sw + 1e-6);
                        *out = [tu, tv];
                    }
                });
                std::mem::swap(&mut cur, &mut next);
            }
        }
        let m = cfg.max_step_px;
        flow.par_iter_mut().zip(&cur).for_each(|(f, t)| {
            f[0] += (t[0] - f[0]).clamp(-m, m);
            f[1] += (t[1] - f[1]).clamp(-m, m);
        });
    }
}

/// Adds `residual_variance_px2 * (r̄ / residual_scale)²` to the covariance of every pixel, where
/// `r̄` is the mean absolute brightness residual `|I2(x + u) - I1(x)|` over a 7x7 window after
/// refinement: variance the cost-slice fit cannot see (occlusions, non-rigid change).
#[must_use]
pub fn inflate_by_residual(
    img1: &GrayImage,
    img2: &GrayImage,
    flow: &[[f32; 2]],
    information: Vec<[f32; 3]>,
    cfg: &crate::config::UncertaintyConfig,
) -> Vec<[f32; 3]> {
    let w = img1.width();
    let h = img1.height();
    let res: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let xs = f64::from(x as f32 + flow[i][0]);
            let ys = f64::from(y as f32 + flow[i][1]);
            (img2.bilinear_clamped(xs, ys) - img1.get(x, y)).abs()
        })
        .collect();
    let mean = box_filter(&res, w, h, 1, 3);
    information
        .into_par_iter()
        .zip(mean.par_iter())
        .map(|(m, r)| {
            let q = r / cfg.residual_scale;
            let extra = cfg.residual_variance_px2 * q * q;
            let Some(c) = crate::uncertainty::invert(m) else {
                return m;
            };
            let inf = crate::uncertainty::invert([c[0] + extra, c[1], c[2] + extra]).unwrap_or(m);
            crate::uncertainty::clamp_eigen(inf, cfg.min_information, cfg.max_information)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn residual_inflation_lowers_information_only_where_images_disagree() {
        let (w, h) = (20, 10);
        let img1 = GrayImage::from_fn(w, h, |x, y| (x * 10 + y) as f32);
        // image 2 equals image 1 on the left half, differs by 20 levels on the right half
        let img2 = GrayImage::from_fn(w, h, |x, y| {
            (x * 10 + y) as f32 + if x >= 10 { 20.0 } else { 0.0 }
        });
        let flow = vec![[0.0_f32; 2]; w * h];
        let info = vec![[4.0_f32, 0.0, 4.0]; w * h];
        let cfg = crate::config::UncertaintyConfig {
            residual_variance_px2: 1.0,
            ..Default::default()
        };
        let out = inflate_by_residual(&img1, &img2, &flow, info, &cfg);
        assert!((out[5 * w + 2][0] - 4.0).abs() < 1e-4);
        // r̄ = 20, scale 10: variance 0.25 + 4 -> information 1 / 4.25
        assert!(
            (out[5 * w + 17][0] - 1.0 / 4.25).abs() < 1e-3,
            "{:?}",
            out[5 * w + 17]
        );
    }
}
