//! Fits the global coefficients of the uncertainty model on synthetic pairs with exact ground
//! truth, never on the real evaluation data.
//!
//! Pairs: the crate's procedural pairs (rotation, zoom, translation, a moving box; ±4 levels of
//! noise and a 5 % gain change) and rendered city drives from `visnav-synth` (KITTI-like
//! geometry with depth discontinuities, occlusions, sky and road; the same noise). For every
//! visible pixel it collects the true error `e`, the cost-slice fit's covariance `C` (eq. 1–4,
//! at calibration 1) and the model terms ([`visnav_flow::UncertaintyTerms`]); then it minimises
//! the Gaussian negative log-likelihood `½ eᵀΣ⁻¹e + ½ ln det Σ` (eq. 1) over
//! `Σ = C / calibration + (k_fb fb² + k_fill d² + k_res r² + k_var s² + k_mag |f|² + k_0) I`
//! by coordinate descent in log space; then one global variance scale brings the 1- and
//! 2-sigma shares on the synthetic pixels closest to the Gaussian's 39.3 % and 86.5 %. It prints
//! the coefficients for [`visnav_flow::UncertaintyConfig`] and the shares they give.
//!
//! `cargo run --release -p visnav-flow --example calibrate_uncertainty [-- --without NAME ...]`
//! (`--without` keeps a term of the model at zero, e.g. `normalised_residual_weight`).
#![allow(clippy::unwrap_used)]

use visnav_core::GrayImage;
use visnav_flow::synthetic::{Motion, MovingBox, render_pair};
use visnav_flow::{FlowConfig, FlowEstimator, FlowInput};

/// One visible pixel: error (px), fitted covariance at calibration 1 (px²), squared terms
/// (fb², d², r², s², 1) in px².
#[derive(Clone)]
struct Sample {
    e: [f64; 2],
    cov: [f64; 3],
    f: [f64; 6],
}

const NAMES: [&str; 7] = [
    "calibration",
    "fb_variance_weight",
    "fill_variance_weight",
    "normalised_residual_weight",
    "flow_variation_weight",
    "flow_magnitude_weight",
    "base_variance_px2",
];

fn add_noise(img: &mut GrayImage, seed: u64) {
    let mut state = seed.wrapping_add(99);
    for v in img.data_mut() {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        let u = ((state >> 33) as f32) / ((1_u64 << 31) as f32);
        *v = (*v * 1.05 + 8.0 * (u - 0.5)).clamp(0.0, 255.0);
    }
}

fn collect(
    est: &FlowEstimator,
    a: &GrayImage,
    b: &GrayImage,
    gt: &[[f32; 2]],
    visible: &[bool],
    out: &mut Vec<Sample>,
) {
    let (flow, _, terms) = est.compute_detailed(a, b, &FlowInput::default()).unwrap();
    let w = flow.width;
    let margin = 4;
    for i in 0..flow.flow.len() {
        let (x, y) = (i % w, i / w);
        if !visible[i] || x < margin || y < margin || x + margin >= w || y + margin >= flow.height {
            continue;
        }
        let c = terms.fit_covariance_px2[i];
        let sq = |v: f32| f64::from(v).powi(2);
        out.push(Sample {
            e: [
                f64::from(flow.flow[i][0] - gt[i][0]),
                f64::from(flow.flow[i][1] - gt[i][1]),
            ],
            cov: c.map(f64::from),
            f: [
                sq(terms.fb_discrepancy_px[i]),
                sq(terms.fill_distance_px[i]),
                sq(terms.normalised_residual_px[i]),
                sq(terms.flow_variation_px[i]),
                sq(terms.flow_magnitude_px[i]),
                1.0,
            ],
        });
    }
}

/// Squared Mahalanobis distance and log-determinant under parameters `p` (linear scale).
fn d2_logdet(s: &Sample, p: &[f64; 7]) -> (f64, f64) {
    let extra: f64 = s.f.iter().zip(&p[1..]).map(|(f, k)| f * k).sum();
    let a = s.cov[0] / p[0] + extra;
    let b = s.cov[1] / p[0];
    let c = s.cov[2] / p[0] + extra;
    let det = (a * c - b * b).max(1e-30);
    let [u, v] = s.e;
    ((c * u * u - 2.0 * b * u * v + a * v * v) / det, det.ln())
}

fn nll(samples: &[Sample], p: &[f64; 7]) -> f64 {
    samples
        .iter()
        .map(|s| {
            let (d2, ld) = d2_logdet(s, p);
            0.5 * d2 + 0.5 * ld
        })
        .sum::<f64>()
        / samples.len() as f64
}

