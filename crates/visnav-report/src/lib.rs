//! Pictures of visnav runs. The HTML run report of an odometry run: one self-contained page (no network: plots as inline
//! SVG, images as base64 PNG data URIs) with
//!
//! * the top view of the trajectory against the ground truth (when known),
//! * the KITTI errors by segment length and by speed (`visnav-eval`, the devkit's metric),
//! * the time per frame by stage (stacked), the feature / inlier counts and the status per frame
//!   (from the odometry `--json` report, stereo or mono),
//! * a gallery of frames with their dense flow (colour wheel with its px scale), the flow
//!   uncertainty (1-sigma radius in px, colour bar) and the fused depth (m, colour bar) for mono
//!   runs, or the stereo feature tracks (coloured by depth in m, outliers red) for stereo runs.
//!
//! A *run directory* holds `poses.txt` (the estimate, KITTI format) and `report.json` (the
//! odometry `--json` report), optionally `flow/` (`PPPPPP_CCCCCC.flo` + `.info.pfm`, as
//! `--save-flow` writes them), `depth/` (`NNNNNN.pfm`, as `--save-depth` writes them) and
//! `tracks/` (`NNNNNN.tracks.csv`, as `--save-tracks` writes them);
//! `visnav odometry --report` writes exactly that beside its output. The ground truth is
//! `--ground-truth`, else `poses.txt` inside the sequence directory (`visnav synth`), else
//! `poses/XX.txt` two levels above a KITTI odometry `sequences/XX` directory.

pub mod colour;
pub mod html;
pub mod run;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use visnav_eval::PoseMatrix;
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::plot::{
    ErrorAxis, NamedSeries, SeriesStyle, errors_svg, series_svg, top_view_svg,
};
use visnav_eval::{EvalConfig, TrajectoryPair, evaluate};

use self::html::{escape, img, plot, png_data_uri};
use self::run::{FrameRow, RunSummary};

/// Width of gallery images in the page, pixels.
const GALLERY_WIDTH_PX: u32 = 330;
/// Size of the wide plots, pixels.
const WIDE_PLOT: (u32, u32) = (1100, 380);

/// What a report is made of.
#[derive(Debug, Clone)]
pub struct ReportInputs {
    /// The estimated trajectory (KITTI or TUM).
    pub poses: PathBuf,
    /// The odometry `--json` report.
    pub run_json: PathBuf,
    /// Directory of saved flow (`PPPPPP_CCCCCC.flo` + `.info.pfm`), if any.
    pub flow_dir: Option<PathBuf>,
    /// Directory of saved depth maps (`NNNNNN.pfm`, metres), if any.
    pub depth_dir: Option<PathBuf>,
    /// Directory of saved stereo tracks (`NNNNNN.tracks.csv`), if any.
    pub tracks_dir: Option<PathBuf>,
    /// Ground truth; `None` looks beside the sequence (see the module doc).
    pub ground_truth: Option<PathBuf>,
    /// The sequence directory (frames of the gallery); `None` takes the report's `sequence`.
    pub sequence: Option<PathBuf>,
    /// KITTI segment lengths, metres; `None` picks five from the path length (the devkit's
    /// 100..800 m when the path is at least 800 m long).
    pub lengths_m: Option<Vec<f64>>,
    /// Frames in the gallery (at most).
    pub gallery_frames: usize,
}

impl ReportInputs {
    /// The inputs of a run directory (see the module doc), with `poses.txt` and `report.json`.
    #[must_use]
    pub fn from_run_dir(dir: &Path) -> Self {
        let optional = |name: &str| Some(dir.join(name)).filter(|p| p.is_dir());
        Self {
            poses: dir.join("poses.txt"),
            run_json: dir.join("report.json"),
            flow_dir: optional("flow"),
            depth_dir: optional("depth"),
            tracks_dir: optional("tracks"),
            ground_truth: None,
            sequence: None,
            lengths_m: None,
            gallery_frames: 4,
        }
    }
}

