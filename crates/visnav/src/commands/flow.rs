//! `visnav flow IMG1 IMG2 --output flow.flo [--information info.pfm] [--visualize DIR] [--json]`:
//! dense optical flow with per-pixel uncertainty between two images (visnav-flow).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use visnav_flow::{
    AnyFlow, DenseFlow, FastFlow, FastFlowConfig, FlowConfig, FlowEstimator, FlowInput, SearchMode,
};
use visnav_io::atomic::write_atomic;
use visnav_io::flo::{FlowField, write_flo};
use visnav_io::image_io::load_gray;
use visnav_io::pfm::{PfmImage, write_pfm};

use visnav_report::colour;

/// Arguments of `visnav flow`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// First image (PNG, gray or colour).
    pub image1: PathBuf,
    /// Second image, same size.
    pub image2: PathBuf,
    /// Output flow, Middlebury `.flo`.
    #[arg(long, short)]
    pub output: PathBuf,
    /// Output information matrix: 3-channel little-endian PFM (Yxx, Yxy, Yyy in 1/px²).
    #[arg(long)]
    pub information: Option<PathBuf>,
    /// Directory for `flow.png` (colour wheel), `uncertainty.png` (heat map of the 1-sigma
    /// radius), `index.html` (both with their legends) and the effective `flow-config.toml`.
    #[arg(long)]
    pub visualize: Option<PathBuf>,
    /// Flow configuration (TOML, `FlowConfig` fields, or `FastFlowConfig` fields with
    /// `--method fast`; missing fields keep their defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Flow algorithm: `paper` (the paper's DCFlow-style flow, the default) or `fast` (dense
    /// inverse search with the alignment's uncertainty, about 10x faster; no epipolar cost).
    #[arg(long, value_enum, default_value = "paper")]
    pub method: Method,
    /// Use the DCFlow reference mode (±80 px window at 1/3 resolution; slow, several GB).
    #[arg(long)]
    pub reference: bool,
    /// Fundamental matrix (9 numbers, row-major, full-resolution pixels) for the epipolar cost;
    /// the nine values after it are numbers even when they start with `-` (`--fundamental 0
    /// -1.2e-6 0.003 ...`).
    #[arg(long, num_args = 9, value_name = "F", allow_hyphen_values = true)]
    pub fundamental: Option<Vec<f64>>,
    /// Estimate the fundamental matrix from Shi–Tomasi corners tracked by KLT (normalised
    /// eight-point + RANSAC) and add the epipolar cost (ignored when `--fundamental` is given).
    #[arg(long)]
    pub estimate_fundamental: bool,
    /// Print a JSON summary (timings, valid share) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The flow algorithm of `--method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// The paper's flow ([`FlowEstimator`]).
    Paper,
    /// Dense inverse search ([`FastFlow`]).
    Fast,
}

/// The flow stage of `--method` with its configuration (an optional TOML file of the method's
/// fields; `--reference` applies to the paper's flow only), and the configuration as TOML.
///
/// # Errors
/// Unreadable or invalid configuration, `--reference` with the fast flow.
pub fn load_estimator(
    method: Method,
    path: Option<&Path>,
    reference: bool,
) -> Result<(AnyFlow, String)> {
    match method {
        Method::Paper => {
            let cfg = load_config(path, reference)?;
            let text = toml::to_string(&cfg)?;
            Ok((AnyFlow::Paper(Box::new(FlowEstimator::new(cfg)?)), text))
        }
        Method::Fast => {
            anyhow::ensure!(
                !reference,
                "--reference is a mode of the paper's flow, not of --method fast"
            );
            let cfg: FastFlowConfig = match path {
                Some(p) => {
                    let text = visnav_io::text::read_text(p)
                        .with_context(|| format!("cannot read flow config {}", p.display()))?;
                    toml::from_str(&text)
                        .with_context(|| format!("invalid fast flow config {}", p.display()))?
                }
                None => FastFlowConfig::default(),
            };
            let text = toml::to_string(&cfg)?;
            Ok((AnyFlow::Fast(FastFlow::new(cfg)?), text))
        }
    }
}

