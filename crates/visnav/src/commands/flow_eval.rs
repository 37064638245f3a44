//! `visnav flow-eval DATASET_DIR [--json]`: runs visnav-flow on every pair of a Middlebury
//! (`other-data` + `other-gt-flow`), KITTI 2012/2015 (`image_0` or `image_2` + `flow_noc` /
//! `flow_occ`, 16-bit PNG) or MPI-Sintel (`training/<pass>` + `training/flow`) layout and scores
//! the flow (EPE, Fl, time) and its uncertainty (sparsification, AUSE, sigma-ellipse coverage).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use visnav_core::FlowField;
use visnav_eval::flow::{
    FlowMetrics, FlowPixel, coverage_percent, evaluate, gaussian_coverage_percent,
};
use visnav_flow::{AnyFlow, DenseFlow, FlowInput};
use visnav_io::flow_benchmarks::{FlowPair, discover_flow_pairs};
use visnav_io::image_io::load_gray;

/// Arguments of `visnav flow-eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Dataset root (Middlebury, KITTI or Sintel layout; detected automatically).
    pub dataset: PathBuf,
    /// KITTI ground truth: `noc` (non-occluded, default) or `occ` (all).
    #[arg(long, default_value = "noc")]
    pub kitti_gt: KittiGt,
    /// Sintel pass (`clean` or `final`).
    #[arg(long, default_value = "clean")]
    pub sintel_pass: String,
    /// Evaluate at most this many pairs (at least 1).
    #[arg(long)]
    pub limit: Option<usize>,
    /// Flow configuration (TOML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Flow algorithm: `paper` (default) or `fast` (dense inverse search).
    #[arg(long, value_enum, default_value = "paper")]
    pub method: super::flow::Method,
    /// DCFlow reference mode (±80 px window).
    #[arg(long)]
    pub reference: bool,
    /// Estimate a fundamental matrix per pair (corners + KLT + eight-point) and add the
    /// epipolar cost (for static scenes, e.g. KITTI 2012).
    #[arg(long)]
    pub estimate_fundamental: bool,
    /// Write a per-pair end-point-error map (`<pair>_epe.png`, 0 = black, >= 5 px = white)
    /// into this directory.
    #[arg(long)]
    pub error_maps: Option<PathBuf>,
    /// Write `sparsification.svg` (EPE of the pixels kept against the share removed, by
    /// predicted uncertainty and by the oracle) and `coverage.svg` (share of the ground truth
    /// inside the k-sigma ellipse against k, with the Gaussian's) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Print the results as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Which KITTI ground truth to score against.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum KittiGt {
    /// `flow_noc`.
    Noc,
    /// `flow_occ`.
    Occ,
}

impl From<KittiGt> for visnav_io::flow_benchmarks::KittiGt {
    fn from(k: KittiGt) -> Self {
        match k {
            KittiGt::Noc => Self::Noc,
            KittiGt::Occ => Self::Occ,
        }
    }
}

/// Scores of one pair.
#[derive(Debug, Clone, Serialize)]
struct PairResult {
    name: String,
    width: usize,
    height: usize,
    time_ms: f64,
    valid_fraction: f64,
    metrics: FlowMetrics,
}

/// Means over pairs.
#[derive(Debug, Clone, Serialize)]
struct Summary {
    layout: &'static str,
    pairs: usize,
    mean_epe_px: f64,
    mean_fl_percent: f64,
    mean_time_ms: f64,
    mean_sigma1_percent: f64,
    mean_sigma2_percent: f64,
    mean_ause_over_epe: f64,
    mean_half_over_all_epe: f64,
    /// Pairs whose ground truth has no valid pixel (left out of the means, with a warning).
    unscored: Vec<String>,
    /// The same metrics over all pixels of all pairs taken as one set (a large pair weighs
    /// more); `None` when the pairs hold more than [`POOLED_MAX_PIXELS`] pixels.
    pooled: Option<Pooled>,
}

/// Most pixels kept for the pooled metrics (24 bytes each: 384 MB).
const POOLED_MAX_PIXELS: usize = 16_000_000;

/// Metrics over the union of all pairs' pixels.
#[derive(Debug, Clone, Serialize)]
struct Pooled {
    pixels: usize,
    epe_px: f64,
    fl_percent: f64,
    sigma1_percent: f64,
    sigma2_percent: f64,
    ause_over_epe: f64,
    half_over_all_epe: f64,
}

