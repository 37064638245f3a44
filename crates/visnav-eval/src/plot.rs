//! Plots of an evaluation, drawn with plotters, each written as PNG and SVG:
//!
//! * the top view (x–z plane of the world = first camera frame: x right, z forward) of the
//!   estimate against the ground truth, with equal axis scales;
//! * the KITTI errors against segment length or speed (t_err in %, r_err in deg/100 m), as the
//!   devkit's `tl`/`rl`/`ts`/`rs` plots;
//! * per-frame series (timings by stage stacked, feature counts as lines) for the run report.
//!
//! The `*_svg` functions return an SVG document as a string (for inlining in an HTML page).
//!
//! Text uses DejaVu Sans embedded by the `dejavu` crate (no system font is needed), registered
//! with plotters once as `sans-serif` by [`register_font`].

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::PoseMatrix;

use crate::error::{EvalError, Result};
use crate::kitti::BinScore;

/// The font family the plots use.
pub const FONT_FAMILY: &str = "sans-serif";

/// Registers the embedded DejaVu Sans with plotters as [`FONT_FAMILY`] (once per process).
///
/// # Errors
/// The embedded font cannot be parsed (never expected).
pub fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
            && plotters::style::register_font(FONT_FAMILY, FontStyle::Bold, dejavu::sans::bold())
                .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(EvalError::Plot {
            path: PathBuf::from("<embedded DejaVu Sans>"),
            message: "cannot register the embedded font".into(),
        })
    }
}

type DrawResult<T, DB> =
    std::result::Result<T, DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A panel of the error plot: axis description, colour, value of a bin.
