//! The Gauss–Newton normal equations of a window, with the points eliminated by the Schur
//! complement (module doc of [`super`]).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Matrix6x3, Vector3, Vector6};

use super::problem::{BaConfig, WindowBa, huber_weight};
use super::residual::StereoResidual;

/// A step of the free poses (`ξ`, in window order after the fixed frames), of all points and
/// of the rig's right principal-point offset (0 unless it is estimated).
#[derive(Debug, Clone)]
pub(super) struct Step {
    pub(super) poses: Vec<Vector6<f64>>,
    pub(super) points: Vec<Vector3<f64>>,
    pub(super) offset_px: f64,
}

/// The blocks of the rig's offset `ε` when it is estimated: `H_εε`, `b_ε`, `H_ξε` of each free
/// pose (stacked) and `H_Xε` of each point.
struct OffsetBlocks {
    h_gg: f64,
    b_g: f64,
    h_pg: DVector<f64>,
    h_lg: Vec<Vector3<f64>>,
}

/// `H δ = b` (`b = −Jᵀ W r`) in blocks: poses × poses dense, points 3x3 block-diagonal, and the
/// pose–point blocks of each observation.
pub(super) struct NormalEquations {
    free: usize,
    h_pp: DMatrix<f64>,
    b_p: DVector<f64>,
    h_ll: Vec<Matrix3<f64>>,
    b_l: Vec<Vector3<f64>>,
    /// Per point: `(free frame, H_pl block)` of its observations in free frames.
    h_pl: Vec<Vec<(usize, Matrix6x3<f64>)>>,
    offset: Option<OffsetBlocks>,
}

impl NormalEquations {
    /// Linearises every active observation at the current estimate, IRLS-weighted by Huber's kernel.
    pub(super) fn build(ba: &WindowBa, config: &BaConfig, active: &[bool]) -> Self {
        let fixed = config.fixed_frames;
        let free = ba.cam_from_world.len() - fixed;
        let n_points = ba.points_w.len();
        let mut eq = Self {
            free,
            h_pp: DMatrix::zeros(6 * free, 6 * free),
            b_p: DVector::zeros(6 * free),
            h_ll: vec![Matrix3::zeros(); n_points],
            b_l: vec![Vector3::zeros(); n_points],
            h_pl: vec![Vec::new(); n_points],
            offset: config.estimate_right_cx_offset.then(|| OffsetBlocks {
                h_gg: 0.0,
                b_g: 0.0,
                h_pg: DVector::zeros(6 * free),
                h_lg: vec![Vector3::zeros(); n_points],
            }),
        };
        for (o, _) in ba.observations.iter().zip(active).filter(|(_, a)| **a) {
            let res = StereoResidual::new(&ba.rig, o);
            let Some(lin) = res.linearise(&ba.cam_from_world[o.frame], &ba.points_w[o.point])
            else {
                continue;
            };
            let w = huber_weight(lin.r.norm_squared(), config.huber_px);
            let j = o.point;
            eq.h_ll[j] += w * lin.d_point.transpose() * lin.d_point;
            eq.b_l[j] -= w * lin.d_point.transpose() * lin.r;
            if let Some(g) = &mut eq.offset {
                g.h_gg += w * lin.d_offset.norm_squared();
                g.b_g -= w * lin.d_offset.dot(&lin.r);
                g.h_lg[j] += w * lin.d_point.transpose() * lin.d_offset;
                if o.frame >= fixed {
                    let mut h = g.h_pg.fixed_rows_mut::<6>(6 * (o.frame - fixed));
                    h += w * lin.d_pose.transpose() * lin.d_offset;
                }
            }
            if o.frame < fixed {
                continue;
            }
            let k = o.frame - fixed;
            let jp_t = lin.d_pose.transpose();
            let block: Matrix6<f64> = w * jp_t * lin.d_pose;
            let mut view = eq.h_pp.fixed_view_mut::<6, 6>(6 * k, 6 * k);
            view += block;
            let mut b = eq.b_p.fixed_rows_mut::<6>(6 * k);
            b -= w * jp_t * lin.r;
            eq.h_pl[j].push((k, w * jp_t * lin.d_point));
        }
        eq
    }