/// Builds the report page.
///
/// # Errors
/// An unreadable or invalid trajectory, odometry report or explicitly given ground truth. Broken
/// gallery files are skipped with a warning and a note on the page; a ground truth found
/// automatically that cannot be read is a warning.
pub fn build(inputs: &ReportInputs) -> anyhow::Result<String> {
    let run = run::read_run(&inputs.run_json)?;
    let est = visnav_io::trajectory::read_pose_matrices(&inputs.poses)
        .with_context(|| format!("reading trajectory {}", inputs.poses.display()))?
        .poses;
    if est.is_empty() {
        bail!("{} holds no pose", inputs.poses.display());
    }
    let sequence = inputs.sequence.clone().or_else(|| run.sequence.clone());
    let gt = load_ground_truth(inputs, sequence.as_deref())?;
    let name = sequence
        .as_deref()
        .and_then(Path::file_name)
        .map_or_else(|| "run".to_owned(), |n| n.to_string_lossy().into_owned());
    let title = format!("visnav {} odometry: {name}", run.mode);

    let mut body = String::new();
    let _ = write!(body, "<h1>{}</h1>", escape(&title));
    let cut = pose_count_mismatch(inputs, run.frames, est.len());
    if let Some(c) = &cut {
        log::warn!("{c}");
        let _ = write!(body, r#"<p class="note">{}</p>"#, escape(c));
    }
    // palindrome runs go out and back: only the way out matches the ground truth
    let est_scored = &est[..run.input_frames.clamp(1, est.len())];
    let scored = gt
        .as_ref()
        .map(|(gt_path, gt)| (gt_path, score(gt, est_scored, inputs.lengths_m.clone())));
    body.push_str(&summary_table(
        inputs,
        &run,
        sequence.as_deref(),
        &est,
        scored.as_ref().map(|(p, s)| (p.as_path(), s)),
    ));

    body.push_str("<h2>Trajectory</h2>");
    let gt_poses: &[PoseMatrix] = gt.as_ref().map_or(&[], |(_, g)| g.as_slice());
    let gt_shown = &gt_poses[..gt_poses.len().min(est_scored.len())];
    body.push_str(&plot(
        "top_view",
        &top_view_svg(gt_shown, &est, &format!("{name}: top view (x-z)"), (760, 640))?,
        "Top view of the left camera path in the first camera frame (x right, z forward), equal axis scales; red: estimate, blue: ground truth.",
    ));
    match &scored {
        Some((_, Ok(report))) if report.segments > 0 => {
            body.push_str(&plot(
                "errors_length",
                &errors_svg(&report.per_length, ErrorAxis::SegmentLength, "KITTI error by segment length", (900, 340))?,
                &format!("Mean translation (%) and rotation (deg/100 m) error of all segments of each length (devkit metric; lengths {:?} m, a segment every 10 frames).", report.lengths_m),
            ));
            body.push_str(&plot(
                "errors_speed",
                &errors_svg(&report.per_speed, ErrorAxis::Speed, "KITTI error by speed", (900, 340))?,
                "The same segments binned by speed (segment length / duration at 10 Hz, 2 m/s bins as the devkit).",
            ));
        }
        Some((_, Ok(_))) => body.push_str(
            r#"<p class="note">The run is too short for any KITTI segment of the chosen lengths (try <code>--lengths</code>).</p>"#,
        ),
        Some((_, Err(e))) => {
            let _ = write!(body, r#"<p class="note">No KITTI score: {}</p>"#, escape(&format!("{e:#}")));
        }
        None => body.push_str(
            r#"<p class="note">No ground truth (give <code>--ground-truth GT.txt</code>): no error plots.</p>"#,
        ),
    }

    body.push_str("<h2>Time per frame</h2>");
    body.push_str(&plot(
        "timing",
        &series_svg(&timing_series(&run.per_frame), SeriesStyle::Stacked, ("Time per frame by stage (stacked)", "frame (step of the run)", "time [ms]"), WIDE_PLOT)?,
        "Wall time of each stage of each frame, stacked (totals left out; wait = waiting for the decoded image).",
    ));
    body.push_str("<h2>Features and inliers</h2>");
    body.push_str(&plot(
        "counts",
        &series_svg(&count_series(&run.per_frame), SeriesStyle::Lines, ("Features and inliers per frame", "frame (step of the run)", "count"), WIDE_PLOT)?,
        if run.mode == "stereo" {
            "Stereo: corners detected, with a stereo match, tracked, passing the circular check, and inliers of the rotation and translation phases."
        } else {
            "Mono: flow correspondences, Mahalanobis eight-point inliers, PnP correspondences and inliers."
        },
    ));
    body.push_str("<h2>Status per frame</h2>");
    body.push_str(&status_section(&run.per_frame, cut.as_deref()));

    body.push_str("<h2>Gallery</h2>");
    body.push_str(&gallery(inputs, sequence.as_deref()));

    body.push_str(&frame_table(&run.per_frame));
    Ok(html::page(&title, &body))
}

/// Writes the report to `output`.
///
/// # Errors
/// As [`build`], or the output cannot be written.
pub fn write(inputs: &ReportInputs, output: &Path) -> anyhow::Result<()> {
    let page = build(inputs)?;
    visnav_io::trajectory::write_atomically(output, page.as_bytes())
        .with_context(|| format!("writing report {}", output.display()))
}

/// The ground truth: the given file (an error when unreadable), else one found beside the
/// sequence (a warning when unreadable).
fn load_ground_truth(
    inputs: &ReportInputs,
    sequence: Option<&Path>,
) -> anyhow::Result<Option<(PathBuf, Vec<PoseMatrix>)>> {
    if let Some(p) = &inputs.ground_truth {
        let gt = visnav_io::trajectory::read_pose_matrices(p)
            .with_context(|| format!("reading ground truth {}", p.display()))?;
        return Ok(Some((p.clone(), gt.poses)));
    }
    let Some(found) = sequence.and_then(find_ground_truth) else {
        return Ok(None);
    };
    match visnav_io::trajectory::read_pose_matrices(&found) {
        Ok(gt) => Ok(Some((found, gt.poses))),
        Err(e) => {
            log::warn!(
                "ground truth {}: {e:#}; the report has no error plots",
                found.display()
            );
            Ok(None)
        }
    }
}

/// `SEQ/poses.txt` (`visnav synth`), else `SEQ/../../poses/NAME.txt` for a KITTI odometry
/// `sequences/NAME` directory.
#[must_use]
pub fn find_ground_truth(sequence: &Path) -> Option<PathBuf> {
    let inside = sequence.join("poses.txt");
    if inside.is_file() {
        return Some(inside);
    }
    let name = sequence.file_name()?;
    let parent = sequence.parent()?;
    if parent.file_name()? != "sequences" {
        return None;
    }
    let kitti = parent
        .parent()?
        .join("poses")
        .join(format!("{}.txt", name.to_string_lossy()));
    kitti.is_file().then_some(kitti)
}

/// A round step (1, 2 or 5 × 10^k) near `x`.
fn nice_step(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= x)
        .unwrap_or(10.0 * p)
}

/// Segment lengths for a path: the devkit's when it is long enough, else five round lengths up to
/// about half the path.
fn auto_lengths(path_length_m: f64) -> Vec<f64> {
    let devkit = KittiMetricConfig::default().lengths_m;
    if path_length_m >= devkit.last().copied().unwrap_or(800.0) {
        return devkit;
    }
    let step = nice_step((path_length_m / 10.0).max(0.1));
    (1..=5).map(|k| f64::from(k) * step).collect()
}

fn score(
    gt: &[PoseMatrix],
    est: &[PoseMatrix],
    lengths_m: Option<Vec<f64>>,
) -> anyhow::Result<visnav_eval::EvalReport> {
    let n = gt.len().min(est.len());
    let path = visnav_eval::kitti::trajectory_distances(&gt[..n])
        .last()
        .copied()
        .map_or(0.0, f64::from);
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths_m.unwrap_or_else(|| auto_lengths(path)),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    };
    config.validate()?;
    // the run covers the start of the sequence only: score the frames it has
    Ok(evaluate(
        &[TrajectoryPair::by_index(&gt[..n], &est[..n])],
        &config,
    )?)
}

