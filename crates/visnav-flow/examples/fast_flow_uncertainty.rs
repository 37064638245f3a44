//! Calibrates the fast flow's uncertainty ([`visnav_flow::FastUncertaintyConfig::calibration`])
//! on rendered pairs with exact flow (`visnav_flow::synthetic::varied_pair`): the factor of the
//! densified covariance that puts 1 - e^-1/2 = 39.3 % of the true flows inside their 1-sigma
//! ellipse on the tuning seeds, then the scores of that factor on held-out seeds.
//!
//! ```sh
//! cargo run --release -p visnav-flow --example fast_flow_uncertainty -- [TUNE_SEEDS HELD_OUT_SEEDS]
//! ```
//!
//! Tuning seeds are `0..TUNE_SEEDS` (default 24), held-out seeds `1000..1000 + HELD_OUT_SEEDS`
//! (default 12); pairs are 448x256 pixels, scored 8 px inside the border on visible pixels.

use visnav_eval::flow::{FlowPixel, evaluate};
use visnav_flow::synthetic::varied_pair;
use visnav_flow::{FastFlow, FastFlowConfig};

const W: usize = 448;
const H: usize = 256;
const MARGIN: usize = 8;

/// Per scored pixel: the flow error and the raw covariance (calibration 1, no floor).
struct Sample {
    error: [f32; 2],
    gt_magnitude: f32,
    cov: [f32; 3],
}

fn samples(seeds: impl Iterator<Item = u64>, flow: &FastFlow) -> Vec<Sample> {
    let mut out = Vec::new();
    for seed in seeds {
        let pair = varied_pair(W, H, seed);
        let Ok(est) = flow.compute(&pair.image1, &pair.image2) else {
            continue;
        };
        for y in MARGIN..H - MARGIN {
            for x in MARGIN..W - MARGIN {
                let i = y * W + x;
                if !pair.visible[i] {
                    continue;
                }
                let (f, g) = (est.flow[i], pair.flow[i]);
                out.push(Sample {
                    error: [f[0] - g[0], f[1] - g[1]],
                    gt_magnitude: g[0].hypot(g[1]),
                    cov: est.covariance(i),
                });
            }
        }
    }
    out
}

/// The pixels as `visnav-eval` scores them, with the covariance `c · cov + floor · I`.
fn pixels(samples: &[Sample], c: f32, floor: f32) -> Vec<FlowPixel> {
    samples
        .iter()
        .filter_map(|s| {
            let cov = [c * s.cov[0] + floor, c * s.cov[1], c * s.cov[2] + floor];
            let det = cov[0] * cov[2] - cov[1] * cov[1];
            (det > 0.0 && det.is_finite()).then(|| FlowPixel {
                error_px: s.error,
                gt_magnitude_px: s.gt_magnitude,
                information: [cov[2] / det, -cov[1] / det, cov[0] / det],
            })
        })
        .collect()
}

fn report(name: &str, samples: &[Sample], c: f32, floor: f32) {
    if let Some(m) = evaluate(&pixels(samples, c, floor)) {
        println!(
            "{name}: {} px, EPE {:.3}, AUSE/EPE {:.3}, certain half {:.3}, 1-sigma {:.1} %, 2-sigma {:.1} %",
            m.pixels,
            m.mean_epe_px,
            m.ause_over_epe,
            m.certain_half_over_all(),
            m.sigma1_percent,
            m.sigma2_percent
        );
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tune: u64 = args.next().map_or(Ok(24), |a| a.parse())?;
    let held: u64 = args.next().map_or(Ok(12), |a| a.parse())?;
    let defaults = FastFlowConfig::default();
    let mut raw_cfg = defaults.clone();
    raw_cfg.uncertainty.calibration = 1.0;
    raw_cfg.uncertainty.floor_px2 = 0.0;
    raw_cfg.uncertainty.min_information = 1e-6;
    raw_cfg.uncertainty.max_information = 1e6;
    let flow = FastFlow::new(raw_cfg)?;
    let floor = defaults.uncertainty.floor_px2;
    let tuning = samples(0..tune, &flow);
    let held_out = samples(1000..1000 + held, &flow);
    // the 1-sigma share grows with c: bisect log(c) for 39.35 %
    let share = |c: f32| evaluate(&pixels(&tuning, c, floor)).map_or(0.0, |m| m.sigma1_percent);
    let target = 100.0 * (1.0 - (-0.5_f64).exp());
    let (mut lo, mut hi) = (1e-3_f32.ln(), 1e3_f32.ln());
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if share(mid.exp()) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let c = (0.5 * (lo + hi)).exp();
    println!(
        "calibration {c:.4} (default {}), floor {floor} px²",
        defaults.uncertainty.calibration
    );
    report("tuning seeds, fitted", &tuning, c, floor);
    report("held-out seeds, fitted", &held_out, c, floor);
    let d = defaults.uncertainty.calibration;
    report("tuning seeds, default", &tuning, d, floor);
    report("held-out seeds, default", &held_out, d, floor);
    Ok(())
}
