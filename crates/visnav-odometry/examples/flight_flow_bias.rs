//! How far the monocular pipeline's dense flow is from giving the right inverse depth, on a
//! rendered flight (or drive) with exact depth and poses: every `STEP`-th frame pair, the flow of
//! `MonoConfig::default().flow` is triangulated in inverse depth with the *true* relative pose
//! (`triangulate_inverse_depth`, no filter on the value), and the median of
//! `ρ_flow / ρ_true` is printed by true depth and, within 200 m, by distance from the image
//! border. 1.000 everywhere is an unbiased flow; the depth-ratio scale chain of a forward flight
//! drifts with the way this ratio changes along a point's track
//! (docs/notes/2026-12-02-aerial-history.md, round 2).
//!
//! ```sh
//! visnav synth --flight flight563.toml --out fl563 --frames 563 --width 620 --height 188
//! cargo run --release -p visnav-odometry --example flight_flow_bias -- fl563 [STEP]
//! ```

use nalgebra::Point2;
use visnav_geometry::Correspondence;
use visnav_geometry::triangulation::triangulate_inverse_depth;
use visnav_odometry::mono::{MonoConfig, MonoFlow};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(args.next().ok_or("usage: flight_flow_bias DIR [STEP]")?);
    let step: usize = args.next().map_or(Ok(40), |s| s.parse())?;
    let seq = visnav_io::Sequence::open(&dir)?;
    let poses = visnav_io::trajectory::read_kitti(&dir.join("poses.txt"))?;
    let flow_stage = MonoFlow::new(&MonoConfig::default().flow)?;
    println!(
        "frame | depth <80 m, 80-200, 200-500, >500 | border <10 px, 10-25, 25-50, >=50 (depth < 200 m)"
    );
    for i in (step.max(1)..seq.len()).step_by(step.max(1)) {
        let (flow, _) = flow_stage.compute_timed(&seq.load_left(i - 1)?, &seq.load_left(i)?)?;
        let depth = visnav_io::pfm::read_pfm(&dir.join(format!("depth/{:06}.pfm", i - 1)))?;
        let cur_from_prev = poses[i].inverse() * poses[i - 1];
        let (mut by_depth, mut by_border) = (vec![Vec::new(); 4], vec![Vec::new(); 4]);
        for y in (0..flow.height).step_by(4) {
            for x in (0..flow.width).step_by(4) {
                let k = y * flow.width + x;
                let z = f64::from(depth.data[k]);
                if !(flow.valid[k] && z > 0.0 && z < 1e4) {
                    continue;
                }
                let [u, v] = flow.flow[k];
                let c = Correspondence {
                    p1_px: Point2::new(x as f64, y as f64),
                    p2_px: Point2::new(x as f64 + f64::from(u), y as f64 + f64::from(v)),
                    information: flow.information_at(k).to_matrix(),
                };
                let Some(m) = triangulate_inverse_depth(&seq.camera, &cur_from_prev, &c) else {
                    continue;
                };
                // precise enough by the truth (a selection independent of the flow's error)
                if m.variance.sqrt() > 0.5 / z {
                    continue;
                }
                let ratio = m.inverse_depth * z;
                by_depth[[80.0, 200.0, 500.0].iter().filter(|&&b| z >= b).count()].push(ratio);
                let edge = x.min(flow.width - 1 - x).min(y).min(flow.height - 1 - y);
                if z < 200.0 {
                    by_border[[10, 25, 50].iter().filter(|&&b| edge >= b).count()].push(ratio);
                }
            }
        }
        println!(
            "{i:5} | {} | {}",
            medians(&mut by_depth),
            medians(&mut by_border)
        );
    }
    Ok(())
}

/// `median (n)` of each bin.
fn medians(bins: &mut [Vec<f64>]) -> String {
    bins.iter_mut()
        .map(|b| {
            b.sort_by(f64::total_cmp);
            match b.get(b.len() / 2) {
                Some(m) => format!("{m:.3} ({})", b.len()),
                None => "- (0)".to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}
