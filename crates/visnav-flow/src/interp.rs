//! Edge-aware interpolation of the pixels removed by the forward–backward check, in the spirit
//! of EpicFlow (Revaud et al. 2015): a geodesic distance on an edge map (cost per step
//! `1 + edge_weight * |∇I|`), computed by raster-scan passes, assigns each removed pixel the flow
//! of its geodesically nearest kept match, so flow does not leak across image edges.

use crate::config::InterpolationConfig;

/// Fills `flow` where `keep` is false with the flow of the geodesically nearest kept pixel.
/// `gradient` is the gradient magnitude of the source image. Leaves `flow` untouched when no
/// pixel is kept.
pub fn geodesic_fill(
    flow: &mut [[f32; 2]],
    keep: &[bool],
    gradient: &[f32],
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) {
    let _ = geodesic_fill_with_distance(flow, keep, gradient, w, h, cfg);
}

/// As [`geodesic_fill`], returning per pixel the geodesic distance (level px weighted by the
/// edge cost) to the kept match it took its flow from: 0 for kept pixels, infinite everywhere
/// when no pixel is kept.
pub fn geodesic_fill_with_distance(
    flow: &mut [[f32; 2]],
    keep: &[bool],
    gradient: &[f32],
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) -> Vec<f32> {
    if !keep.iter().any(|k| *k) {
        return vec![f32::INFINITY; keep.len()];
    }
    let cost: Vec<f32> = gradient.iter().map(|g| 1.0 + cfg.edge_weight * g).collect();
    let mut dist: Vec<f32> = keep
        .iter()
        .map(|k| if *k { 0.0 } else { f32::INFINITY })
        .collect();
    const DIAG: f32 = std::f32::consts::SQRT_2;
    let fwd: [(isize, isize, f32); 4] = [(-1, 0, 1.0), (-1, -1, DIAG), (0, -1, 1.0), (1, -1, DIAG)];
    let bwd: [(isize, isize, f32); 4] = [(1, 0, 1.0), (1, 1, DIAG), (0, 1, 1.0), (-1, 1, DIAG)];
    let (wi, hi) = (w as isize, h as isize);
    let mut relax = |x: usize, y: usize, nb: &[(isize, isize, f32); 4]| {
        let i = y * w + x;
        for &(dx, dy, len) in nb {
            let qx = x as isize + dx;
            let qy = y as isize + dy;
            if qx < 0 || qy < 0 || qx >= wi || qy >= hi {
                continue;
            }
            let q = (qy * wi + qx) as usize;
            let cand = dist[q] + len * 0.5 * (cost[i] + cost[q]);
            if cand < dist[i] {
                dist[i] = cand;
                flow[i] = flow[q];
            }
        }
    };
    for _ in 0..cfg.passes.max(1) {
        for y in 0..h {
            for x in 0..w {
                relax(x, y, &fwd);
            }
        }
        for y in (0..h).rev() {
            for x in (0..w).rev() {
                relax(x, y, &bwd);
            }
        }
    }
    dist
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_does_not_cross_a_strong_edge() {
        // left half flow (1,0), right half flow (5,0); a hole straddling the edge at x = 5
        let (w, h) = (10, 5);
        let mut flow: Vec<[f32; 2]> = (0..w * h)
            .map(|i| if i % w < 5 { [1.0, 0.0] } else { [5.0, 0.0] })
            .collect();
        let mut keep = vec![true; w * h];
        for y in 0..h {
            for x in 3..7 {
                keep[y * w + x] = false;
                flow[y * w + x] = [0.0, 0.0];
            }
        }
        let grad: Vec<f32> = (0..w * h)
            .map(|i| if i % w == 4 || i % w == 5 { 100.0 } else { 0.0 })
            .collect();
        geodesic_fill(
            &mut flow,
            &keep,
            &grad,
            w,
            h,
            &InterpolationConfig::default(),
        );
        assert_eq!(flow[2 * w + 3], [1.0, 0.0]);
        assert_eq!(flow[2 * w + 6], [5.0, 0.0]);
    }
}