fn summary_table(
    inputs: &ReportInputs,
    run: &RunSummary,
    sequence: Option<&Path>,
    est: &[PoseMatrix],
    scored: Option<(&Path, &anyhow::Result<visnav_eval::EvalReport>)>,
) -> String {
    let mut rows: Vec<(String, String)> = vec![
        ("mode".into(), run.mode.clone()),
        (
            "sequence".into(),
            sequence.map_or_else(|| "unknown".into(), |p| p.display().to_string()),
        ),
        ("estimate".into(), inputs.poses.display().to_string()),
        ("poses".into(), est.len().to_string()),
        ("frames in the report".into(), run.frames.to_string()),
        ("wall time".into(), format!("{:.2} s", run.wall_s)),
    ];
    rows.extend(run.figures.iter().cloned());
    match scored {
        Some((gt, Ok(r))) => {
            rows.push(("ground truth".into(), gt.display().to_string()));
            if r.segments > 0 {
                rows.push((
                    "KITTI error".into(),
                    format!(
                        "{:.3} % / {:.3} deg/100 m ({} segments, lengths {:?} m)",
                        r.t_err_percent, r.r_err_deg_per_100m, r.segments, r.lengths_m
                    ),
                ));
            }
            if let Some(a) = r.ate_se3_m {
                rows.push(("ATE (SE(3) aligned)".into(), format!("{a:.3} m")));
            }
            if let Some(a) = r.ate_sim3_m {
                rows.push(("ATE (Sim(3) aligned)".into(), format!("{a:.3} m")));
            }
        }
        Some((gt, Err(_))) => rows.push(("ground truth".into(), gt.display().to_string())),
        None => rows.push(("ground truth".into(), "none".into())),
    }
    let mut s = String::from("<table class=\"summary\">");
    for (k, v) in rows {
        let _ = write!(s, "<tr><th>{}</th><td>{}</td></tr>", escape(&k), escape(&v));
    }
    s.push_str("</table>");
    s
}