    /// Solves the damped system (`H_ii ← H_ii·(1 + λ)`, Marquardt) by eliminating the points;
    /// `None` when the reduced camera system is not positive definite.
    pub(super) fn solve(&self, lambda: f64) -> Option<Step> {
        let damp3 = |m: &Matrix3<f64>| {
            let mut d = *m;
            for i in 0..3 {
                d[(i, i)] = d[(i, i)] * (1.0 + lambda) + 1e-12;
            }
            d
        };
        let (mut s, mut rhs) = self.reduced_start(lambda);
        let g = 6 * self.free; // the offset's row, when estimated
        let mut h_ll_inv = Vec::with_capacity(self.h_ll.len());
        for (j, h) in self.h_ll.iter().enumerate() {
            // a point no observation constrains stays where it is
            let inv = damp3(h).try_inverse().unwrap_or_else(Matrix3::zeros);
            for &(ka, wa) in &self.h_pl[j] {
                let wa_inv = wa * inv;
                let mut r = rhs.fixed_rows_mut::<6>(6 * ka);
                r -= wa_inv * self.b_l[j];
                // the Cholesky factorisation reads the lower triangle only: blocks with
                // kb > ka are never read, so they are not formed
                for &(kb, wb) in self.h_pl[j].iter().filter(|(kb, _)| *kb <= ka) {
                    subtract_outer(&mut s, (6 * ka, 6 * kb), &wa_inv, &wb);
                }
            }
            if let Some(o) = &self.offset {
                // the offset's row (last, so below every pose: the lower triangle)
                let lg_inv = inv * o.h_lg[j];
                rhs[g] -= lg_inv.dot(&self.b_l[j]);
                s[(g, g)] -= lg_inv.dot(&o.h_lg[j]);
                for &(ka, wa) in &self.h_pl[j] {
                    let coupling = wa * lg_inv;
                    for r in 0..6 {
                        s[(g, 6 * ka + r)] -= coupling[r];
                    }
                }
            }
            h_ll_inv.push(inv);
        }
        let delta_p = s.cholesky()?.solve(&rhs);
        let poses: Vec<Vector6<f64>> = (0..self.free)
            .map(|k| delta_p.fixed_rows::<6>(6 * k).into_owned())
            .collect();
        let offset_px = if self.offset.is_some() {
            delta_p[g]
        } else {
            0.0
        };
        let points = (0..self.h_ll.len())
            .map(|j| {
                let mut b = self.b_l[j];
                for &(k, w) in &self.h_pl[j] {
                    b -= w.transpose() * poses[k];
                }
                if let Some(o) = &self.offset {
                    b -= o.h_lg[j] * offset_px;
                }
                h_ll_inv[j] * b
            })
            .collect();
        (poses.iter().all(|p| p.iter().all(|v| v.is_finite())) && offset_px.is_finite()).then_some(
            Step {
                poses,
                points,
                offset_px,
            },
        )
    }

