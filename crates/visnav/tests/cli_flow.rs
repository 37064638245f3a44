//! `visnav flow` and `visnav flow-eval` end to end on a synthetic pair written as PNG.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_flow::synthetic::{Motion, render_pair};
use visnav_io::flo::{FlowField, read_flo, write_flo};
use visnav_io::image_io::save_gray_png;
use visnav_io::pfm::read_pfm;

mod common;
use common::{run_err, run_ok, visnav};

const W: usize = 150;
const H: usize = 120;

fn write_pair(dir: &Path) -> Vec<[f32; 2]> {
    let motion = Motion {
        translation_px: [4.5, -2.0],
        angle_rad: 0.0,
        zoom: 1.0,
    };
    let pair = render_pair(W, H, 11, motion, None);
    save_gray_png(&pair.image1, &dir.join("a.png")).unwrap();
    save_gray_png(&pair.image2, &dir.join("b.png")).unwrap();
    pair.flow
}

/// The synthetic pair saved as `dir/names[0]` and `dir/names[1]`; returns the true flow.
fn write_named_pair(dir: &Path, names: [&str; 2]) -> Vec<[f32; 2]> {
    std::fs::create_dir_all(dir).unwrap();
    let truth = write_pair(dir);
    std::fs::rename(dir.join("a.png"), dir.join(names[0])).unwrap();
    std::fs::rename(dir.join("b.png"), dir.join(names[1])).unwrap();
    truth
}

/// The true flow as a Middlebury `.flo` at `path` (parent created).
fn write_truth_flo(path: &Path, truth: &[[f32; 2]]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let gt = FlowField {
        width: W,
        height: H,
        uv: truth.iter().flat_map(|f| *f).collect(),
    };
    write_flo(path, &gt).unwrap();
}

#[test]
fn flow_writes_flo_information_and_pictures() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let truth = write_pair(d);
    let out = run_ok(
        visnav()
            .args([
                "flow",
                "a.png",
                "b.png",
                "--output",
                "f.flo",
                "--information",
                "i.pfm",
            ])
            .args(["--visualize", "vis", "--json"])
            .current_dir(d),
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["width"], W);
    assert!(json["timings_ms"]["total_ms"].as_f64().unwrap() > 0.0);
    let flo = read_flo(&d.join("f.flo")).unwrap();
    assert_eq!((flo.width, flo.height), (W, H));
    let (u, v) = flo.get(W / 2, H / 2);
    let t = truth[(H / 2) * W + W / 2];
    assert!((u - t[0]).hypot(v - t[1]) < 0.5, "({u}, {v}) vs {t:?}");
    let info = read_pfm(&d.join("i.pfm")).unwrap();
    assert_eq!((info.width, info.height, info.channels), (W, H, 3));
    assert!(
        info.data
            .chunks(3)
            .all(|m| m[0] > 0.0 && m[0] * m[2] > m[1] * m[1])
    );
    assert!(d.join("vis/flow.png").is_file());
    assert!(d.join("vis/uncertainty.png").is_file());
    assert!(d.join("vis/flow-config.toml").is_file());
    let page = std::fs::read_to_string(d.join("vis/index.html")).unwrap();
    for part in [
        "src=\"flow.png\"",
        "src=\"uncertainty.png\"",
        "1-sigma radius [px], log scale",
        "a.png → b.png",
    ] {
        assert!(page.contains(part), "index.html lacks {part}");
    }
    // the wheel legend names the rim magnitude: the largest flow of the field
    let max = flo
        .uv
        .chunks(2)
        .map(|c| c[0].hypot(c[1]))
        .fold(0.0_f32, f32::max);
    assert!(page.contains(&format!("rim ≥ {max:.1} px")), "rim {max:.1}");
}

/// `visnav flow a.png b.png` in `d` with `extra` arguments, once with the AVX2 kernels chosen at
/// run time (`wide.flo`, `wide.pfm`) and once with the portable ones (`portable.*`).
fn flow_with_both_kernel_sets(d: &Path, extra: &[&str]) {
    for (name, portable) in [("wide", false), ("portable", true)] {
        let mut cmd = visnav();
        cmd.args(["flow", "a.png", "b.png", "-q"])
            .args(extra)
            .arg("--output")
            .arg(format!("{name}.flo"))
            .arg("--information")
            .arg(format!("{name}.pfm"))
            .env_remove("VISNAV_PORTABLE_SIMD")
            .current_dir(d);
        if portable {
            cmd.env("VISNAV_PORTABLE_SIMD", "1");
        }
        run_ok(&mut cmd);
    }
}