impl Pooled {
    fn new(pixels: &[FlowPixel]) -> Option<Self> {
        let m = evaluate(pixels)?;
        Some(Self {
            pixels: m.pixels,
            epe_px: m.mean_epe_px,
            fl_percent: m.fl_percent,
            sigma1_percent: m.sigma1_percent,
            sigma2_percent: m.sigma2_percent,
            ause_over_epe: m.ause_over_epe,
            half_over_all_epe: m.certain_half_over_all(),
        })
    }
}

/// The evaluated pixels of one pair and their metrics (`None` when no pixel has ground truth).
fn score(
    flow: &DenseFlow,
    gt: &FlowField,
    known: &[bool],
) -> Result<(Vec<FlowPixel>, Option<FlowMetrics>)> {
    if (gt.width, gt.height) != (flow.width, flow.height) {
        bail!(
            "ground truth is {}x{}, images are {}x{}",
            gt.width,
            gt.height,
            flow.width,
            flow.height
        );
    }
    let pixels: Vec<FlowPixel> = (0..flow.width * flow.height)
        .filter(|i| known[*i])
        .map(|i| {
            let (gu, gv) = gt.get(i % gt.width, i / gt.width);
            let f = flow.flow[i];
            FlowPixel {
                error_px: [f[0] - gu, f[1] - gv],
                gt_magnitude_px: gu.hypot(gv),
                information: flow.information[i],
            }
        })
        .collect();
    let metrics = evaluate(&pixels);
    Ok((pixels, metrics))
}

/// The ellipse sizes of the coverage plot: k = 0, 0.1, …, 4 sigma.
fn coverage_ks() -> Vec<f64> {
    (0..=40).map(|i| f64::from(i) / 10.0).collect()
}

/// Writes `sparsification.svg` and `coverage.svg` (see [`Args::plots`]): curves averaged over
/// the pairs (each pair's sparsification normalised by its own EPE, as AUSE/EPE is), and the
/// pooled coverage when all pixels were kept.
fn write_plots(
    dir: &Path,
    results: &[PairResult],
    coverage: &[Vec<f64>],
    pooled: Option<&[FlowPixel]>,
    layout: &str,
) -> Result<()> {
    use plotters::prelude::SeriesLabelPosition;
    use visnav_eval::plot::{NamedSeries, SeriesStyle, series_svg, series_svg_with_legend};
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let n = results.len().max(1) as f64;
    let mean_curve = |curve: &dyn Fn(&FlowMetrics) -> &Vec<f64>| -> Vec<(f64, f64)> {
        let Some(first) = results.first() else {
            return Vec::new();
        };
        (0..first.metrics.sparsification.removed.len())
            .map(|k| {
                let y = results
                    .iter()
                    .map(|r| curve(&r.metrics)[k] / r.metrics.mean_epe_px.max(1e-12))
                    .sum::<f64>()
                    / n;
                (100.0 * first.metrics.sparsification.removed[k], y)
            })
            .collect()
    };
    let by_sigma = mean_curve(&|m| &m.sparsification.by_uncertainty_px);
    let oracle = mean_curve(&|m| &m.sparsification.oracle_px);
    let flat = by_sigma.iter().map(|p| (p.0, 1.0)).collect();
    let sparsification = series_svg(
        &[
            NamedSeries {
                name: "removing the most uncertain first".into(),
                points: by_sigma,
            },
            NamedSeries {
                name: "removing the largest errors first (oracle)".into(),
                points: oracle,
            },
            NamedSeries {
                name: "no ranking".into(),
                points: flat,
            },
        ],
        SeriesStyle::Lines,
        (
            &format!(
                "sparsification, {layout}, mean over {} pairs (area between: AUSE/EPE)",
                results.len()
            ),
            "pixels removed [%]",
            "EPE of the rest / EPE of all",
        ),
        (900, 500),
    )?;
    let path = dir.join("sparsification.svg");
    visnav_io::atomic::write_atomic(&path, sparsification.as_bytes())?;
    let ks = coverage_ks();
    let curve = |ys: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        ks.iter().enumerate().map(|(i, k)| (*k, ys(i))).collect()
    };
    let mut series = vec![NamedSeries {
        name: "calibrated Gaussian, 1 - exp(-k²/2)".into(),
        points: curve(&|i| gaussian_coverage_percent(ks[i])),
    }];
    series.push(NamedSeries {
        name: format!("mean over {} pairs", coverage.len()),
        points: curve(&|i| {
            coverage.iter().map(|c| c[i]).sum::<f64>() / coverage.len().max(1) as f64
        }),
    });
    if let Some(all) = pooled {
        let c = coverage_percent(all, &ks);
        series.push(NamedSeries {
            name: "all pixels pooled".into(),
            points: curve(&|i| c[i]),
        });
    }
    let svg = series_svg_with_legend(
        &series,
        SeriesStyle::Lines,
        (
            &format!("uncertainty calibration, {layout}: ground truth inside the k-sigma ellipse"),
            "k [sigma]",
            "share inside [%]",
        ),
        (900, 500),
        SeriesLabelPosition::LowerRight,
    )?;
    let path = dir.join("coverage.svg");
    visnav_io::atomic::write_atomic(&path, svg.as_bytes())?;
    Ok(())
}

