//! Where the refinement itself goes, started from the exact flow (or the exact flow scaled) of a
//! rendered pair: the estimator's own refinements after the matching
//! ([`visnav_flow::refine_from_full_resolution`]: the half-resolution variational pass, dense
//! Lucas–Kanade and the full-resolution variational pass of the flow's configuration). Prints the median share of the true flow kept, `f·g / |g|²`, by distance
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

use std::io::Write;
use std::path::Path;

use visnav_flow::config::FlowConfig;

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
    let flow = visnav_flow::refine_from_full_resolution((&im1, &im2), &start, &cfg.refinement);
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
    // written, not printed: a closed pipe (`| head`) is an error, not a panic
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "frame {i}, start {scale} x truth: {}",
        bands.join("  ")
    )?;
    let sides: Vec<String> = by_side
        .iter_mut()
        .zip(["left", "right", "top", "bottom"])
        .map(|(v, name)| format!("{name} {} ({})", median(v), v.len()))
        .collect();
    writeln!(out, "  within 25 px, by side: {}", sides.join("  "))?;
    Ok(())
}

/// The median of `v` (sorted in place), formatted; `-` when empty.
fn median(v: &mut [f32]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.sort_by(f32::total_cmp);
    format!("{:.4}", v[v.len() / 2])
}
