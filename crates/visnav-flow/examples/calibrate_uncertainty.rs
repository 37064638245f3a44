//! Fits the coefficients of the uncertainty model ([`visnav_flow::VarianceModel`]) on synthetic
//! pairs with exact ground truth, never on the real evaluation data.
//!
//! Pairs (320x200 unless stated):
//! * six procedural pairs (rotation, zoom, translation, a moving box; ±4 levels of noise and a
//!   5 % gain change on image 2),
//! * four rendered city-drive pairs from `visnav-synth` at 620x188 (KITTI-like geometry with
//!   depth discontinuities, occlusions, sky and road; the same noise),
//! * 24 varied procedural pairs ([`visnav_flow::synthetic::varied_pair`]: up to three
//!   overlapping independently moving boxes, larger motions, flat low-texture patches and
//!   shading, gain / offset / illumination ramp, blur, sensor noise). Pairs whose flow broke
//!   down (mean end-point error above 3 px) are left out: the model describes the errors of a
//!   working flow, and a pair wrong over whole regions teaches nothing about which pixels of a
//!   good one are off.
//!
//! For every visible pixel at least 4 px from the border (every third one) it collects the
//! end-point error, the cost-slice fit's covariance (eq. 1–4, default calibration) and the
//! model's predictors ([`visnav_flow::UncertaintyTerms::log_features`]). It fits
//! `ln(EPE + 0.01) = θ₀ + Σ θ_k φ_k` by least squares (every pair weighted alike), so the
//! variance is `exp(2θ₀ + Σ 2θ_k φ_k)`: first the per-pixel predictors, then, with those fixed,
//! the constant and the image-wide one (the pair's mean NCC dissimilarity, the same for all its
//! pixels). Least squares on the log error makes the spread of `ln(EPE / σ)` as small as the
//! predictors allow, which is what the ellipse shares depend on (an earlier fit of the mean
//! error, `E[EPE] = exp(θᵀφ)` by Poisson quasi-likelihood, ranked the pixels less well and left
//! heavier tails). Then the blend of the covariance shape towards a circle
//! ([`visnav_flow::VarianceModel::shape_isotropy`], 0, 0.25, …, 1) and one global variance scale
//! (steps of 10 %) are chosen, with the information clamped as in the estimator, to bring the
//! mean 2-sigma share over the pairs to the Gaussian's 86.5 %, the 1-sigma share (39.3 %)
//! breaking ties: errors are heavier-tailed than a Gaussian, so one scale cannot give both
//! shares, and the 2-sigma ellipse is the one gates and robust weights rely on. It prints the
//! `[uncertainty.variance_model]` section, the shares and AUSE it gives, and the shares in each
//! tenth of the samples ordered by predicted variance.
//!
//! `cargo run --release -p visnav-flow --example calibrate_uncertainty [-- flow-config.toml]
//! [--without fb_full_resolution,smoothness_sensitivity]`
//!
//! With a flow configuration (TOML, as `visnav flow --config` reads it) the model is refitted
//! for that configuration's flow; paste the printed section into the same file.
#![allow(clippy::unwrap_used)]

use nalgebra::{DMatrix, DVector};
use visnav_core::GrayImage;
use visnav_core::Information2;
use visnav_flow::synthetic::{Motion, MovingBox, SyntheticPair, render_pair, varied_pair};
use visnav_flow::uncertainty::{LOG_FEATURES, model_covariance};
use visnav_flow::{FlowConfig, FlowEstimator, FlowInput, UncertaintyConfig};

const N: usize = LOG_FEATURES + 1;

/// The coefficients' names in `[uncertainty.variance_model]`, constant first (θ's order).
const NAMES: [&str; N] = [
    "log_scale",
    "fit_trace",
    "fb_discrepancy",
    "flow_magnitude",
    "texture",
    "removed_share",
    "refinement_change",
    "flow_variation",
    "flow_variation_wide",
    "ncc_dissimilarity",
    "fb_full_resolution",
    "ambiguity",
    "smoothness_sensitivity",
    "image_ncc_dissimilarity",
];