/// Stage names in order of first appearance.
fn names<'a>(rows: impl Iterator<Item = &'a Vec<(String, f64)>>) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        for (k, _) in r {
            if !out.contains(k) {
                out.push(k.clone());
            }
        }
    }
    out
}

fn series_of(frames: &[FrameRow], pick: fn(&FrameRow) -> &Vec<(String, f64)>) -> Vec<NamedSeries> {
    names(frames.iter().map(pick))
        .into_iter()
        .map(|name| NamedSeries {
            points: frames
                .iter()
                .map(|f| {
                    let v = pick(f)
                        .iter()
                        .find(|(k, _)| *k == name)
                        .map_or(0.0, |(_, v)| *v);
                    (f.step as f64, v)
                })
                .collect(),
            name,
        })
        .collect()
}

fn timing_series(frames: &[FrameRow]) -> Vec<NamedSeries> {
    series_of(frames, |f| &f.timings_ms)
}

fn count_series(frames: &[FrameRow]) -> Vec<NamedSeries> {
    series_of(frames, |f| &f.counts)
}

/// Colour of a frame status in the status strip.
fn status_colour(status: &str) -> &'static str {
    match status {
        "ok" => "#2ca02c",
        "low_parallax" => "#ff7f0e",
        "fallback" => "#d62728",
        "skipped" => "#9467bd",
        _ => "#7f7f7f",
    }
}

/// Issue 53: a `poses.txt` with fewer (or more) poses than the run's report has frames (a copy
/// cut short, the poses of another run): what the page and a warning say about it.
fn pose_count_mismatch(inputs: &ReportInputs, frames: usize, poses: usize) -> Option<String> {
    (poses != frames).then(|| {
        let what = if poses < frames {
            format!(
                "the trajectory is cut: frames {poses} to {} of the run have no pose",
                frames - 1
            )
        } else {
            "the trajectory is not this run's".to_owned()
        };
        format!(
            "{} holds {poses} poses but the run's report {} has {frames} frames: {what}",
            inputs.poses.display(),
            inputs.run_json.display()
        )
    })
}

/// A strip with one cell per frame coloured by status, its legend, and a table of the frames
/// that were not plainly `ok` (`cut`: why the trajectory does not hold every frame).
fn status_section(frames: &[FrameRow], cut: Option<&str>) -> String {
    let w = 1100.0;
    let cell = w / frames.len().max(1) as f64;
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="70" viewBox="0 0 {w} 70">"#
    );
    for (k, f) in frames.iter().enumerate() {
        let _ = write!(
            svg,
            r#"<rect x="{:.2}" y="0" width="{:.2}" height="30" fill="{}"><title>step {} frame {}: {}</title></rect>"#,
            k as f64 * cell,
            cell.max(0.5),
            status_colour(&f.status),
            f.step,
            f.index,
            escape(&f.status)
        );
    }
    let mut statuses: Vec<&str> = frames.iter().map(|f| f.status.as_str()).collect();
    statuses.sort_unstable();
    statuses.dedup();
    let mut x = 0.0;
    for s in statuses {
        let n = frames.iter().filter(|f| f.status == s).count();
        let _ = write!(
            svg,
            r##"<rect x="{x}" y="44" width="14" height="14" fill="{}" stroke="#333"/><text x="{}" y="56" font-size="13">{} ({n})</text>"##,
            status_colour(s),
            x + 20.0,
            escape(s)
        );
        x += 30.0 + 9.0 * (s.len() as f64 + 5.0);
    }
    svg.push_str("</svg>");
    let mut out = plot(
        "status",
        &svg,
        "Status of each frame, left to right (hover for details): green ok, blue first, orange low speed / low parallax, red constant-velocity fallback.",
    );
    let special: Vec<&FrameRow> = frames.iter().filter(|f| f.status != "ok").collect();
    if let Some(c) = cut {
        let _ = write!(out, r#"<p class="note">{}</p>"#, escape(c));
    }
    if special.is_empty() && cut.is_none() {
        out.push_str("<p>Every frame after the first was estimated (status ok).</p>");
    } else if special.is_empty() {
        out.push_str("<p>Every frame of the run's report after the first was estimated (status ok), but the trajectory does not hold them all.</p>");
    } else {
        out.push_str("<table><tr><th>step</th><th>frame</th><th>status</th><th>detail</th></tr>");
        for f in special.iter().take(200) {
            let _ = write!(
                out,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                f.step,
                f.index,
                escape(&f.status),
                escape(&f.detail)
            );
        }
        out.push_str("</table>");
        if special.len() > 200 {
            let _ = write!(out, "<p>… and {} more.</p>", special.len() - 200);
        }
    }
    out
}

