//! How far the mono window's tracks drift from the truth on a rendered flight, forward and
//! backward: the pixels of a 6-px grid of frame `START` (40 px inside the border) followed over
//! `AGES` frames (`START..=START+AGES`, then the same frames reversed) by three trackers, and the
//! median share of the true displacement from the first frame found (`d·g / |g|²`) and the
//! median error along it (pixels) printed at every age:
//!
//! * mode 0: chained through the pipeline's dense flow (`mono::follow_flow`), as the window did before
//!   `MonoWindowConfig::refine_tracks`;
//! * mode 1: each frame's flow pixel refined by Lucas–Kanade from the previous image (15x15,
//!   the template warped by the flow's Jacobian: what `refine_tracks` does);
//! * mode 2: aligned against the first frame's patch, the template warped by the product of
//!   the flow's Jacobians (tried, not kept).
//!
//! The truth is the grid pixel's true depth and the true poses.
//! docs/notes/2026-12-02-aerial-history.md, round 9.
//!
//! ```sh
//! visnav synth --flight flight563.toml --out fl563 --frames 563 --width 620 --height 188
//! cargo run --release -p visnav-odometry --example window_track_bias -- fl563 100 12
//! ```

use nalgebra::{Matrix2, Point2, Point3};
use visnav_image::{KltConfig, Pyramid, track_warped};
use visnav_odometry::mono::{MonoConfig, MonoFlow, flow_jacobian, follow_flow};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(
        args.next()
            .ok_or("usage: window_track_bias DIR [START] [AGES]")?,
    );
    let start: usize = args.next().map_or(Ok(100), |s| s.parse())?;
    let ages: usize = args.next().map_or(Ok(6), |s| s.parse())?;
    let seq = visnav_io::Sequence::open(&dir)?;
    let poses = visnav_io::trajectory::read_kitti(&dir.join("poses.txt"))?;
    let flow_stage = MonoFlow::new(&MonoConfig::default().flow)?;
    let cam = seq.camera;
    for backward in [false, true] {
        let frames: Vec<usize> = if backward {
            (start..=start + ages).rev().collect()
        } else {
            (start..=start + ages).collect()
        };
        let first = frames[0];
        let z0 = visnav_io::pfm::read_pfm(&dir.join(format!("depth/{first:06}.pfm")))?;
        let imgs: Vec<_> = frames
            .iter()
            .map(|&i| seq.load_left(i))
            .collect::<Result<_, _>>()?;
        let pyr: Vec<_> = imgs.iter().map(|im| Pyramid::build(im, 1)).collect();
        let w = cam.width as usize;
        let (mut seeds, mut depths) = (Vec::new(), Vec::new());
        for y in (40..cam.height as usize - 40).step_by(6) {
            for x in (40..w - 40).step_by(6) {
                let z = f64::from(z0.data[y * w + x]);
                if z > 0.0 && z < 1e4 {
                    seeds.push(Point2::new(x as f64, y as f64));
                    depths.push(z);
                }
            }
        }
        for mode in 0..3 {
            let refine = mode > 0;
            let mut cur: Vec<Option<Point2<f64>>> = seeds.iter().map(|p| Some(*p)).collect();
            let mut line = format!("{} mode {mode}:", if backward { "bwd" } else { "fwd" });
            let mut comp: Vec<Matrix2<f64>> = vec![Matrix2::identity(); seeds.len()];
            for k in 1..frames.len() {
                let (flow, _) = flow_stage.compute_timed(&imgs[k - 1], &imgs[k])?;
                let mut idx = Vec::new();
                let (mut pts, mut guesses, mut warps) = (Vec::new(), Vec::new(), Vec::new());
                for (i, c) in cur.iter_mut().enumerate() {
                    let Some(p) = *c else { continue };
                    match follow_flow(&flow, &p) {
                        Some(q) => {
                            idx.push(i);
                            pts.push(p);
                            guesses.push(q);
                            let j = flow_jacobian(&flow, &p);
                            comp[i] = j * comp[i];
                            warps.push(if mode == 2 { comp[i] } else { j });
                        }
                        None => *c = None,
                    }
                }
                let targets: Vec<Option<Point2<f64>>> = if refine {
                    let cfg = KltConfig {
                        window_radius: 7,
                        levels: 1,
                        ..KltConfig::default()
                    };
                    let (src, from): (&Pyramid, Vec<Point2<f64>>) = if mode == 2 {
                        (&pyr[0], idx.iter().map(|&i| seeds[i]).collect())
                    } else {
                        (&pyr[k - 1], pts.clone())
                    };
                    track_warped(src, &pyr[k], &from, Some(&guesses), &warps, &cfg)?
                        .iter()
                        .zip(&guesses)
                        .map(|(t, g)| t.tracked().filter(|q| (q - g).norm() <= 1.0))
                        .collect()
                } else {
                    guesses.iter().map(|g| Some(*g)).collect()
                };
                for (i, t) in idx.into_iter().zip(targets) {
                    cur[i] = t.filter(|q| {
                        q.x >= 40.0
                            && q.y >= 40.0
                            && q.x <= cam.width as f64 - 41.0
                            && q.y <= cam.height as f64 - 41.0
                    });
                }
                // share of the true displacement from the seed
                let b_from_a = poses[frames[k]].inverse() * poses[first];
                let mut shares = Vec::new();
                let mut along = Vec::new();
                for ((s, z), c) in seeds.iter().zip(&depths).zip(&cur) {
                    let Some(c) = c else { continue };
                    let Some(t) = cam.project(&(b_from_a * Point3::from(cam.ray(s) * *z))) else {
                        continue;
                    };
                    let g = t - s;
                    if g.norm() < 2.0 {
                        continue;
                    }
                    shares.push((c - s).dot(&g) / g.norm_squared());
                    along.push((c - t).dot(&g) / g.norm());
                }
                shares.sort_by(f64::total_cmp);
                along.sort_by(f64::total_cmp);
                let med = |v: &[f64]| v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
                line += &format!(
                    " | {k}: {:.4} {:+.3}px ({})",
                    med(&shares),
                    med(&along),
                    shares.len()
                );
            }
            println!("{line}");
        }
    }
    Ok(())
}