/// One visible pixel: error (px), fitted covariance (px²), predictors with a leading 1.
struct Sample {
    e: [f64; 2],
    cov: [f32; 3],
    phi: [f64; N],
}

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

/// The samples of one pair (every third visible pixel), or `None` when its flow broke down.
fn collect(
    est: &FlowEstimator,
    a: &GrayImage,
    b: &GrayImage,
    gt: &[[f32; 2]],
    visible: &[bool],
    name: &str,
) -> Option<Vec<Sample>> {
    let (flow, _, terms) = est.compute_detailed(a, b, &FlowInput::default()).unwrap();
    let w = flow.width;
    let margin = 4;
    let mut out = Vec::new();
    let mut epe_sum = 0.0;
    let mut count = 0_usize;
    for i in 0..flow.flow.len() {
        let (x, y) = (i % w, i / w);
        if !visible[i] || x < margin || y < margin || x + margin >= w || y + margin >= flow.height {
            continue;
        }
        let e = [
            f64::from(flow.flow[i][0] - gt[i][0]),
            f64::from(flow.flow[i][1] - gt[i][1]),
        ];
        epe_sum += e[0].hypot(e[1]);
        count += 1;
        if !count.is_multiple_of(3) {
            continue;
        }
        let mut phi = [1.0; N];
        for (p, f) in phi[1..].iter_mut().zip(terms.log_features(i)) {
            *p = f64::from(f);
        }
        out.push(Sample {
            e,
            cov: terms.fit_covariance_px2[i],
            phi,
        });
    }
    let epe = epe_sum / count.max(1) as f64;
    let kept = epe <= 3.0;
    println!(
        "{name}: mean EPE {epe:.3} px, {} samples{}",
        out.len(),
        if kept {
            ""
        } else {
            " (left out: the flow broke down)"
        }
    );
    kept.then_some(out)
}

/// [`collect`] on a procedural pair.
fn collect_pair(est: &FlowEstimator, pair: &SyntheticPair, name: &str) -> Option<Vec<Sample>> {
    collect(
        est,
        &pair.image1,
        &pair.image2,
        &pair.flow,
        &pair.visible,
        name,
    )
}

/// Offset of the log end-point error, px: below it errors count as equally small (keeps the
/// logarithm of a near-exact pixel from dominating the fit).
const LOG_EPE_OFFSET_PX: f64 = 0.01;

/// Least-squares fit of `ln(EPE + ε) = θᵀφ` (ε = [`LOG_EPE_OFFSET_PX`]), each pair weighted
/// alike, over the coefficients `free` (the others keep their values in `start`). It minimises
/// the spread of `ln(EPE / σ)`, which is what decides how many errors fall inside the 1- and
/// 2-sigma ellipses once one global scale is set.
fn fit_log(pairs: &[Vec<Sample>], free: &[usize], start: [f64; N]) -> [f64; N] {
    let m = free.len();
    let mut a = DMatrix::<f64>::identity(m, m) * 1e-9;
    let mut rhs = DVector::<f64>::zeros(m);
    for p in pairs {
        let wgt = 1.0 / p.len() as f64;
        for s in p {
            let fixed: f64 = (0..N)
                .filter(|k| !free.contains(k))
                .map(|k| s.phi[k] * start[k])
                .sum();
            let y = (s.e[0].hypot(s.e[1]) + LOG_EPE_OFFSET_PX).ln() - fixed;
            for (r, &fr) in free.iter().enumerate() {
                rhs[r] += wgt * y * s.phi[fr];
                for (c, &fc) in free.iter().enumerate() {
                    a[(r, c)] += wgt * s.phi[fr] * s.phi[fc];
                }
            }
        }
    }
    let sol = a.lu().solve(&rhs).unwrap();
    let mut th = start;
    for (&f, v) in free.iter().zip(sol.iter()) {
        th[f] = *v;
    }
    th
}