/// The full per-frame table, folded.
fn frame_table(frames: &[FrameRow]) -> String {
    let count_names = names(frames.iter().map(|f| &f.counts));
    let timing_names = names(frames.iter().map(|f| &f.timings_ms));
    let mut s = String::from(
        "<h2>All frames</h2><details><summary>per-frame table</summary><table><tr><th>step</th><th>frame</th><th>status</th><th>detail</th>",
    );
    for n in count_names.iter().chain(&timing_names) {
        let _ = write!(s, "<th>{}</th>", escape(n));
    }
    s.push_str("</tr>");
    for f in frames {
        let _ = write!(
            s,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            f.step,
            f.index,
            escape(&f.status),
            escape(&f.detail)
        );
        for (names, values) in [(&count_names, &f.counts), (&timing_names, &f.timings_ms)] {
            for n in names {
                match values.iter().find(|(k, _)| k == n) {
                    Some((_, v)) => {
                        let _ = write!(s, "<td>{v:.1}</td>");
                    }
                    None => s.push_str("<td></td>"),
                }
            }
        }
        s.push_str("</tr>");
    }
    s.push_str("</table></details>");
    s
}

/// One frame of the gallery: what is saved for frame `index`.
#[derive(Debug, Clone, Default)]
struct GalleryFrame {
    index: usize,
    /// `(previous frame, .flo path)`.
    flow: Option<(usize, PathBuf)>,
    depth: Option<PathBuf>,
    /// `NNNNNN.tracks.csv`.
    tracks: Option<PathBuf>,
}

/// `NNNNNN` or `PPPPPP_CCCCCC` stems of the files in `dir` ending in `suffix`.
fn stems(dir: &Path, suffix: &str) -> Vec<(String, PathBuf)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        log::warn!("cannot list {}", dir.display());
        return Vec::new();
    };
    let mut out: Vec<(String, PathBuf)> = entries
        .filter_map(Result::ok)
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let stem = name.strip_suffix(suffix)?.to_owned();
            Some((stem, e.path()))
        })
        .collect();
    out.sort();
    out
}

fn gallery_frames(inputs: &ReportInputs) -> Vec<GalleryFrame> {
    let mut frames: std::collections::BTreeMap<usize, GalleryFrame> = Default::default();
    if let Some(dir) = &inputs.flow_dir {
        for (stem, path) in stems(dir, ".flo") {
            if let Some((p, c)) = stem.split_once('_')
                && let (Ok(p), Ok(c)) = (p.parse::<usize>(), c.parse::<usize>())
            {
                let f = frames.entry(c).or_default();
                f.index = c;
                f.flow = Some((p, path));
            }
        }
    }
    if let Some(dir) = &inputs.depth_dir {
        // `NNNNNN.pfm` only: the way back of a palindrome (`_back`) is left out
        for (stem, path) in stems(dir, ".pfm") {
            if let Ok(i) = stem.parse::<usize>() {
                let f = frames.entry(i).or_default();
                f.index = i;
                f.depth = Some(path);
            }
        }
    }
    if let Some(dir) = &inputs.tracks_dir {
        for (stem, path) in stems(dir, ".tracks.csv") {
            if let Ok(i) = stem.parse::<usize>() {
                let f = frames.entry(i).or_default();
                f.index = i;
                f.tracks = Some(path);
            }
        }
    }
    let all: Vec<GalleryFrame> = frames.into_values().collect();
    let k = inputs.gallery_frames.min(all.len());
    if k == 0 {
        return Vec::new();
    }
    // evenly spaced, last one included
    (0..k)
        .map(|j| {
            all[if k == 1 {
                all.len() / 2
            } else {
                j * (all.len() - 1) / (k - 1)
            }]
            .clone()
        })
        .collect()
}