/// Reads an optional TOML flow configuration and applies `--reference`.
///
/// # Errors
/// Unreadable or invalid configuration.
pub fn load_config(path: Option<&Path>, reference: bool) -> Result<FlowConfig> {
    let mut cfg = match path {
        Some(p) => {
            let text = visnav_io::text::read_text(p)
                .with_context(|| format!("cannot read flow config {}", p.display()))?;
            toml::from_str(&text).with_context(|| format!("invalid flow config {}", p.display()))?
        }
        None => FlowConfig::default(),
    };
    if reference {
        cfg.mode = SearchMode::Reference;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// The `--fundamental` matrix, checked: 9 finite numbers, not all zero (a NaN would silently
/// switch the epipolar cost off).
///
/// # Errors
/// A count other than 9, a value that is not finite, or the zero matrix.
fn fundamental_matrix(f: &[f64]) -> Result<nalgebra::Matrix3<f64>> {
    if f.len() != 9 {
        anyhow::bail!(
            "--fundamental: expected 9 numbers (row-major 3x3), found {}",
            f.len()
        );
    }
    if let Some((i, v)) = f.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        anyhow::bail!(
            "--fundamental: number {} is {v}, not a finite number",
            i + 1
        );
    }
    let m = nalgebra::Matrix3::from_row_slice(f);
    if m.norm() == 0.0 {
        anyhow::bail!("--fundamental: the matrix is zero");
    }
    Ok(m)
}

/// Runs the subcommand.
///
/// # Errors
/// Unreadable images, different sizes, unwritable outputs.
pub fn run(args: &Args, _ctx: &super::Context) -> Result<()> {
    // before the work: an output that cannot be written (read-only, a directory) is named now
    for path in std::iter::once(&args.output).chain(&args.information) {
        visnav_io::atomic::check_writable(path)
            .with_context(|| format!("output {}", path.display()))?;
    }
    let (estimator, cfg_toml) =
        load_estimator(args.method, args.config.as_deref(), args.reference)?;
    let img1 = load_gray(&args.image1)?;
    let img2 = load_gray(&args.image2)?;
    let fundamental = args
        .fundamental
        .as_deref()
        .map(fundamental_matrix)
        .transpose()?
        .or_else(|| {
            args.estimate_fundamental
                .then(|| visnav_geometry::tracks::fundamental_from_tracks(&img1, &img2, 0))
                .flatten()
        });
    if fundamental.is_some() && args.method == Method::Fast {
        log::warn!("--method fast has no epipolar cost: the fundamental matrix is not used");
    }
    if args.estimate_fundamental && fundamental.is_none() {
        log::warn!("no fundamental matrix could be estimated; running without the epipolar cost");
    }
    let input = FlowInput {
        fundamental,
        prior: None,
    };
    let (flow, timings) = estimator
        .compute_timed(&img1, &img2, &input)
        .with_context(|| {
            format!(
                "flow between {} and {}",
                args.image1.display(),
                args.image2.display()
            )
        })?;
    write_flo(&args.output, &to_flow_field(&flow))?;
    if let Some(p) = &args.information {
        write_pfm(p, &information_pfm(&flow))?;
    }
    if let Some(dir) = &args.visualize {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        // one saturation scale for the picture and the rim of its legend's wheel
        let max_px = colour::max_magnitude_px(flow.flow.iter().copied());
        save_rgb(
            &dir.join("flow.png"),
            &flow_colour(&flow, max_px),
            flow.width,
            flow.height,
        )?;
        save_rgb(
            &dir.join("uncertainty.png"),
            &uncertainty_colour(&flow),
            flow.width,
            flow.height,
        )?;
        write_atomic(&dir.join("flow-config.toml"), cfg_toml.as_bytes())?;
        let page = visualisation_page(args, &flow, max_px, timings.total_ms)?;
        write_atomic(&dir.join("index.html"), page.as_bytes())?;
    }
    let valid_fraction = flow.valid_fraction();
    if valid_fraction == 0.0 {
        log::warn!(
            "no pixel of {} and {} passed the forward-backward check (flat or unrelated images?): \
             the flow is the prior everywhere, with the maximum uncertainty",
            args.image1.display(),
            args.image2.display()
        );
    }
    if args.json {
        let out = serde_json::json!({
            "width": flow.width,
            "height": flow.height,
            "valid_fraction": valid_fraction,
            "timings_ms": timings,
        });
        println!("{out}");
    } else {
        log::info!(
            "flow {}x{}: {:.1} % forward-backward consistent, {:.0} ms",
            flow.width,
            flow.height,
            100.0 * valid_fraction,
            timings.total_ms
        );
    }
    Ok(())
}

/// The flow as a `.flo` field.
#[must_use]
pub fn to_flow_field(flow: &DenseFlow) -> FlowField {
    FlowField {
        width: flow.width,
        height: flow.height,
        uv: flow.flow.iter().flat_map(|f| [f[0], f[1]]).collect(),
    }
}

/// The information matrix as a 3-channel PFM image.
#[must_use]
pub fn information_pfm(flow: &DenseFlow) -> PfmImage {
    PfmImage {
        width: flow.width,
        height: flow.height,
        channels: 3,
        data: flow.information.iter().flat_map(|m| *m).collect(),
    }
}

fn save_rgb(path: &Path, rgb: &[u8], w: usize, h: usize) -> Result<()> {
    let img = image::RgbImage::from_raw(w as u32, h as u32, rgb.to_vec())
        .context("internal: RGB buffer size")?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .with_context(|| format!("cannot encode {}", path.display()))?;
    write_atomic(path, png.get_ref())?;
    Ok(())
}

/// Middlebury-style colour coding (`visnav_report::colour`): hue = direction, saturation =
/// magnitude relative to `max_px` (the largest magnitude in the field).
fn flow_colour(flow: &DenseFlow, max_px: f32) -> Vec<u8> {
    flow.flow
        .iter()
        .flat_map(|f| colour::flow_rgb(*f, max_px))
        .collect()
}

/// The page of `--visualize`: the two images with their legends (colour wheel with the rim
/// magnitude `max_px`, the 1-sigma scale), the input names and the run's figures.
fn visualisation_page(args: &Args, flow: &DenseFlow, max_px: f32, total_ms: f64) -> Result<String> {
    use visnav_report::html::escape;
    let name = |p: &Path| {
        escape(&p.file_name().map_or_else(
            || p.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        ))
    };
    let (a, b) = (name(&args.image1), name(&args.image2));
    let (pa, pb) = (
        escape(&args.image1.display().to_string()),
        escape(&args.image2.display().to_string()),
    );
    Ok(format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>visnav flow: {a} → {b}</title>
<style>body{{font-family:sans-serif;margin:1.5em}}figure{{margin:0 0 1.5em 0}}img{{max-width:100%;image-rendering:pixelated}}</style></head>
<body><h1>Dense flow {a} → {b}</h1>
<p>From <code>{pa}</code> to <code>{pb}</code>: {w}×{h} px, {valid:.1} % of the pixels forward–backward consistent, largest flow {max_px:.1} px, {total_ms:.0} ms. Configuration: <a href="flow-config.toml">flow-config.toml</a>.</p>
<figure><img src="flow.png" alt="flow, colour wheel"><figcaption>flow</figcaption>{wheel}</figure>
<figure><img src="uncertainty.png" alt="1-sigma radius"><figcaption>uncertainty: 1-sigma radius sqrt(trace(P) / 2) of each pixel's flow covariance</figcaption>{sigma}</figure>
</body></html>
"#,
        w = flow.width,
        h = flow.height,
        valid = 100.0 * flow.valid_fraction(),
        wheel = visnav_report::wheel_legend(max_px)?,
        sigma = colour::sigma_legend_svg(),
    ))
}

