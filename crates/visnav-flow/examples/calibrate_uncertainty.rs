//! Fits the global uncertainty calibration on synthetic pairs with exact ground truth: runs the
//! flow with `calibration = 1`, collects the squared Mahalanobis distances of the true errors
//! over visible pixels, and prints the factor that puts their median at the χ²₂ median
//! (2 ln 2, i.e. 50 % inside the 1.177-sigma ellipse, 39.3 % inside 1 sigma).
//!
//! `cargo run --release -p visnav-flow --example calibrate_uncertainty`
#![allow(clippy::unwrap_used)]

use visnav_flow::synthetic::{Motion, MovingBox, render_pair};
use visnav_flow::{FlowConfig, FlowEstimator, FlowInput};

fn main() {
    let mut cfg = FlowConfig::default();
    cfg.uncertainty.calibration = 1.0;
    // generous eigenvalue range so clamping does not bias the fit
    cfg.uncertainty.max_information = 1e6;
    cfg.uncertainty.min_information = 1e-6;
    let est = FlowEstimator::new(cfg).unwrap();
    let mut d2 = Vec::new();
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
        // sensor noise (uniform, ±4 levels) and a 5 % gain change, like a real camera pair
        let mut state = seed.wrapping_add(99);
        for v in pair.image2.data_mut() {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            let u = ((state >> 33) as f32) / ((1_u64 << 31) as f32);
            *v = (*v * 1.05 + 8.0 * (u - 0.5)).clamp(0.0, 255.0);
        }
        let flow = est
            .compute(&pair.image1, &pair.image2, &FlowInput::default())
            .unwrap();
        for i in 0..flow.flow.len() {
            if pair.visible[i] {
                let du = flow.flow[i][0] - pair.flow[i][0];
                let dv = flow.flow[i][1] - pair.flow[i][1];
                d2.push(f64::from(flow.mahalanobis_sq(i, du, dv)));
            }
        }
    }
    d2.sort_by(f64::total_cmp);
    let median = d2[d2.len() / 2];
    let factor = 2.0 * std::f64::consts::LN_2 / median;
    let share = |t: f64| d2.iter().filter(|v| **v * factor <= t).count() as f64 / d2.len() as f64;
    println!(
        "pixels {} median d² at calibration 1: {median:.4}; calibration = {factor:.5} \
         (1-sigma {:.1} %, 2-sigma {:.1} %)",
        d2.len(),
        100.0 * share(1.0),
        100.0 * share(4.0)
    );
}