/// Resizes an RGB image to the gallery width.
fn to_gallery(rgb: image::RgbImage, filter: image::imageops::FilterType) -> image::RgbImage {
    let (w, h) = rgb.dimensions();
    let new_h =
        ((f64::from(h) * f64::from(GALLERY_WIDTH_PX) / f64::from(w.max(1))).round() as u32).max(1);
    image::imageops::resize(&rgb, GALLERY_WIDTH_PX, new_h, filter)
}

fn rgb_image(w: usize, h: usize, rgb: Vec<u8>) -> anyhow::Result<image::RgbImage> {
    image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .with_context(|| format!("internal: RGB buffer of {w}x{h}"))
}

/// The flow colour image and the magnitude of its wheel's rim, pixels.
fn flow_images(flo: &Path) -> anyhow::Result<(String, Option<String>, f32)> {
    let field = visnav_io::flo::read_flo(flo)?;
    let uv = || field.uv.chunks_exact(2).map(|c| [c[0], c[1]]);
    let max_px = colour::max_magnitude_px(uv().filter(|f| f[0].abs() < 1e9 && f[1].abs() < 1e9));
    let rgb = uv()
        .flat_map(|f| {
            // `.flo` marks unknown flow with values above 1e9
            if f[0].abs() > 1e9 || f[1].abs() > 1e9 {
                colour::UNKNOWN_RGB
            } else {
                colour::flow_rgb(f, max_px)
            }
        })
        .collect();
    let flow_uri = png_data_uri(to_gallery(
        rgb_image(field.width, field.height, rgb)?,
        image::imageops::FilterType::Triangle,
    ))?;
    let info_path = flo.with_extension("info.pfm");
    let sigma_uri = if info_path.is_file() {
        let info = visnav_io::pfm::read_pfm(&info_path)?;
        if info.channels != 3 || info.width != field.width || info.height != field.height {
            bail!(
                "{}: {}x{}x{} information, expected {}x{}x3",
                info_path.display(),
                info.width,
                info.height,
                info.channels,
                field.width,
                field.height
            );
        }
        let rgb = info
            .data
            .chunks_exact(3)
            .flat_map(|y| colour::sigma_rgb(colour::sigma_px([y[0], y[1], y[2]])))
            .collect();
        Some(png_data_uri(to_gallery(
            rgb_image(info.width, info.height, rgb)?,
            image::imageops::FilterType::Triangle,
        ))?)
    } else {
        None
    };
    Ok((flow_uri, sigma_uri, max_px))
}

fn depth_image(path: &Path) -> anyhow::Result<(String, f32, f32)> {
    let d = visnav_io::pfm::read_pfm(path)?;
    if d.channels != 1 {
        bail!(
            "{}: {} channels, expected a 1-channel depth map",
            path.display(),
            d.channels
        );
    }
    let (near, far) = colour::depth_range_m(&d.data).unwrap_or((1.0, 2.0));
    let rgb = d
        .data
        .iter()
        .flat_map(|z| colour::depth_rgb(*z, near, far))
        .collect();
    let uri = png_data_uri(to_gallery(
        rgb_image(d.width, d.height, rgb)?,
        image::imageops::FilterType::Nearest,
    ))?;
    Ok((uri, near, far))
}

use visnav_io::tracks::TrackRow;

/// Reads a tracks file (`--save-tracks`); errors name the file and the line.
fn read_tracks(path: &Path) -> anyhow::Result<Vec<TrackRow>> {
    Ok(visnav_io::tracks::read_tracks_csv(path)?)
}

/// Colour of an outlier track.
const OUTLIER_RGB: [u8; 3] = [230, 30, 30];

