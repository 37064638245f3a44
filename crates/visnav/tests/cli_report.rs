//! `visnav report` and `visnav odometry --report`: the HTML run report of small runs on a
//! sequence rendered by `visnav synth`, opened in headless Chromium, which must load it without
//! errors and render its plots (checked on a screenshot).
//!
//! Chromium is Debian's `chromium` (installed by `scripts/setup.sh`). Without it the browser part
//! is skipped with a message, except when `CI` is set, where a missing browser is a failure.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: usize = 9;

/// The plots every odometry report has.
const ODOMETRY_PLOTS: [&str; 6] = [
    "top_view",
    "errors_length",
    "errors_speed",
    "timing",
    "counts",
    "status",
];

fn visnav() -> Command {
    Command::new(env!("CARGO_BIN_EXE_visnav"))
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Renders a small stereo sequence (with ground truth `poses.txt`) into `dir/seq`.
fn synth(dir: &Path) -> PathBuf {
    let seq = dir.join("seq");
    run_ok(
        visnav()
            .args(["-q", "synth", "--stereo", "--out"])
            .arg(&seq)
            .args(["--frames", &FRAMES.to_string()])
            .args(["--width", "320", "--height", "96"]),
    );
    seq
}

/// Runs `visnav odometry --report` into `run_dir`; returns the report page.
fn odometry_with_report(seq: &Path, run_dir: &Path, mode: &str) -> String {
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", mode])
            .arg(seq)
            .arg("--output")
            .arg(run_dir.join("poses.txt"))
            .arg("--report"),
    );
    for f in ["poses.txt", "report.json", "report.html"] {
        assert!(run_dir.join(f).is_file(), "{mode}: no {f}");
    }
    std::fs::read_to_string(run_dir.join("report.html")).unwrap()
}

/// Checks the page is self-contained and has the sections of the issue.
fn check_page(page: &str, plots: &[&str]) {
    for p in plots {
        assert!(page.contains(&format!("data-plot=\"{p}\"")), "no plot {p}");
    }
    // nothing is fetched: every src is a data URI, no external stylesheet or script
    for pat in [
        "src=\"http",
        "href=\"http",
        "src=\"file",
        "<link",
        "@import",
        "url(http",
    ] {
        assert!(!page.contains(pat), "external reference {pat}");
    }
    // (base64 image data may spell "NaN" by chance: only the text around it counts)
    assert!(
        !without_base64(page).contains("NaN"),
        "a NaN made it to the page"
    );
}

/// The page with the payload of every `base64,` data URI removed.
fn without_base64(page: &str) -> String {
    let mut parts = page.split("base64,");
    let mut out = parts.next().unwrap_or_default().to_owned();
    for part in parts {
        let payload = part
            .find(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '+' | '/' | '=')))
            .unwrap_or(part.len());
        out.push_str(&part[payload..]);
    }
    out
}

/// Debian's Chromium, or `None` (skip) outside CI.
fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("VISNAV_CHROMIUM")
        .map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    if path.is_file() {
        return Some(path);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI is set but {} is missing: run scripts/setup.sh as root",
        path.display()
    );
    eprintln!(
        "skipping the browser check: {} is missing (run scripts/setup.sh as root)",
        path.display()
    );
    None
}