/// Information of a sample under log-variance coefficients `lv` (with the constant), as the
/// estimator builds it.
fn information(s: &Sample, lv: &[f64; N], iso: f32, cfg: &UncertaintyConfig) -> [f32; 3] {
    let z: f64 = s.phi.iter().zip(lv).map(|(a, b)| a * b).sum();
    let v = z.clamp(-30.0, 30.0).exp() as f32;
    let c = model_covariance(s.cov, v, iso);
    Information2::from_covariance_px2(c)
        .unwrap_or(Information2::new(
            cfg.min_information,
            0.0,
            cfg.min_information,
        ))
        .clamp_eigenvalues(cfg.min_information, cfg.max_information)
        .to_array()
}

/// The trace of a sample's covariance (px²) and its squared Mahalanobis error under `lv`.
fn scored(s: &Sample, lv: &[f64; N], iso: f32, cfg: &UncertaintyConfig) -> (f64, f64) {
    let [a, b, c] = information(s, lv, iso, cfg).map(f64::from);
    let [u, v] = s.e;
    let d2 = a * u * u + 2.0 * b * u * v + c * v * v;
    ((a + c) / (a * c - b * b), d2)
}

/// Mean over pairs of the 1- and 2-sigma shares (percent) and of AUSE/EPE.
fn quality(
    pairs: &[Vec<Sample>],
    lv: &[f64; N],
    iso: f32,
    cfg: &UncertaintyConfig,
) -> (f64, f64, f64) {
    let mut s1 = 0.0;
    let mut s2 = 0.0;
    let mut ause = 0.0;
    for p in pairs {
        let mut rows: Vec<(f64, f64)> = Vec::with_capacity(p.len());
        let (mut in1, mut in2) = (0, 0);
        for s in p {
            let (trace, d2) = scored(s, lv, iso, cfg);
            in1 += usize::from(d2 <= 1.0);
            in2 += usize::from(d2 <= 4.0);
            rows.push((trace, s.e[0].hypot(s.e[1])));
        }
        let n = p.len() as f64;
        s1 += 100.0 * in1 as f64 / n;
        s2 += 100.0 * in2 as f64 / n;
        let mut by: Vec<f64> = {
            rows.sort_by(|x, y| x.0.total_cmp(&y.0));
            rows.iter().map(|r| r.1).collect()
        };
        let mut oracle = by.clone();
        oracle.sort_by(f64::total_cmp);
        let prefix = |v: &mut Vec<f64>| {
            let mut acc = 0.0;
            v.iter_mut().for_each(|x| {
                acc += *x;
                *x = acc;
            });
        };
        prefix(&mut by);
        prefix(&mut oracle);
        let len = by.len();
        let mean = by[len - 1] / len as f64;
        let area: f64 = (0..50)
            .map(|k| {
                let keep =
                    (((1.0 - 0.02 * f64::from(k)) * len as f64).round() as usize).clamp(1, len);
                (by[keep - 1] - oracle[keep - 1]) / keep as f64
            })
            .sum::<f64>()
            / 50.0;
        ause += area / mean;
    }
    let k = pairs.len() as f64;
    (s1 / k, s2 / k, ause / k)
}