/// The tracks of a frame drawn over it (or over a grey canvas when the frame is not at hand):
/// a line from the previous to the current position and a dot there, coloured by depth, outliers
/// red. Returns the image, the depth range of the colours, inliers and all tracks.
fn tracks_image(
    csv: &Path,
    frame: Option<image::RgbImage>,
) -> anyhow::Result<(String, f32, f32, usize, usize)> {
    use plotters::prelude::*;
    let rows = read_tracks(csv)?;
    let depths: Vec<f32> = rows
        .iter()
        .filter(|r| r.inlier)
        .map(|r| r.depth_m as f32)
        .collect();
    let (near, far) = colour::depth_range_m(&depths).unwrap_or((1.0, 2.0));
    let base = frame.unwrap_or_else(|| {
        let w = rows
            .iter()
            .map(|r| r.cur_px[0].max(r.prev_px[0]))
            .fold(1.0, f64::max);
        let h = rows
            .iter()
            .map(|r| r.cur_px[1].max(r.prev_px[1]))
            .fold(1.0, f64::max);
        image::RgbImage::from_pixel(
            w.ceil() as u32 + 1,
            h.ceil() as u32 + 1,
            image::Rgb(colour::UNKNOWN_RGB),
        )
    });
    let scale = f64::from(GALLERY_WIDTH_PX) / f64::from(base.width().max(1));
    let small = to_gallery(base, image::imageops::FilterType::Triangle);
    let (w, h) = small.dimensions();
    let mut buf = small.into_raw();
    {
        let area = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let px = |p: [f64; 2]| ((p[0] * scale).round() as i32, (p[1] * scale).round() as i32);
        // outliers first, so that inliers stay visible where they overlap
        for r in rows
            .iter()
            .filter(|r| !r.inlier)
            .chain(rows.iter().filter(|r| r.inlier))
        {
            let [cr, cg, cb] = if r.inlier {
                colour::depth_rgb(r.depth_m as f32, near, far)
            } else {
                OUTLIER_RGB
            };
            let c = RGBColor(cr, cg, cb);
            area.draw(&PathElement::new(vec![px(r.prev_px), px(r.cur_px)], c))
                .and_then(|()| area.draw(&Circle::new(px(r.cur_px), 2, c.filled())))
                .map_err(|e| anyhow::anyhow!("drawing the tracks of {}: {e}", csv.display()))?;
        }
        area.present()
            .map_err(|e| anyhow::anyhow!("drawing the tracks of {}: {e}", csv.display()))?;
    }
    let inliers = rows.iter().filter(|r| r.inlier).count();
    let uri = png_data_uri(rgb_image(w as usize, h as usize, buf)?)?;
    Ok((uri, near, far, inliers, rows.len()))
}

/// The colour wheel legend: the wheel with its rim magnitude in px and the axis directions.
///
/// # Errors
/// PNG encoding of the wheel failed.
pub fn wheel_legend(max_px: f32) -> anyhow::Result<String> {
    const SIZE: usize = 96;
    let uri = png_data_uri(rgb_image(SIZE, SIZE, colour::wheel_rgb(SIZE))?)?;
    Ok(format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" class="legend" width="320" height="130" viewBox="0 0 320 130"><image href="{uri}" x="10" y="16" width="{SIZE}" height="{SIZE}"/><circle cx="58" cy="64" r="48" fill="none" stroke="#333"/><text x="10" y="11" font-size="12">flow colour wheel (x right, y down)</text><text x="118" y="50" font-size="12">hue: direction</text><text x="118" y="68" font-size="12">saturation: |flow| / {max:.1} px</text><text x="118" y="86" font-size="12">centre 0 px, rim ≥ {max:.1} px</text><text x="118" y="104" font-size="12">grey: unknown</text></svg>"##,
        max = max_px
    ))
}