/// Runs the subcommand.
///
/// # Errors
/// Unknown layout, unreadable files, size mismatches.
pub fn run(args: &Args, ctx: &super::Context) -> Result<()> {
    if args.limit == Some(0) {
        bail!("--limit 0: --limit must be at least 1 (leave it out to evaluate every pair)");
    }
    let (estimator, _) =
        super::flow::load_estimator(args.method, args.config.as_deref(), args.reference)?;
    let (layout, mut pairs) =
        discover_flow_pairs(&args.dataset, args.kitti_gt.into(), &args.sintel_pass)?;
    if let Some(n) = args.limit {
        pairs.truncate(n);
    }
    if pairs.is_empty() {
        bail!(
            "{}: no image pairs with ground truth",
            args.dataset.display()
        );
    }
    let bar = crate::progress::bar(pairs.len() as u64, "flow-eval", ctx.quiet || args.json);
    let mut results = Vec::new();
    // every pair's pixels, for the pooled metrics; dropped once they would exceed the cap
    let mut all_pixels: Option<Vec<FlowPixel>> = Some(Vec::new());
    // per pair, with --plots: the share inside the k-sigma ellipse for each k of coverage_ks()
    let mut coverage: Vec<Vec<f64>> = Vec::new();
    let mut unscored = Vec::new();
    for pair in &pairs {
        bar.inc(1);
        let Some((result, pixels)) = eval_pair(args, &estimator, pair)? else {
            log::warn!(
                "pair {}: no ground-truth pixel is valid in {}; the pair is not scored",
                pair.name,
                pair.gt.path().display()
            );
            unscored.push(pair.name.clone());
            continue;
        };
        if args.plots.is_some() {
            coverage.push(coverage_percent(&pixels, &coverage_ks()));
        }
        if let Some(all) = &mut all_pixels {
            if all.len() + pixels.len() > POOLED_MAX_PIXELS {
                log::info!(
                    "more than {POOLED_MAX_PIXELS} evaluated pixels: no pooled metrics, means over pairs only"
                );
                all_pixels = None;
            } else {
                all.extend_from_slice(&pixels);
            }
        }
        results.push(result);
    }
    bar.finish_and_clear();
    if results.is_empty() {
        bail!(
            "{}: no pair has a valid ground-truth pixel ({} pairs, none scored): no EPE to report",
            args.dataset.display(),
            pairs.len()
        );
    }
    let n = results.len() as f64;
    let mean = |f: &dyn Fn(&PairResult) -> f64| results.iter().map(f).sum::<f64>() / n;
    let summary = Summary {
        layout,
        pairs: results.len(),
        unscored,
        mean_epe_px: mean(&|r| r.metrics.mean_epe_px),
        mean_fl_percent: mean(&|r| r.metrics.fl_percent),
        mean_time_ms: mean(&|r| r.time_ms),
        mean_sigma1_percent: mean(&|r| r.metrics.sigma1_percent),
        mean_sigma2_percent: mean(&|r| r.metrics.sigma2_percent),
        mean_ause_over_epe: mean(&|r| r.metrics.ause_over_epe),
        mean_half_over_all_epe: mean(&|r| r.metrics.certain_half_over_all()),
        pooled: all_pixels.as_deref().and_then(Pooled::new),
    };
    if let Some(dir) = &args.plots {
        write_plots(dir, &results, &coverage, all_pixels.as_deref(), layout)?;
    }
    if args.json {
        let out = serde_json::json!({ "summary": summary, "pairs": results });
        println!("{out}");
    } else if !ctx.quiet {
        print_table(&results, &summary, args.plots.as_deref());
    }
    Ok(())
}

