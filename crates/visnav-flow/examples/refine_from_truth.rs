//! Where the refinement itself goes, started from the exact flow (or the exact flow scaled) of a
//! rendered pair: the half-resolution variational pass, dense Lucas–Kanade and the
//! full-resolution variational pass of the flow's configuration, as the estimator runs them
//! after the matching. Prints the median share of the true flow kept, `f·g / |g|²`, by distance
//! from the image border, and within 25 px of it by side. An unbiased refinement keeps 1.000
//! from the truth and brings a scaled start back to 1.000.
//!
//! ```sh
//! visnav synth --flight flight563.toml --out fl563 --frames 563 --width 620 --height 188
//! cargo run --release -p visnav-flow --example refine_from_truth -- fl563 440 1.0 flow.toml
//! cargo run --release -p visnav-flow --example refine_from_truth -- fl563 440 0.92 flow.toml
//! ```
//!
//! `flow.toml` as `visnav flow --config` reads it (the monocular odometry's: the
//! `[mono.flow.flow]` section of a run's `.config.toml`).

use std::path::Path;

use visnav_flow::config::{FlowConfig, RefinementConfig};
use visnav_flow::{ops, refine};

/// Border bands, pixels from the nearest border.
const BANDS: [usize; 6] = [0, 5, 10, 25, 50, usize::MAX];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, frame, scale, config] = args.as_slice() else {
        return Err("usage: refine_from_truth SEQUENCE FRAME SCALE FLOW_CONFIG.toml".into());
    };
    let dir = Path::new(dir);
    let i: usize = frame.parse()?;
    let scale: f32 = scale.parse()?;
    let cfg: FlowConfig = toml::from_str(&std::fs::read_to_string(config)?)?;
    let load = |k: usize| visnav_io::image_io::load_gray(&dir.join(format!("image_0/{k:06}.png")));
    let (im1, im2) = (load(i)?, load(i + 1)?);
    let truth = visnav_io::flo::read_flo(&dir.join(format!("flow/{i:06}.flo")))?;
    let known = |k: usize| {
        let (u, v) = (truth.uv[2 * k], truth.uv[2 * k + 1]);
        (u.abs() < 1e9 && v.abs() < 1e9).then_some([u, v])
    };
    let start: Vec<[f32; 2]> = (0..im1.width() * im1.height())
        .map(|k| known(k).map_or([0.0; 2], |[u, v]| [u * scale, v * scale]))
        .collect();
    let flow = refine_like_the_estimator(&im1, &im2, start, &cfg.refinement);
    let (w, h) = (im1.width(), im1.height());
    let mut by_band = vec![Vec::new(); BANDS.len() - 1];
    let mut by_side = vec![Vec::new(); 4];
    for (k, f) in flow.iter().enumerate() {
        let Some([u, v]) = known(k) else { continue };
        let n2 = u * u + v * v;
        if n2 < 1.0 {
            continue;
        }
        let r = (f[0] * u + f[1] * v) / n2;
        let (x, y) = (k % w, k / w);
        let sides = [x, w - 1 - x, y, h - 1 - y];
        let edge = sides.iter().copied().min().unwrap_or(0);
        by_band[BANDS.iter().filter(|&&b| edge >= b).count() - 1].push(r);
        if edge < 25
            && let Some(side) = sides.iter().position(|&d| d == edge)
        {
            by_side[side].push(r);
        }
    }
    let bands: Vec<String> = by_band
        .iter_mut()
        .zip(BANDS.windows(2))
        .map(|(v, b)| match b[1] {
            usize::MAX => format!(">= {} px {}", b[0], median(v)),
            hi => format!("{}-{} px {}", b[0], hi, median(v)),
        })
        .collect();
    println!("frame {i}, start {scale} x truth: {}", bands.join("  "));
    let sides: Vec<String> = by_side
        .iter_mut()
        .zip(["left", "right", "top", "bottom"])
        .map(|(v, name)| format!("{name} {} ({})", median(v), v.len()))
        .collect();
    println!("  within 25 px, by side: {}", sides.join("  "));
    Ok(())
}

/// The refinements of `visnav_flow`'s estimator after the matching (half-resolution
/// variational pass when configured, Lucas–Kanade, full-resolution variational pass) on the
/// prefiltered pair, from `flow`.
fn refine_like_the_estimator(
    im1: &visnav_core::GrayImage,
    im2: &visnav_core::GrayImage,
    mut flow: Vec<[f32; 2]>,
    r: &RefinementConfig,
) -> Vec<[f32; 2]> {
    let (w, h) = (im1.width(), im1.height());
    if r.half_resolution_pass {
        let half = |img| refine::prefilter_one(&ops::downsample_box(img, 2), r);
        let (q1, q2) = (half(im1), half(im2));
        let (hw, hh) = (q1.width(), q1.height());
        // pixel (x, y) of the half-resolution image covers full-resolution (2x .. 2x+1)
        let mut fh: Vec<[f32; 2]> = (0..hw * hh)
            .map(|k| {
                let f = flow[2 * (k / hw) * w + 2 * (k % hw)];
                [f[0] / 2.0, f[1] / 2.0]
            })
            .collect();
        let half_cfg = RefinementConfig {
            variational_alpha: r.half_resolution_alpha,
            gradient_normalisation: r.half_resolution_normalisation,
            ..r.clone()
        };
        refine::variational(&q1, &q2, &mut fh, &half_cfg);
        flow = ops::upsample_flow(&fh, hw, hh, w, h, 2.0, 0.5);
    }
    let (p1, p2) = refine::prefilter(im1, im2, r);
    refine::refine(&p1, &p2, &mut flow, r);
    let full = if r.half_resolution_pass {
        RefinementConfig {
            variational_outer: r.full_resolution_outer,
            variational_inner: r.full_resolution_inner,
            ..r.clone()
        }
    } else {
        r.clone()
    };
    refine::variational(&p1, &p2, &mut flow, &full);
    flow
}

/// The median of `v` (sorted in place), formatted; `-` when empty.
fn median(v: &mut [f32]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.sort_by(f32::total_cmp);
    format!("{:.4}", v[v.len() / 2])
}