type Series = (&'static str, RGBColor, fn(&BinScore) -> f64);

/// x axis of the errors against segment length.
const LENGTH_DESC: &str = "segment length [m]";

/// Colours of per-frame series (Tableau 10).
const SERIES_COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

const EST_COLOR: RGBColor = RGBColor(214, 39, 40);
const GT_COLOR: RGBColor = RGBColor(31, 119, 180);

/// Largest magnitude a plot axis spans: values beyond are clamped to it (they are drawn at the
/// edge), so that ranges and their padding never overflow to inf or NaN (plotters asserts on a
/// NaN range).
const PLOT_MAX_ABS: f64 = 1e15;

/// A value clamped to ±[`PLOT_MAX_ABS`]: the ranges hold every clamped value, so that no point
/// maps to a pixel coordinate beyond `i32` (plotters adds it to the plot's origin and overflows).
fn drawable(v: f64) -> f64 {
    v.clamp(-PLOT_MAX_ABS, PLOT_MAX_ABS)
}

/// `(min, max)` of values, widened so the range is never empty nor narrower than 1e-9 of its
/// magnitude: plotters steps its ticks across the range, and a range a few ULPs wide (all
/// values near 1.7e308, or one value of 1e9) made that loop never end.
fn padded_range(values: impl Iterator<Item = f64>, pad_frac: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        let v = drawable(v);
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let magnitude = lo.abs().max(hi.abs());
    let span = (hi - lo).max(1e-6).max(1e-9 * magnitude);
    let mid = 0.5 * (lo + hi);
    let half = 0.5 * span * (1.0 + 2.0 * pad_frac);
    (mid - half, mid + half)
}

fn draw_top_view<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    gt: &[PoseMatrix],
    est: &[PoseMatrix],
    title: &str,
) -> DrawResult<(), DB> {
    root.fill(&WHITE)?;
    let xz = |m: &PoseMatrix| (drawable(m[(0, 3)]), drawable(m[(2, 3)]));
    let all = gt.iter().chain(est).map(xz);
    let (x0, x1) = padded_range(all.clone().map(|p| p.0), 0.05);
    let (z0, z1) = padded_range(all.map(|p| p.1), 0.05);
    // equal scales: widen the narrower axis to the plot's aspect ratio
    let (w, h) = root.dim_in_pixel();
    let aspect = f64::from(w.saturating_sub(90).max(1)) / f64::from(h.saturating_sub(90).max(1));
    let (cx, cz) = (0.5 * (x0 + x1), 0.5 * (z0 + z1));
    let (mut hx, mut hz) = (0.5 * (x1 - x0), 0.5 * (z1 - z0));
    if hx / hz < aspect {
        hx = hz * aspect;
    } else {
        hz = hx / aspect;
    }
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT_FAMILY, 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d((cx - hx)..(cx + hx), (cz - hz)..(cz + hz))?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("z [m]")
        .label_style((FONT_FAMILY, 14))
        .axis_desc_style((FONT_FAMILY, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    if !gt.is_empty() {
        chart
            .draw_series(LineSeries::new(gt.iter().map(xz), GT_COLOR.stroke_width(2)))?
            .label("ground truth")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GT_COLOR.stroke_width(2)));
    }
    chart
        .draw_series(LineSeries::new(
            est.iter().map(xz),
            EST_COLOR.stroke_width(2),
        ))?
        .label("estimate")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], EST_COLOR.stroke_width(2)));
    if let Some(p) = gt.first().or(est.first()) {
        chart
            .draw_series(std::iter::once(Circle::new(xz(p), 5, BLACK.filled())))?
            .label("start")
            .legend(|(x, y)| Circle::new((x + 10, y), 4, BLACK.filled()));
    }
    chart
        .configure_series_labels()
        .label_font((FONT_FAMILY, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    root.present()
}

fn draw_errors<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    per_length: &[BinScore],
    title: &str,
    x_desc: &str,
) -> DrawResult<(), DB> {
    root.fill(&WHITE)?;
    let root = root.titled(title, (FONT_FAMILY, 22))?;
    let panels = root.split_evenly((1, 2));
    let l_max = per_length
        .iter()
        .map(|b| b.key)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .min(PLOT_MAX_ABS);
    let (l0, l1) = (0.0, if l_max > 0.0 { 1.1 * l_max } else { 1.0 });
    let series: [Series; 2] = [
        ("translation error [%]", EST_COLOR, |b| b.t_err_percent),
        ("rotation error [deg/100 m]", GT_COLOR, |b| {
            b.r_err_deg_per_100m
        }),
    ];
    for (panel, (desc, color, f)) in panels.iter().zip(series) {
        let hi = per_length
            .iter()
            .map(f)
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            .min(PLOT_MAX_ABS);
        let hi = if hi > 0.0 { hi * 1.15 } else { 1.0 };
        let mut chart = ChartBuilder::on(panel)
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(l0..l1, 0.0..hi)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(desc)
            .label_style((FONT_FAMILY, 14))
            .axis_desc_style((FONT_FAMILY, 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        chart.draw_series(LineSeries::new(
            per_length.iter().map(|b| (drawable(b.key), drawable(f(b)))),
            color.stroke_width(2),
        ))?;
        chart.draw_series(
            per_length
                .iter()
                .map(|b| Circle::new((drawable(b.key), drawable(f(b))), 4, color.filled())),
        )?;
    }
    root.present()
}

fn both_formats(
    dir: &Path,
    stem: &str,
    size: (u32, u32),
    draw_png: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> std::result::Result<(), String>,
    draw_svg: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> std::result::Result<(), String>,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| EvalError::Plot {
        path: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    {
        let area = BitMapBackend::new(&png, size).into_drawing_area();
        draw_png(&area).map_err(|message| EvalError::Plot {
            path: png.clone(),
            message,
        })?;
    }
    {
        let area = SVGBackend::new(&svg, size).into_drawing_area();
        draw_svg(&area).map_err(|message| EvalError::Plot {
            path: svg.clone(),
            message,
        })?;
    }
    for p in [&png, &svg] {
        if !p.exists() {
            return Err(EvalError::Plot {
                path: p.clone(),
                message: "the plot backend wrote no file".into(),
            });
        }
    }
    Ok(vec![png, svg])
}

/// Writes `<stem>.png` and `<stem>.svg` in `dir`: top view (x–z) of `est` against `gt`.
///
/// # Errors
/// The directory or a file cannot be written.
pub fn plot_top_view(
    dir: &Path,
    stem: &str,
    gt: &[PoseMatrix],
    est: &[PoseMatrix],
    title: &str,
) -> Result<Vec<PathBuf>> {
    register_font()?;
    both_formats(
        dir,
        stem,
        (900, 800),
        |a| draw_top_view(a, gt, est, title).map_err(|e| e.to_string()),
        |a| draw_top_view(a, gt, est, title).map_err(|e| e.to_string()),
    )
}

/// Writes `<stem>.png` and `<stem>.svg` in `dir`: translation and rotation error against
/// segment length (one point per length bin).
///
/// # Errors
/// The directory or a file cannot be written.
pub fn plot_errors_vs_length(
    dir: &Path,
    stem: &str,
    per_length: &[BinScore],
    title: &str,
) -> Result<Vec<PathBuf>> {
    register_font()?;
    both_formats(
        dir,
        stem,
        (1200, 500),
        |a| draw_errors(a, per_length, title, LENGTH_DESC).map_err(|e| e.to_string()),
        |a| draw_errors(a, per_length, title, LENGTH_DESC).map_err(|e| e.to_string()),
    )
}

/// Which axis a KITTI error plot has: segment length (m) or speed (m/s).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorAxis {
    /// `BinScore::key` is a segment length in metres.
    SegmentLength,
    /// `BinScore::key` is a speed in m/s.
    Speed,
}

/// A named per-frame series: `(frame, value)` points.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedSeries {
    /// Legend entry.
    pub name: String,
    /// `(x, y)` points, x increasing.
    pub points: Vec<(f64, f64)>,
}

/// How [`series_svg`] draws its series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesStyle {
    /// Stacked areas (the series add up, e.g. time per stage).
    Stacked,
    /// Lines (independent series, e.g. feature counts).
    Lines,
}