fn gallery(inputs: &ReportInputs, sequence: Option<&Path>) -> String {
    let frames = gallery_frames(inputs);
    if frames.is_empty() {
        return "<p class=\"note\">No saved flow, depth or tracks (mono runs save them with <code>--save-flow DIR --save-depth DIR</code>, stereo runs with <code>--save-tracks DIR</code>, both with <code>--report</code>).</p>".into();
    }
    let seq = sequence.and_then(|p| match visnav_io::Sequence::open(p) {
        Ok(s) => Some(s),
        Err(e) => {
            log::warn!("report gallery: sequence {}: {e}", p.display());
            None
        }
    });
    let mut s = String::from("<table class=\"gallery\">");
    for f in &frames {
        let mut cells = Vec::new();
        let mut notes = Vec::new();
        let mut frame_rgb = None;
        if let Some(seq) = &seq
            && f.index < seq.len()
        {
            match image::open(seq.left_path(f.index)) {
                Ok(im) => match png_data_uri(to_gallery(
                    frame_rgb.insert(im.to_rgb8()).clone(),
                    image::imageops::FilterType::Triangle,
                )) {
                    Ok(uri) => cells.push(format!(
                        "{}<figcaption>frame {} (left camera)</figcaption>",
                        img(&uri, &format!("frame {}", f.index), "frame"),
                        f.index
                    )),
                    Err(e) => notes.push(format!("{e:#}")),
                },
                Err(e) => notes.push(format!("{}: {e}", seq.left_path(f.index).display())),
            }
        }
        if let Some((prev, flo)) = &f.flow {
            match flow_images(flo) {
                Ok((flow_uri, sigma_uri, max_px)) => {
                    cells.push(format!(
                        "{}<figcaption>flow {prev} → {}</figcaption>{}",
                        img(&flow_uri, &format!("flow {prev} to {}", f.index), "flow"),
                        f.index,
                        wheel_legend(max_px).unwrap_or_default()
                    ));
                    if let Some(uri) = sigma_uri {
                        cells.push(format!(
                            "{}<figcaption>flow uncertainty {prev} → {}</figcaption>{}",
                            img(&uri, &format!("uncertainty {prev} to {}", f.index), "sigma"),
                            f.index,
                            colour::sigma_legend_svg()
                        ));
                    }
                }
                Err(e) => notes.push(format!("{e:#}")),
            }
        }
        if let Some(depth) = &f.depth {
            match depth_image(depth) {
                Ok((uri, near, far)) => cells.push(format!(
                    "{}<figcaption>fused depth of frame {}</figcaption>{}",
                    img(&uri, &format!("depth {}", f.index), "depth"),
                    f.index,
                    colour::depth_legend_svg(near, far)
                )),
                Err(e) => notes.push(format!("{e:#}")),
            }
        }
        if let Some(csv) = &f.tracks {
            match tracks_image(csv, frame_rgb.take()) {
                Ok((uri, near, far, inliers, all)) => cells.push(format!(
                    "{}<figcaption>stereo tracks {} → {}: {inliers} inliers of {all} (line: motion in the image; colour: depth, red: outlier)</figcaption>{}",
                    img(&uri, &format!("tracks {}", f.index), "tracks"),
                    f.index.saturating_sub(1),
                    f.index,
                    colour::depth_legend_svg(near, far)
                )),
                Err(e) => notes.push(format!("{e:#}")),
            }
        }
        for n in &notes {
            log::warn!("report gallery, frame {}: {n}", f.index);
        }
        let _ = write!(s, "<tr><th colspan=\"4\">frame {}</th></tr><tr>", f.index);
        for c in cells {
            let _ = write!(s, "<td><figure>{c}</figure></td>");
        }
        s.push_str("</tr>");
        for n in notes {
            let _ = write!(
                s,
                "<tr><td colspan=\"4\" class=\"note\">skipped: {}</td></tr>",
                escape(&n)
            );
        }
    }
    s.push_str("</table>");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_follow_the_path() {
        assert_eq!(auto_lengths(2000.0), KittiMetricConfig::default().lengths_m);
        assert_eq!(auto_lengths(100.0), vec![10.0, 20.0, 30.0, 40.0, 50.0]);
        assert_eq!(auto_lengths(27.0), vec![5.0, 10.0, 15.0, 20.0, 25.0]);
        assert_eq!(nice_step(0.3), 0.5);
    }

    #[test]
    fn ground_truth_is_found_beside_the_sequence() {
        let root = tempfile::tempdir().unwrap();
        let seq = root.path().join("sequences").join("07");
        std::fs::create_dir_all(&seq).unwrap();
        assert_eq!(find_ground_truth(&seq), None);
        std::fs::create_dir_all(root.path().join("poses")).unwrap();
        std::fs::write(root.path().join("poses/07.txt"), "").unwrap();
        assert_eq!(
            find_ground_truth(&seq),
            Some(root.path().join("poses/07.txt"))
        );
        std::fs::write(seq.join("poses.txt"), "").unwrap();
        assert_eq!(find_ground_truth(&seq), Some(seq.join("poses.txt")));
    }

    #[test]
    fn gallery_picks_evenly_spaced_frames() {
        let dir = tempfile::tempdir().unwrap();
        let flow = dir.path().join("flow");
        std::fs::create_dir_all(&flow).unwrap();
        for c in 1..=9 {
            std::fs::write(flow.join(format!("{:06}_{c:06}.flo", c - 1)), "").unwrap();
        }
        std::fs::write(flow.join("notes.txt"), "").unwrap();
        let mut inputs = ReportInputs::from_run_dir(dir.path());
        assert_eq!(inputs.flow_dir.as_deref(), Some(flow.as_path()));
        assert_eq!(inputs.depth_dir, None);
        inputs.gallery_frames = 3;
        let picked: Vec<usize> = gallery_frames(&inputs).iter().map(|f| f.index).collect();
        assert_eq!(picked, [1, 5, 9]);
        // a broken .flo is skipped with a note, not a failure of the report
        let page = gallery(&inputs, None);
        assert!(page.contains("skipped"), "{page}");
    }
}