/// The AVX2 kernels (`visnav_core::simd`, chosen at run time) and the portable ones
/// (`VISNAV_PORTABLE_SIMD` set) give the same flow and information, byte for byte. On a CPU
/// without AVX2 both runs take the portable path and the test is trivially true.
#[test]
fn wide_and_portable_kernels_give_identical_flow() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_pair(d);
    flow_with_both_kernel_sets(d, &[]);
    for ext in ["flo", "pfm"] {
        let a = std::fs::read(d.join(format!("wide.{ext}"))).unwrap();
        let b = std::fs::read(d.join(format!("portable.{ext}"))).unwrap();
        assert!(a.len() > 1000);
        assert!(
            a == b,
            "{ext} outputs differ between the AVX2 and portable kernels"
        );
    }
}

#[test]
fn flow_rejects_images_of_different_sizes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_pair(d);
    let small = visnav_core::GrayImage::new(W - 3, H, 10.0);
    save_gray_png(&small, &d.join("c.png")).unwrap();
    let err = run_err(
        visnav()
            .args(["flow", "a.png", "c.png", "--output", "f.flo"])
            .current_dir(d),
    );
    assert!(err.contains("sizes differ"), "{err}");
    assert!(err.contains("a.png") && err.contains("c.png"), "{err}");
    let tiny = visnav_core::GrayImage::new(20, 12, 10.0);
    save_gray_png(&tiny, &d.join("t1.png")).unwrap();
    save_gray_png(&tiny, &d.join("t2.png")).unwrap();
    let err = run_err(
        visnav()
            .args(["flow", "t1.png", "t2.png", "--output", "t.flo"])
            .current_dir(d),
    );
    assert!(err.contains("too small") && err.contains("t1.png"), "{err}");
    assert!(!d.join("t.flo").exists());
    let out = visnav()
        .args(["flow", "a.png", "missing.png", "--output", "f.flo"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(!out.status.success());
}

#[test]
fn flow_eval_scores_a_middlebury_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let gt_file = root.join("other-gt-flow/Synth/flow10.flo");
    let truth = write_named_pair(
        &root.join("other-data/Synth"),
        ["frame10.png", "frame11.png"],
    );
    write_truth_flo(&gt_file, &truth);
    eval_layout(root, &[], "middlebury", 1);
    // the same pair twice: the pooled figures count both and equal the means over pairs
    let truth = write_named_pair(
        &root.join("other-data/Synth2"),
        ["frame10.png", "frame11.png"],
    );
    write_truth_flo(&root.join("other-gt-flow/Synth2/flow10.flo"), &truth);
    let json = eval_layout(root, &[], "middlebury", 2);
    let summary = &json["summary"];
    let pooled = &summary["pooled"];
    let pair_pixels = json["pairs"][0]["metrics"]["pixels"].as_u64().unwrap();
    assert_eq!(pooled["pixels"].as_u64().unwrap(), 2 * pair_pixels);
    for (p, m) in [
        ("epe_px", "mean_epe_px"),
        ("sigma2_percent", "mean_sigma2_percent"),
        ("half_over_all_epe", "mean_half_over_all_epe"),
    ] {
        let (p, m) = (pooled[p].as_f64().unwrap(), summary[m].as_f64().unwrap());
        assert!((p - m).abs() < 1e-6, "pooled {p} vs mean {m}");
    }
    let plots = tmp.path().join("plots");
    let out = run_ok(
        visnav()
            .args(["flow-eval", root.to_str().unwrap(), "--plots"])
            .arg(&plots),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("pooled") && text.contains("coverage.svg"),
        "{text}"
    );
    // the plots: the sparsification curves and the coverage curve against the Gaussian's
    let svg = std::fs::read_to_string(plots.join("sparsification.svg")).unwrap();
    for part in ["oracle", "most uncertain first", "mean over 2 pairs"] {
        assert!(svg.starts_with("<svg") && svg.contains(part), "{part}");
    }
    let svg = std::fs::read_to_string(plots.join("coverage.svg")).unwrap();
    for part in ["1 - exp(-k²/2)", "all pixels pooled", "k [sigma]"] {
        assert!(svg.contains(part), "{part}");
    }
    // a corrupt ground truth is a clear error
    std::fs::write(&gt_file, b"not a flo file").unwrap();
    let out = visnav()
        .args(["flow-eval", root.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
}

/// Scores `root` with `flow-eval --json` and checks the layout, the pair count and the EPE.
fn eval_layout(root: &Path, extra: &[&str], layout: &str, pairs: u64) -> serde_json::Value {
    let mut args = vec!["flow-eval", root.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let out = run_ok(visnav().args(&args));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["summary"]["layout"], layout);
    assert_eq!(json["summary"]["pairs"], pairs);
    let epe = json["summary"]["mean_epe_px"].as_f64().unwrap();
    assert!(epe < 0.5, "{layout}: EPE {epe}");
    json
}

#[test]
fn flow_eval_reads_kitti_png_ground_truth_with_its_validity_mask() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let truth = write_named_pair(
        &root.join("training/image_0"),
        ["000007_10.png", "000007_11.png"],
    );
    // KITTI's encoding: u = (R - 2^15) / 64, v = (G - 2^15) / 64, valid = B > 0; the left
    // quarter is marked invalid and holds a wrong flow that must not be scored
    let gt = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(W as u32, H as u32, |x, y| {
        let [u, v] = truth[y as usize * W + x as usize];
        let valid = x as usize >= W / 4;
        let enc = |f: f32| (f * 64.0 + 32768.0).round() as u16;
        if valid {
            image::Rgb([enc(u), enc(v), 1])
        } else {
            image::Rgb([enc(u + 40.0), enc(v), 0])
        }
    });
    for dir in ["flow_noc", "flow_occ"] {
        std::fs::create_dir_all(root.join("training").join(dir)).unwrap();
        gt.save(root.join("training").join(dir).join("000007_10.png"))
            .unwrap();
    }
    let json = eval_layout(root, &[], "kitti", 1);
    assert_eq!(json["pairs"][0]["name"], "000007");
    let pixels = json["pairs"][0]["metrics"]["pixels"].as_u64().unwrap();
    assert_eq!(pixels as usize, (W - W / 4) * H);
    eval_layout(root, &["--kitti-gt", "occ"], "kitti", 1);
}

#[test]
fn flow_eval_reads_a_sintel_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let truth = write_named_pair(
        &root.join("training/clean/alley_9"),
        ["frame_0001.png", "frame_0002.png"],
    );
    write_truth_flo(&root.join("training/flow/alley_9/frame_0001.flo"), &truth);
    let json = eval_layout(root, &[], "sintel", 1);
    assert_eq!(json["pairs"][0]["name"], "alley_9/frame_0001");
    // the final pass is asked for but missing: no layout, a clear error
    let err = run_err(visnav().args([
        "flow-eval",
        root.to_str().unwrap(),
        "--sintel-pass",
        "final",
    ]));
    assert!(err.contains("no Middlebury"), "{err}");
}