/// Draws into an SVG string of `size` pixels.
fn svg_string(
    size: (u32, u32),
    what: &str,
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> std::result::Result<(), String>,
) -> Result<String> {
    register_font()?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw(&area).map_err(|message| EvalError::Plot {
            path: PathBuf::from(format!("<{what} svg>")),
            message,
        })?;
    }
    Ok(svg)
}

/// The top view (x–z) of `est` against `gt` (may be empty) as an SVG document.
///
/// # Errors
/// The plot cannot be drawn (never expected for finite poses).
pub fn top_view_svg(
    gt: &[PoseMatrix],
    est: &[PoseMatrix],
    title: &str,
    size: (u32, u32),
) -> Result<String> {
    svg_string(size, "top view", |a| {
        draw_top_view(a, gt, est, title).map_err(|e| e.to_string())
    })
}

/// The KITTI translation and rotation errors per bin as an SVG document.
///
/// # Errors
/// The plot cannot be drawn (never expected for finite scores).
pub fn errors_svg(
    bins: &[BinScore],
    axis: ErrorAxis,
    title: &str,
    size: (u32, u32),
) -> Result<String> {
    let x_desc = match axis {
        ErrorAxis::SegmentLength => LENGTH_DESC,
        ErrorAxis::Speed => "speed [m/s]",
    };
    svg_string(size, "errors", |a| {
        draw_errors(a, bins, title, x_desc).map_err(|e| e.to_string())
    })
}

