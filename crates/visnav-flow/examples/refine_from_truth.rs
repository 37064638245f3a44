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
//! The pixels whose true target leaves the image have no rendered flow; each row's unknown ends
//! start from the straight line through its last 8 known pixels (rows with fewer known pixels:
//! the same along each column). With a fifth argument the
//! refined flow is written there (`.flo`).
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
    let (dir, frame, scale, config, out_flo) = match args.as_slice() {
        [d, f, s, c] => (d, f, s, c, None),
        [d, f, s, c, o] => (d, f, s, c, Some(o)),
        _ => {
            return Err(
                "usage: refine_from_truth SEQUENCE FRAME SCALE FLOW_CONFIG.toml [OUT.flo]".into(),
            );
        }
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
    let (w, h) = (im1.width(), im1.height());
    // the pixels whose true target leaves the image have no rendered flow: they start from
    // the row's straight line through its last known pixels (zeros would pull the known
    // pixels next to them short)
    let rows: Vec<Option<Vec<[f32; 2]>>> = (0..h)
        .map(|y| fill_row(&(0..w).map(|x| known(y * w + x)).collect::<Vec<_>>()))
        .collect();
    // rows with too few known pixels (the bottom rows of a forward flight): the same along
    // each column, through the filled rows
    let mut start = vec![[0.0_f32; 2]; w * h];
    for x in 0..w {
        let column: Vec<Option<[f32; 2]>> = rows.iter().map(|r| r.as_ref().map(|r| r[x])).collect();
        for (y, f) in fill_row(&column)
            .unwrap_or_default()
            .into_iter()
            .enumerate()
        {
            start[y * w + x] = [f[0] * scale, f[1] * scale];
        }
    }
    let flow = visnav_flow::refine_from_full_resolution((&im1, &im2), &start, &cfg.refinement);
    if let Some(path) = out_flo {
        let field = visnav_core::flow::FlowField {
            width: w,
            height: h,
            uv: flow.iter().flat_map(|f| [f[0], f[1]]).collect(),
        };
        visnav_io::flo::write_flo(Path::new(path), &field)?;
    }
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

/// Known pixels of the row as they are; an unknown run at either end continued by the
/// least-squares line of the [`FILL_FIT`] known pixels next to it, one inside the row by its
/// left neighbour's value; `None` for a row with fewer known pixels.
fn fill_row(row: &[Option<[f32; 2]>]) -> Option<Vec<[f32; 2]>> {
    let known: Vec<usize> = (0..row.len()).filter(|&x| row[x].is_some()).collect();
    if known.len() < FILL_FIT {
        return None;
    }
    let line = |xs: &[usize], x: usize| {
        let n = xs.len() as f32;
        let mx = xs.iter().map(|&i| i as f32).sum::<f32>() / n;
        let mut out = [0.0; 2];
        for (c, o) in out.iter_mut().enumerate() {
            let val = |i: usize| row[i].map_or(0.0, |f| f[c]);
            let my = xs.iter().map(|&i| val(i)).sum::<f32>() / n;
            let sxy: f32 = xs.iter().map(|&i| (i as f32 - mx) * (val(i) - my)).sum();
            let sxx: f32 = xs.iter().map(|&i| (i as f32 - mx).powi(2)).sum();
            *o = my + sxy / sxx * (x as f32 - mx);
        }
        out
    };
    let (first, last) = (known[0], known[known.len() - 1]);
    let mut out = Vec::with_capacity(row.len());
    for (x, f) in row.iter().enumerate() {
        out.push(match f {
            Some(f) => *f,
            None if x < first => line(&known[..FILL_FIT], x),
            None if x > last => line(&known[known.len() - FILL_FIT..], x),
            None => out[x - 1],
        });
    }
    Some(out)
}

/// Known pixels the end of a row is continued from ([`fill_row`]).
const FILL_FIT: usize = 8;

/// The median of `v` (sorted in place), formatted; `-` when empty.
fn median(v: &mut [f32]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.sort_by(f32::total_cmp);
    format!("{:.4}", v[v.len() / 2])
}