/// Runs the flow on one pair and scores it (with `--error-maps`, writes its EPE map); `None`
/// when no pixel of its ground truth is valid.
fn eval_pair(
    args: &Args,
    estimator: &AnyFlow,
    pair: &FlowPair,
) -> Result<Option<(PairResult, Vec<FlowPixel>)>> {
    let img1 = load_gray(&pair.image1)?;
    let img2 = load_gray(&pair.image2)?;
    let (gt, known) = pair.gt.load()?;
    let t = Instant::now();
    let input = FlowInput {
        fundamental: if args.estimate_fundamental {
            visnav_geometry::tracks::fundamental_from_tracks(&img1, &img2, 0)
        } else {
            None
        },
        prior: None,
    };
    let (flow, _) = estimator
        .compute_timed(&img1, &img2, &input)
        .with_context(|| format!("pair {}", pair.name))?;
    let time_ms = t.elapsed().as_secs_f64() * 1e3;
    let (pixels, metrics) = score(&flow, &gt, &known).with_context(|| pair.name.clone())?;
    if let Some(dir) = &args.error_maps {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let map = visnav_core::GrayImage::from_fn(flow.width, flow.height, |x, y| {
            let i = y * flow.width + x;
            if !known[i] {
                return 0.0;
            }
            let (gu, gv) = gt.get(x, y);
            let f = flow.flow[i];
            ((f[0] - gu).hypot(f[1] - gv) * 51.0).min(255.0)
        });
        let name = pair.name.replace('/', "_");
        visnav_io::image_io::save_gray_png(&map, &dir.join(format!("{name}_epe.png")))?;
    }
    let Some(metrics) = metrics else {
        return Ok(None);
    };
    let result = PairResult {
        name: pair.name.clone(),
        width: flow.width,
        height: flow.height,
        time_ms,
        valid_fraction: flow.valid_fraction(),
        metrics,
    };
    Ok(Some((result, pixels)))
}

/// Prints the per-pair table, the means and the pooled line.
fn print_table(results: &[PairResult], summary: &Summary, plots: Option<&Path>) {
    println!(
        "{:<14} {:>9} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9}",
        "pair", "EPE px", "Fl %", "1sig %", "2sig %", "AUSE/EPE", "half/all", "ms"
    );
    for r in results {
        let m = &r.metrics;
        println!(
            "{:<14} {:>9.3} {:>8.2} {:>8.1} {:>8.1} {:>8.3} {:>9.3} {:>9.0}",
            r.name,
            m.mean_epe_px,
            m.fl_percent,
            m.sigma1_percent,
            m.sigma2_percent,
            m.ause_over_epe,
            m.certain_half_over_all(),
            r.time_ms
        );
    }
    println!(
        "{:<14} {:>9.3} {:>8.2} {:>8.1} {:>8.1} {:>8.3} {:>9.3} {:>9.0}",
        "mean",
        summary.mean_epe_px,
        summary.mean_fl_percent,
        summary.mean_sigma1_percent,
        summary.mean_sigma2_percent,
        summary.mean_ause_over_epe,
        summary.mean_half_over_all_epe,
        summary.mean_time_ms
    );
    if let Some(p) = &summary.pooled {
        println!(
            "{:<14} {:>9.3} {:>8.2} {:>8.1} {:>8.1} {:>8.3} {:>9.3}",
            "pooled",
            p.epe_px,
            p.fl_percent,
            p.sigma1_percent,
            p.sigma2_percent,
            p.ause_over_epe,
            p.half_over_all_epe
        );
    }
    if let Some(dir) = plots {
        println!(
            "plots: {} and {}",
            dir.join("sparsification.svg").display(),
            dir.join("coverage.svg").display()
        );
    }
}