/// Heat map of the 1-sigma radius `sqrt(trace(P) / 2)`, log scale from 0.1 px (blue) to 10 px
/// (red) (`visnav_report::colour`).
fn uncertainty_colour(flow: &DenseFlow) -> Vec<u8> {
    flow.information
        .iter()
        .flat_map(|y| colour::sigma_rgb(colour::sigma_px(*y)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Result<Args, clap::Error> {
        let mut argv = vec!["flow", "a.png", "b.png", "-o", "f.flo", "--fundamental"];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv).map(|c| c.args)
    }

    #[test]
    fn fundamental_takes_negative_numbers_and_rejects_nan() {
        let real = [
            "0", "-1.2e-6", "0.0031", "1.1e-6", "0", "-0.3", "-0.003", "0.29", "1",
        ];
        let a = parse(&real).unwrap();
        let f = fundamental_matrix(a.fundamental.as_deref().unwrap()).unwrap();
        assert_eq!(f[(1, 2)], -0.3);
        let mut with_nan = real;
        with_nan[4] = "NaN";
        let a = parse(&with_nan).unwrap();
        let e = fundamental_matrix(a.fundamental.as_deref().unwrap()).unwrap_err();
        assert!(e.to_string().contains("number 5"), "{e}");
        assert!(fundamental_matrix(&[0.0; 9]).is_err());
        assert!(parse(&real[..8]).is_err());
    }
}