/// `--method fast`: the fast flow (dense inverse search) recovers the pair's motion, writes a
/// positive-definite information, gives the same bytes with the AVX2 and the portable kernels,
/// and refuses `--reference` (a mode of the paper's flow).
#[test]
fn the_fast_method_matches_the_pair_with_either_kernel_set() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let truth = write_pair(d);
    flow_with_both_kernel_sets(d, &["--method", "fast"]);
    let flo = read_flo(&d.join("wide.flo")).unwrap();
    let (u, v) = flo.get(W / 2, H / 2);
    let t = truth[(H / 2) * W + W / 2];
    assert!((u - t[0]).hypot(v - t[1]) < 0.3, "({u}, {v}) vs {t:?}");
    let info = read_pfm(&d.join("wide.pfm")).unwrap();
    assert!(
        info.data
            .chunks(3)
            .all(|m| m[0] > 0.0 && m[0] * m[2] > m[1] * m[1])
    );
    for ext in ["flo", "pfm"] {
        let a = std::fs::read(d.join(format!("wide.{ext}"))).unwrap();
        let b = std::fs::read(d.join(format!("portable.{ext}"))).unwrap();
        assert!(a == b, "{ext}: the AVX2 and portable kernels differ");
    }
    let err = run_err(
        visnav()
            .args(["flow", "a.png", "b.png", "--method", "fast", "--reference"])
            .args(["--output", "r.flo"])
            .current_dir(d),
    );
    assert!(err.contains("--reference"), "{err}");
}