fn main() {
    // an optional flow configuration (TOML, as for `visnav flow --config`) to refit the model
    // for, e.g. with `half_label_cost = true`; its own variance-model coefficients are ignored
    // `--without a,b`: predictors left out of the fit (their coefficients 0, so the estimator
    // skips the work they need: `fb_full_resolution` the backward refinement,
    // `smoothness_sensitivity` the weakly smoothed one)
    let args: Vec<String> = std::env::args().skip(1).collect();
    let without: Vec<String> = args
        .iter()
        .position(|a| a == "--without")
        .and_then(|i| args.get(i + 1))
        .map(|v| v.split(',').map(str::to_owned).collect())
        .unwrap_or_default();
    let config_path = args
        .iter()
        .enumerate()
        .find(|(i, a)| !a.starts_with("--") && (*i == 0 || args[i - 1] != "--without"))
        .map(|(_, a)| a.clone());
    let cfg = match config_path {
        Some(path) => {
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("cannot read flow config {path}: {e}"));
            toml::from_str::<FlowConfig>(&text)
                .unwrap_or_else(|e| panic!("invalid flow config {path}: {e}"))
        }
        None => FlowConfig::default(),
    };
    let ucfg = cfg.uncertainty.clone();
    let est = FlowEstimator::new(cfg).unwrap();
    let mut pairs: Vec<Vec<Sample>> = Vec::new();
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
        pairs.extend(collect_pair(&est, &pair, &format!("procedural {seed}")));
    }
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
        let name = format!("city drive {k}");
        pairs.extend(collect(&est, &a.image, &b.image, &flow, &gt.valid, &name));
    }
    for seed in 0..24_u64 {
        let pair = varied_pair(320, 200, 1000 + seed);
        pairs.extend(collect_pair(
            &est,
            &pair,
            &format!("varied {}", 1000 + seed),
        ));
    }
    println!(
        "{} pairs, {} samples",
        pairs.len(),
        pairs.iter().map(Vec::len).sum::<usize>()
    );
    // first the per-pixel predictors (the image-wide one, the last, held at 0), then the
    // image-wide one with the constant, the per-pixel coefficients fixed: it scales whole pairs
    // and leaves the order of the pixels within a pair (AUSE) as the per-pixel fit has it
    let per_pixel: Vec<usize> = (0..N - 1)
        .filter(|&k| !without.iter().any(|w| w == NAMES[k]))
        .collect();
    let th = fit_log(&pairs, &per_pixel, [0.0; N]);
    let th = fit_log(&pairs, &[0, N - 1], th);
    let mut lv = th.map(|t| 2.0 * t);
    // the covariance shape and one global variance scale for the 2-sigma share (1-sigma breaks
    // ties)
    let mut best = (f64::INFINITY, 0.0, 0.0_f32);
    for iso in [0.0_f32, 0.25, 0.5, 0.75, 1.0] {
        for k in -40..=20 {
            let q = f64::from(k) * 1.1_f64.ln();
            let mut cand = lv;
            cand[0] += q;
            let (s1, s2, _) = quality(&pairs, &cand, iso, &ucfg);
            let cost = (s2 - 86.5).powi(2) + 0.01 * (s1 - 39.3).powi(2);
            if cost < best.0 {
                best = (cost, q, iso);
            }
        }
    }
    lv[0] += best.1;
    let iso = best.2;
    let (s1, s2, ause) = quality(&pairs, &lv, iso, &ucfg);
    let names = NAMES;
    println!("[uncertainty.variance_model]");
    println!("enabled = true");
    println!("shape_isotropy = {iso}");
    for (n, v) in names.iter().zip(&lv) {
        println!("{n} = {v:.4}");
    }
    println!(
        "on the synthetic pairs: 1-sigma {s1:.1} %, 2-sigma {s2:.1} % (Gaussian 39.3 / 86.5), \
         AUSE/EPE {ause:.3}"
    );
    print_tenths(&pairs, &lv, iso, &ucfg);
}

/// The 1- and 2-sigma shares and the mean end-point error in each tenth of all samples, ordered
/// by their predicted variance: whether the calibration holds from the most certain pixels to
/// the least, not only on average.
fn print_tenths(pairs: &[Vec<Sample>], lv: &[f64; N], iso: f32, cfg: &UncertaintyConfig) {
    let mut rows: Vec<(f64, f64, f64)> = pairs
        .iter()
        .flatten()
        .map(|s| {
            let (trace, d2) = scored(s, lv, iso, cfg);
            (0.5 * trace, d2, s.e[0].hypot(s.e[1]))
        })
        .collect();
    rows.sort_by(|x, y| x.0.total_cmp(&y.0));
    println!("tenth  sigma px  EPE px  1-sigma %  2-sigma %");
    let n = rows.len();
    for k in 0..10 {
        let part = &rows[k * n / 10..(k + 1) * n / 10];
        let m = part.len().max(1) as f64;
        let share = |t: f64| 100.0 * part.iter().filter(|r| r.1 <= t).count() as f64 / m;
        println!(
            "{:>5} {:>9.3} {:>7.3} {:>10.1} {:>10.1}",
            k + 1,
            (part.iter().map(|r| r.0).sum::<f64>() / m).sqrt(),
            part.iter().map(|r| r.2).sum::<f64>() / m,
            share(1.0),
            share(4.0)
        );
    }
}