/// Runs headless Chromium on `page` with `extra` arguments (killed after 120 s); returns stdout.
fn run_chromium(chromium: &Path, page: &Path, extra: &[String]) -> String {
    let profile = tempfile::tempdir().unwrap();
    let stdout_path = profile.path().join("stdout.txt");
    let stderr_path = profile.path().join("stderr.txt");
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--virtual-time-budget=10000",
        ])
        .arg(format!(
            "--user-data-dir={}",
            profile.path().join("profile").display()
        ))
        .args(extra)
        .arg(format!("file://{}", page.display()))
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&stdout_path).unwrap())
        .stderr(std::fs::File::create(&stderr_path).unwrap())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > Duration::from_secs(120) {
            child.kill().unwrap();
            panic!("chromium did not finish in 120 s on {}", page.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    assert!(status.success(), "chromium failed: {stderr}");
    std::fs::read_to_string(&stdout_path).unwrap()
}

/// A plot's name and its box in page pixels.
#[derive(Debug)]
struct Region {
    name: String,
    x: u32,
    y: u32,
    w: u32,
    h: u32,
}

/// Loads `page` in Chromium: asserts the page's self-check found no error; returns the plots'
/// boxes.
fn load_in_browser(chromium: &Path, page: &Path) -> Vec<Region> {
    let dom = run_chromium(chromium, page, &["--dump-dom".into()]);
    let title = dom
        .split_once("<title>")
        .and_then(|(_, t)| t.split_once("</title>"))
        .map(|(t, _)| t.replace("&amp;", "&"))
        .unwrap_or_default();
    assert!(
        title.starts_with("visnav-report-ok"),
        "the page reported errors (or did not run its check): {title:.2000}"
    );
    let (_, plots) = title.split_once("| plots ").unwrap();
    plots
        .split_whitespace()
        .map(|r| {
            let f: Vec<&str> = r.split(',').collect();
            assert_eq!(f.len(), 5, "{r}");
            let n = |k: usize| f[k].parse::<i64>().unwrap().max(0) as u32;
            Region {
                name: f[0].to_owned(),
                x: n(1),
                y: n(2),
                w: n(3),
                h: n(4),
            }
        })
        .collect()
}

/// Screenshots `page` tall enough for every plot and checks each plot's box is drawn: not blank
/// (luminance spread) and with enough ink.
fn check_rendered(chromium: &Path, page: &Path, regions: &[Region]) {
    let bottom = regions.iter().map(|r| r.y + r.h).max().unwrap();
    let height = (bottom + 40).min(12_000);
    let shot = page.with_extension("png");
    run_chromium(
        chromium,
        page,
        &[
            format!("--screenshot={}", shot.display()),
            format!("--window-size=1400,{height}"),
        ],
    );
    let img = image::open(&shot).unwrap().to_luma8();
    for r in regions {
        assert!(
            r.x + r.w <= img.width() && r.y + r.h <= img.height(),
            "plot {} at {r:?} is outside the {}x{} screenshot",
            r.name,
            img.width(),
            img.height()
        );
        let values: Vec<f64> = (r.y..r.y + r.h)
            .flat_map(|y| (r.x..r.x + r.w).map(move |x| (x, y)))
            .map(|(x, y)| f64::from(img.get_pixel(x, y).0[0]))
            .collect();
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        let ink = values.iter().filter(|v| **v < 200.0).count() as f64 / n;
        assert!(
            std > 8.0 && ink > 0.005,
            "plot {} looks blank in the screenshot: std {std:.1}, ink {:.2} %",
            r.name,
            100.0 * ink
        );
    }
}

#[test]
fn mono_and_stereo_reports_load_and_render_in_chromium() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());

    let mono_dir = tmp.path().join("mono");
    let mono = odometry_with_report(&seq, &mono_dir, "mono");
    check_page(&mono, &ODOMETRY_PLOTS);
    // the gallery: frames, flow with its wheel, uncertainty and depth with colour bars
    for text in [
        "flow colour wheel",
        "1-sigma radius [px]",
        "depth [m]",
        "alt=\"frame ",
        "alt=\"flow ",
        "alt=\"uncertainty ",
        "alt=\"depth ",
        "data:image/png;base64,",
        "correspondences",
    ] {
        assert!(mono.contains(text), "mono report lacks {text}");
    }
    // --report saved a few gallery frames only, and `visnav report` on the run directory
    // rebuilds the same page
    let saved = std::fs::read_dir(mono_dir.join("flow")).unwrap().count();
    assert!(saved > 0 && saved < 2 * (FRAMES - 1), "{saved} flow files");
    let again = tmp.path().join("again.html");
    run_ok(
        visnav()
            .args(["-q", "report"])
            .arg(&mono_dir)
            .arg("--output")
            .arg(&again),
    );
    assert_eq!(std::fs::read_to_string(&again).unwrap(), mono);

    let stereo_dir = tmp.path().join("stereo");
    let stereo = odometry_with_report(&seq, &stereo_dir, "stereo");
    check_page(&stereo, &ODOMETRY_PLOTS);
    assert!(stereo.contains("rotation_inliers") && stereo.contains("pyramid_ms"));
    // the stereo gallery: frames and their tracks coloured by depth, with the depth colour bar
    for text in [
        "alt=\"frame ",
        "alt=\"tracks ",
        "stereo tracks ",
        "depth [m]",
    ] {
        assert!(stereo.contains(text), "stereo report lacks {text}");
    }
    let tracks: Vec<_> = std::fs::read_dir(stereo_dir.join("tracks"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(
        !tracks.is_empty() && tracks.len() < FRAMES,
        "{} track files",
        tracks.len()
    );
    // each file holds the frame's circular-checked tracks and its final inliers, as counted in
    // the JSON report
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(stereo_dir.join("report.json")).unwrap())
            .unwrap();
    for path in &tracks {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let index: usize = name.strip_suffix(".tracks.csv").unwrap().parse().unwrap();
        let counts = &json["per_frame"][index]["detail"]["stereo"]["counts"];
        let csv = std::fs::read_to_string(path).unwrap();
        let mut lines = csv.lines();
        assert_eq!(lines.next(), Some("prev_u,prev_v,u,v,depth_m,inlier"));
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert!(rows.iter().all(|r| r.len() == 6 && r[4] > 0.0), "{name}");
        assert_eq!(rows.len() as u64, counts["circular"].as_u64().unwrap());
        let inliers = rows.iter().filter(|r| r[5] == 1.0).count() as u64;
        let expected = match counts["translation_inliers"].as_u64().unwrap() {
            0 => counts["rotation_inliers"].as_u64().unwrap(),
            n => n,
        };
        assert!(
            inliers > 10 && inliers == expected,
            "{name}: {inliers} vs {expected}"
        );
    }
    // a malformed tracks file is skipped with a note naming it, the page still builds
    std::fs::write(&tracks[0], "prev_u,prev_v,u,v,depth_m,inlier\n1,2,3\n").unwrap();
    run_ok(
        visnav()
            .args(["-q", "report"])
            .arg(&stereo_dir)
            .arg("--output")
            .arg(tmp.path().join("stereo-again.html")),
    );
    let again = std::fs::read_to_string(tmp.path().join("stereo-again.html")).unwrap();
    assert!(
        again.contains("skipped: ") && again.contains(".tracks.csv:2:"),
        "no note"
    );

    let Some(chromium) = chromium() else {
        return;
    };
    for dir in [&mono_dir, &stereo_dir] {
        let page = dir.join("report.html");
        let regions = load_in_browser(&chromium, &page);
        let names: Vec<&str> = regions.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ODOMETRY_PLOTS, "{}", page.display());
        check_rendered(&chromium, &page, &regions);
    }
}