fn draw_series<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &[NamedSeries],
    style: SeriesStyle,
    labels: (&str, &str, &str),
    legend_at: SeriesLabelPosition,
) -> DrawResult<(), DB> {
    let (title, x_desc, y_desc) = labels;
    root.fill(&WHITE)?;
    // stacked: each series drawn as the running sum of itself and the ones before it
    let mut drawn: Vec<Vec<(f64, f64)>> = Vec::with_capacity(series.len());
    for s in series {
        let points = match (style, drawn.last()) {
            (SeriesStyle::Stacked, Some(below)) => s
                .points
                .iter()
                .zip(below)
                .map(|(&(x, y), &(_, b))| (x, y + b))
                .collect(),
            _ => s.points.clone(),
        };
        drawn.push(
            points
                .into_iter()
                .map(|(x, y)| (drawable(x), drawable(y)))
                .collect(),
        );
    }
    let xs = drawn.iter().flatten().map(|p| p.0);
    let (x0, x1) = padded_range(xs, 0.0);
    let y_hi = drawn
        .iter()
        .flatten()
        .map(|p| p.1)
        .filter(|y| y.is_finite())
        .fold(0.0f64, f64::max)
        .min(PLOT_MAX_ABS);
    let y_hi = if y_hi > 0.0 { 1.1 * y_hi } else { 1.0 };
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT_FAMILY, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, 0.0..y_hi)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style((FONT_FAMILY, 13))
        .axis_desc_style((FONT_FAMILY, 15))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    // draw the top of the stack first so the lower areas stay visible
    for (k, (s, points)) in series.iter().zip(&drawn).enumerate().rev() {
        let color = SERIES_COLORS[k % SERIES_COLORS.len()];
        let legend =
            move |(x, y): (i32, i32)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], color.filled());
        match style {
            SeriesStyle::Stacked => chart
                .draw_series(AreaSeries::new(
                    points.iter().copied(),
                    0.0,
                    color.mix(0.85).filled(),
                ))?
                .label(s.name.as_str())
                .legend(legend),
            SeriesStyle::Lines => chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    color.stroke_width(2),
                ))?
                .label(s.name.as_str())
                .legend(legend),
        };
    }
    chart
        .configure_series_labels()
        .label_font((FONT_FAMILY, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(legend_at)
        .draw()?;
    root.present()
}

/// Per-frame series (stacked areas or lines) as an SVG document; `labels` are the title and the
/// x and y axis descriptions. Stacked series must share their x values.
///
/// # Errors
/// The plot cannot be drawn (never expected for finite values).
pub fn series_svg(
    series: &[NamedSeries],
    style: SeriesStyle,
    labels: (&str, &str, &str),
    size: (u32, u32),
) -> Result<String> {
    series_svg_with_legend(series, style, labels, size, SeriesLabelPosition::UpperRight)
}

/// [`series_svg`] with the legend box at `legend_at` (for curves that rise to the upper right).
///
/// # Errors
/// The plot cannot be drawn (never expected for finite values).
pub fn series_svg_with_legend(
    series: &[NamedSeries],
    style: SeriesStyle,
    labels: (&str, &str, &str),
    size: (u32, u32),
    legend_at: SeriesLabelPosition,
) -> Result<String> {
    svg_string(size, "series", |a| {
        draw_series(a, series, style, labels, legend_at).map_err(|e| e.to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use visnav_core::Pose;

    #[test]
    fn plots_are_written_in_both_formats() {
        let dir = tempfile::tempdir().unwrap();
        let gt: Vec<Pose> = (0..50)
            .map(|i| {
                let a = 0.05 * f64::from(i);
                Pose::from_parts(
                    Translation3::new(10.0 * a.sin(), 0.0, 10.0 * (1.0 - a.cos())),
                    UnitQuaternion::identity(),
                )
            })
            .collect();
        let est: Vec<Pose> = gt
            .iter()
            .map(|p| Pose::from_parts((p.translation.vector * 1.05).into(), p.rotation))
            .collect();
        let gt = crate::pose_matrices(&gt);
        let est = crate::pose_matrices(&est);
        let files = plot_top_view(dir.path(), "top", &gt, &est, "test").unwrap();
        assert_eq!(files.len(), 2);
        for f in &files {
            assert!(
                std::fs::metadata(f).unwrap().len() > 1000,
                "{}",
                f.display()
            );
        }
        let svg = std::fs::read_to_string(&files[1]).unwrap();
        assert!(svg.contains("ground truth"));
        let bins = [
            BinScore {
                key: 100.0,
                t_err_percent: 2.0,
                r_err_deg_per_100m: 1.0,
                segments: 5,
            },
            BinScore {
                key: 200.0,
                t_err_percent: 1.5,
                r_err_deg_per_100m: 0.7,
                segments: 4,
            },
        ];
        let files = plot_errors_vs_length(dir.path(), "err", &bins, "errors").unwrap();
        assert!(files.iter().all(|f| f.exists()));
        let svg = errors_svg(&bins, ErrorAxis::Speed, "by speed", (800, 300)).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("speed [m/s]"),
            "{svg:.200}"
        );
        let svg = top_view_svg(&[], &est, "estimate only", (500, 400)).unwrap();
        assert!(svg.contains("estimate") && !svg.contains("ground truth"));
        // an unwritable target is an error, not a panic
        let blocker = dir.path().join("file");
        std::fs::write(&blocker, "x").unwrap();
        assert!(plot_top_view(&blocker, "top", &gt, &est, "t").is_err());
    }
}

#[cfg(test)]
mod extreme_tests {
    use super::*;

    fn at(x: f64, z: f64) -> PoseMatrix {
        let mut m = PoseMatrix::identity();
        m[(0, 3)] = x;
        m[(2, 3)] = z;
        m
    }

    /// Coordinates of ±1e308 made the range NaN (plotters panicked), near 1.7e308 or a single
    /// point at 1e9 the tick loop never ended (issue 21).
    #[test]
    fn top_view_of_extreme_coordinates_neither_panics_nor_hangs() {
        let cases = [
            vec![at(-1e308, 0.0), at(1e308, 1e308)],
            vec![at(1.7e308, 1.7e308), at(1.7e308, 1.7e308)],
            vec![at(1e9, 1e9)],
            vec![at(f64::NAN, f64::INFINITY), at(0.0, 1.0)],
        ];
        for poses in &cases {
            let svg = top_view_svg(poses, poses, "extreme", (400, 300)).unwrap();
            assert!(svg.starts_with("<svg"));
        }
        let (lo, hi) = padded_range([1.7e308, 1.7e308].into_iter(), 0.05);
        assert!(lo.is_finite() && hi.is_finite() && hi - lo >= 1e-9 * hi.abs());
    }
}

#[cfg(test)]
mod series_tests {
    use super::*;

    #[test]
    fn stacked_series_are_drawn_with_legend_and_axes() {
        let a = NamedSeries {
            name: "flow_ms".into(),
            points: (0..20).map(|i| (f64::from(i), 10.0)).collect(),
        };
        let b = NamedSeries {
            name: "vo_ms".into(),
            points: (0..20).map(|i| (f64::from(i), f64::from(i))).collect(),
        };
        let svg = series_svg(
            &[a.clone(), b.clone()],
            SeriesStyle::Stacked,
            ("time", "frame", "ms"),
            (600, 300),
        )
        .unwrap();
        for text in ["flow_ms", "vo_ms", "frame", "ms", "<polygon"] {
            assert!(svg.contains(text), "missing {text}");
        }
        // the stack tops at 10 + 19 = 29 ms: the y axis reaches beyond 25
        assert!(svg.contains("25.0") && svg.contains("30.0"), "{svg}");
        let lines = series_svg(
            &[a, b],
            SeriesStyle::Lines,
            ("n", "frame", "count"),
            (600, 300),
        )
        .unwrap();
        assert!(lines.contains("<polyline"));
        // an empty series set still gives a valid (empty) chart
        assert!(series_svg(&[], SeriesStyle::Lines, ("n", "x", "y"), (300, 200)).is_ok());
    }
}