fn main() {
    let mut cfg = FlowConfig::default();
    cfg.uncertainty.calibration = 1.0;
    // generous eigenvalue range so clamping does not bias the fit
    cfg.uncertainty.max_information = 1e6;
    cfg.uncertainty.min_information = 1e-6;
    let est = FlowEstimator::new(cfg).unwrap();
    let mut samples = Vec::new();
    for seed in 0..6_u64 {
        let s = seed as f64;
        let motion = Motion {
            translation_px: [3.0 + 2.0 * s, -1.5 + 0.7 * s],
            angle_rad: 0.01 * (s - 2.5),
            zoom: 1.0 + 0.01 * (s - 2.0),
        };
        let bx = MovingBox {
            rect_px: [100.0, 60.0, 180.0, 130.0],
            translation_px: [-6.0 + s, 4.0],
        };
        let mut pair = render_pair(320, 200, seed, motion, (seed % 2 == 0).then_some(bx));
        add_noise(&mut pair.image2, seed);
        collect(
            &est,
            &pair.image1,
            &pair.image2,
            &pair.flow,
            &pair.visible,
            &mut samples,
        );
    }
    let procedural = samples.len();
    // rendered city drive, KITTI-like camera at half resolution
    let poses = visnav_synth::drive_trajectory(40, 11);
    let scene = visnav_synth::Scene::along(&poses, 11)
        .unwrap()
        .with_supersampling(2);
    let cam = visnav_synth::kitti_like_camera(620, 188);
    for k in [0_usize, 6, 12, 30] {
        let a = visnav_synth::render_view(&scene, &cam, &poses[k]);
        let mut b = visnav_synth::render_view(&scene, &cam, &poses[k + 1]);
        let gt = visnav_synth::flow_between(&scene, &cam, &poses[k], &a, &poses[k + 1], &b);
        add_noise(&mut b.image, k as u64);
        let flow: Vec<[f32; 2]> = gt.flow.uv.chunks(2).map(|c| [c[0], c[1]]).collect();
        collect(&est, &a.image, &b.image, &flow, &gt.valid, &mut samples);
    }
    println!(
        "pixels: {procedural} procedural, {} rendered",
        samples.len() - procedural
    );
    // every 7th pixel keeps the search fast
    let fit: Vec<Sample> = samples.iter().step_by(7).cloned().collect();
    let args: Vec<String> = std::env::args().collect();
    let frozen: Vec<bool> = NAMES
        .iter()
        .map(|n| args.windows(2).any(|a| a[0] == "--without" && a[1] == *n))
        .collect();
    let mut logp = [12.4_f64.ln(), -20.0, -20.0, -20.0, -20.0, -20.0, -20.0];
    let to_lin = |l: &[f64; 7]| l.map(f64::exp);
    let mut best = nll(&fit, &to_lin(&logp));
    println!("NLL with the fit alone (calibration 12.4): {best:.4}");
    let mut step = 2.0;
    while step > 0.02 {
        let mut improved = false;
        for k in (0..7).filter(|k| !frozen[*k]) {
            for dir in [-1.0, 1.0] {
                let mut cand = logp;
                cand[k] = (cand[k] + dir * step).clamp(-20.0, 12.0);
                let v = nll(&fit, &to_lin(&cand));
                if v < best - 1e-7 {
                    best = v;
                    logp = cand;
                    improved = true;
                }
            }
        }
        if !improved {
            step *= 0.5;
        }
    }
    let p = to_lin(&logp);
    println!("NLL at the optimum: {best:.4}");
    let d2: Vec<f64> = samples.iter().map(|s| d2_logdet(s, &p).0).collect();
    let share = |t: f64| 100.0 * d2.iter().filter(|v| **v <= t).count() as f64 / d2.len() as f64;
    println!(
        "at the NLL optimum: 1-sigma {:.1} %, 2-sigma {:.1} %",
        share(1.0),
        share(4.0)
    );
    // the errors are heavy-tailed, so the likelihood optimum is over-wide for most pixels: one
    // global variance scale q (covariance x q) then brings the 1- and 2-sigma shares closest
    // to the Gaussian's 39.3 % and 86.5 %
    let mut best_q = (f64::INFINITY, 1.0);
    for k in -60..=20 {
        let q = 1.1_f64.powi(k);
        let s1 = 100.0 * d2.iter().filter(|v| **v / q <= 1.0).count() as f64 / d2.len() as f64;
        let s2 = 100.0 * d2.iter().filter(|v| **v / q <= 4.0).count() as f64 / d2.len() as f64;
        let cost = (s1 - 39.3).powi(2) + (s2 - 86.5).powi(2);
        if cost < best_q.0 {
            best_q = (cost, q);
        }
    }
    let q = best_q.1;
    let mut scaled = p;
    scaled[0] /= q;
    for v in &mut scaled[1..] {
        *v *= q;
    }
    for (name, v) in NAMES.iter().zip(&scaled) {
        println!("{name} = {v:.5}");
    }
    println!(
        "with the variance scale {q:.4}: 1-sigma {:.1} %, 2-sigma {:.1} % (Gaussian: 39.3 %, 86.5 %)",
        100.0 * d2.iter().filter(|v| **v / q <= 1.0).count() as f64 / d2.len() as f64,
        100.0 * d2.iter().filter(|v| **v / q <= 4.0).count() as f64 / d2.len() as f64
    );
}