/// The issue's acceptance run: `visnav odometry --report` on the shared KITTI 00 clip (first 9
/// frames, mono, scale from the camera height) gives a page with every plot and a gallery that
/// Chromium loads without errors and renders.
#[test]
fn kitti_00_clip_report_loads_and_renders_in_chromium() {
    let Some(seq) = visnav_core::testdata::shared_data("kitti/odometry/sequences/00") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run00");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--max-frames", "9"])
            .args(["--camera-height", "1.7"])
            .arg(&seq)
            .arg("--output")
            .arg(dir.join("poses.txt"))
            .arg("--report"),
    );
    let page = std::fs::read_to_string(dir.join("report.html")).unwrap();
    check_page(&page, &ODOMETRY_PLOTS);
    // the ground truth was found beside the sequence (poses/00.txt) and scored
    assert!(page.contains("00.txt"), "no ground truth named");
    for text in [
        "alt=\"frame ",
        "alt=\"flow ",
        "alt=\"uncertainty ",
        "alt=\"depth ",
    ] {
        assert!(page.contains(text), "the 00 report lacks {text}");
    }
    let Some(chromium) = chromium() else {
        return;
    };
    let page_path = dir.join("report.html");
    let regions = load_in_browser(&chromium, &page_path);
    let names: Vec<&str> = regions.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ODOMETRY_PLOTS);
    check_rendered(&chromium, &page_path, &regions);
}

#[test]
fn the_self_check_catches_a_broken_image() {
    // the check must be able to fail: a page with an undecodable image reports it
    let Some(chromium) = chromium() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    let dir = tmp.path().join("run");
    let page = odometry_with_report(&seq, &dir, "stereo");
    let broken = page.replacen(
        "<h2>Trajectory</h2>",
        "<h2>Trajectory</h2><img src=\"data:image/png;base64,AAAA\" alt=\"broken\">",
        1,
    );
    let path = dir.join("broken.html");
    std::fs::write(&path, broken).unwrap();
    let dom = run_chromium(&chromium, &path, &["--dump-dom".into()]);
    assert!(
        dom.contains("visnav-report-errors: cannot load img broken"),
        "{dom:.3000}"
    );
}

#[test]
fn bad_run_directories_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = visnav()
        .args(["-q", "report"])
        .arg(tmp.path().join("missing"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not exist"));

    // a run directory without report.json names the file
    std::fs::write(tmp.path().join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    let out = visnav()
        .args(["-q", "report"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("report.json"), "{err}");

    // a report of an unknown mode
    std::fs::write(
        tmp.path().join("report.json"),
        r#"{"mode": "lidar", "per_frame": []}"#,
    )
    .unwrap();
    let out = visnav()
        .args(["-q", "report"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("report.json") && err.contains("lidar"),
        "{err}"
    );
}

#[cfg(not(feature = "rerun"))]
#[test]
fn live_view_options_need_the_rerun_feature() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    let out = visnav()
        .args(["-q", "odometry", "--mode", "stereo"])
        .arg(&seq)
        .arg("--output")
        .arg(tmp.path().join("poses.txt"))
        .arg("--rerun-save")
        .arg(tmp.path().join("live.rrd"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("`rerun` feature"), "{err}");
}

/// With the feature (`cargo test -p visnav --features rerun --test cli_report`): a mono run
/// writes a Rerun recording. Its content (path, camera, frame, flow, uncertainty, points per
/// frame) was checked with rerun-cli 0.36.3's `rerun rrd verify` / `rrd print`
/// (docs/benchmarks.md, "Live view").
#[cfg(feature = "rerun")]
#[test]
fn live_view_writes_a_rerun_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    let rrd = tmp.path().join("live.rrd");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--max-frames", "4"])
            .arg(&seq)
            .arg("--output")
            .arg(tmp.path().join("poses.txt"))
            .arg("--rerun-save")
            .arg(&rrd),
    );
    let bytes = std::fs::read(&rrd).unwrap();
    // the .rrd stream header, then at least the 4 grey frames of 320x96
    assert_eq!(&bytes[..4], b"RRF2");
    assert!(bytes.len() > 4 * 320 * 96 / 4, "{} bytes", bytes.len());
}