    /// The undamped reduced camera system `S = H_pp − Σ_j H_pj H_jj⁻¹ H_jp` (both triangles;
    /// the offset's row and column last, when estimated): the information of the free poses
    /// with the points marginalised ([`super::covariance`]). A point whose 3x3 block is singular
    /// (unconstrained) adds nothing.
    pub(super) fn reduced_information(&self) -> DMatrix<f64> {
        let n = self.h_pp.nrows();
        let size = n + usize::from(self.offset.is_some());
        let mut s = DMatrix::zeros(size, size);
        s.view_mut((0, 0), (n, n)).copy_from(&self.h_pp);
        if let Some(o) = &self.offset {
            for i in 0..n {
                s[(n, i)] = o.h_pg[i];
                s[(i, n)] = o.h_pg[i];
            }
            s[(n, n)] = o.h_gg;
        }
        for (j, h) in self.h_ll.iter().enumerate() {
            let Some(inv) = h.try_inverse() else {
                continue;
            };
            for &(ka, wa) in &self.h_pl[j] {
                let wa_inv = wa * inv;
                for &(kb, wb) in &self.h_pl[j] {
                    let mut block = s.fixed_view_mut::<6, 6>(6 * ka, 6 * kb);
                    block -= wa_inv * wb.transpose();
                }
                if let Some(o) = &self.offset {
                    let coupling = wa_inv * o.h_lg[j];
                    for r in 0..6 {
                        s[(6 * ka + r, n)] -= coupling[r];
                        s[(n, 6 * ka + r)] -= coupling[r];
                    }
                }
            }
            if let Some(o) = &self.offset {
                s[(n, n)] -= o.h_lg[j].dot(&(inv * o.h_lg[j]));
            }
        }
        s
    }

    /// The damped pose block (and the offset's row and column, when estimated) and its
    /// right-hand side, before the points are eliminated.
    fn reduced_start(&self, lambda: f64) -> (DMatrix<f64>, DVector<f64>) {
        let n = self.h_pp.nrows();
        let size = n + usize::from(self.offset.is_some());
        let mut s = DMatrix::zeros(size, size);
        s.view_mut((0, 0), (n, n)).copy_from(&self.h_pp);
        let mut rhs = DVector::zeros(size);
        rhs.rows_mut(0, n).copy_from(&self.b_p);
        if let Some(o) = &self.offset {
            for i in 0..n {
                s[(n, i)] = o.h_pg[i];
                s[(i, n)] = o.h_pg[i];
            }
            s[(n, n)] = o.h_gg;
            rhs[n] = o.b_g;
        }
        for i in 0..size {
            s[(i, i)] = s[(i, i)] * (1.0 + lambda) + 1e-12;
        }
        (s, rhs)
    }
}

/// `s[r0.., c0..] −= a bᵀ` for the 6x6 block at `(r0, c0)` (`a`, `b` 6x3), each entry summed
/// over the three columns in order, as nalgebra's product `a * b.transpose()` sums it (the same
/// bits, without the transposed copy and the product's temporary).
fn subtract_outer(
    s: &mut DMatrix<f64>,
    (r0, c0): (usize, usize),
    a: &Matrix6x3<f64>,
    b: &Matrix6x3<f64>,
) {
    let rows = s.nrows();
    let data = s.as_mut_slice();
    for c in 0..6 {
        let column = &mut data[(c0 + c) * rows + r0..(c0 + c) * rows + r0 + 6];
        let (b0, b1, b2) = (b[(c, 0)], b[(c, 1)], b[(c, 2)]);
        for (r, v) in column.iter_mut().enumerate() {
            *v -= a[(r, 0)] * b0 + a[(r, 1)] * b1 + a[(r, 2)] * b2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subtract_outer_is_the_product_bit_for_bit() {
        let a = Matrix6x3::from_fn(|r, c| ((r * 7 + c * 3) % 11) as f64 * 0.137 - 0.61);
        let b = Matrix6x3::from_fn(|r, c| ((r * 5 + c * 13) % 17) as f64 * 0.093 + 0.2);
        let mut s = DMatrix::from_fn(18, 18, |r, c| (r * 18 + c) as f64 * 0.01);
        let mut expected = s.clone();
        let mut block = expected.fixed_view_mut::<6, 6>(12, 6);
        block -= a * b.transpose();
        subtract_outer(&mut s, (12, 6), &a, &b);
        for (x, y) in s.iter().zip(expected.iter()) {
            assert_eq!(x.to_bits(), y.to_bits());
        }
    }
}
