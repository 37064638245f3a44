//! A block-sparse symmetric positive-definite system `H x = b` with `B x B` blocks, solved by
//! `faer`'s sparse Cholesky (`LLᵀ`, AMD ordering). The sparsity pattern (upper triangle, compressed
//! sparse columns) and the symbolic factorisation are computed once; every numeric
//! factorisation reuses them, and the factor's values and the scratch memory too (allocating
//! them afresh for every factorisation had the kernel zero pages for ≈ 15 % of sphere2500's time).

use std::collections::HashMap;

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::SMatrix;

use crate::error::GraphError;

/// The factorisation's parallelism: one thread. The supernodes of pose graphs are small, so
/// faer's parallel dense kernels spend more on handing work between threads than they save:
/// sphere2500 (15,000 unknowns) 0.33 s wall with rayon against 0.24 s on one thread,
/// parking-garage the same (`docs/notes/2026-12-02-realtime-history.md`, #24 step 10).
const PAR: Par = Par::Seq;

/// Where the entries of one block live in the value array: for each column `k` of the block, the
/// index of its first stored row.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BlockSlot<const B: usize> {
    /// First stored value of each block column.
    starts: [usize; B],
    /// Diagonal block (only its upper triangle is stored).
    diagonal: bool,
}

/// The block-sparse normal equations.
pub(crate) struct BlockSystem<const B: usize> {
    n_blocks: usize,
    pattern: SymbolicSparseColMat<usize>,
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    /// The numeric factor's values (`symbolic.len_val()`), overwritten by every factorisation.
    factor: Vec<f64>,
    /// Scratch memory of the factorisation and the solve, sized once.
    scratch: MemBuffer,
    diagonal_slots: Vec<BlockSlot<B>>,
    pair_slots: HashMap<(usize, usize), BlockSlot<B>>,
    /// Positions of the scalar diagonal entries.
    diagonal_positions: Vec<usize>,
}

impl<const B: usize> std::fmt::Debug for BlockSystem<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlockSystem")
            .field("n_blocks", &self.n_blocks)
            .field("stored_values", &self.values.len())
            .field("factor_values", &self.factor.len())
            .finish_non_exhaustive()
    }
}

impl<const B: usize> BlockSystem<B> {
    /// The pattern of `n_blocks` diagonal blocks plus the listed off-diagonal block pairs
    /// (either order; duplicates allowed).
    pub(crate) fn new(n_blocks: usize, pairs: &[(usize, usize)]) -> Result<Self, GraphError> {
        let mut rows_of_col: Vec<Vec<usize>> = (0..n_blocks).map(|b| vec![b]).collect();
        for &(a, b) in pairs {
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            if lo != hi {
                rows_of_col[hi].push(lo);
            }
        }
        let n = n_blocks * B;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut diagonal_slots = Vec::with_capacity(n_blocks);
        let mut pair_slots = HashMap::new();
        let mut diagonal_positions = vec![0; n];
        col_ptr.push(0);
        for (bj, rows) in rows_of_col.iter_mut().enumerate() {
            rows.sort_unstable();
            rows.dedup();
            let mut starts: Vec<[usize; B]> = vec![[0; B]; rows.len()];
            for k in 0..B {
                for (slot, &bi) in rows.iter().enumerate() {
                    starts[slot][k] = row_idx.len();
                    let count = if bi == bj { k + 1 } else { B };
                    row_idx.extend((0..count).map(|r| bi * B + r));
                    if bi == bj {
                        diagonal_positions[bj * B + k] = row_idx.len() - 1;
                    }
                }
                col_ptr.push(row_idx.len());
            }
            for (slot, &bi) in rows.iter().enumerate() {
                let s = BlockSlot {
                    starts: starts[slot],
                    diagonal: bi == bj,
                };
                if bi == bj {
                    diagonal_slots.push(s);
                } else {
                    pair_slots.insert((bi, bj), s);
                }
            }
        }
        let nnz = row_idx.len();
        let pattern = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic = factorize_symbolic_cholesky(
            pattern.as_ref(),
            Side::Upper,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| GraphError::Factorisation {
            stage: "symbolic",
            message: format!("{e:?}"),
        })?;
        let scratch = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(PAR, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(B, PAR),
        ]);
        let scratch = MemBuffer::try_new(scratch).map_err(|e| GraphError::Factorisation {
            stage: "symbolic",
            message: format!("scratch memory: {e:?}"),
        })?;
        Ok(Self {
            n_blocks,
            pattern,
            factor: vec![0.0; symbolic.len_val()],
            symbolic,
            values: vec![0.0; nnz],
            scratch,
            diagonal_slots,
            pair_slots,
            diagonal_positions,
        })
    }

    /// Number of block rows.
    pub(crate) fn n_blocks(&self) -> usize {
        self.n_blocks
    }

    /// Sets every entry to zero.
    pub(crate) fn clear(&mut self) {
        self.values.fill(0.0);
    }

    /// The slot of block `(a, b)`; `None` for a pair not in the pattern.
    pub(crate) fn slot(&self, a: usize, b: usize) -> Option<BlockSlot<B>> {
        if a == b {
            self.diagonal_slots.get(a).copied()
        } else {
            self.pair_slots.get(&(a.min(b), a.max(b))).copied()
        }
    }

    /// Adds `m` to block `(a, b)` of `H` (and implicitly `mᵀ` to block `(b, a)`); `slot` must be
    /// `self.slot(a, b)`.
    pub(crate) fn add(&mut self, slot: BlockSlot<B>, a: usize, b: usize, m: &SMatrix<f64, B, B>) {
        if slot.diagonal {
            for k in 0..B {
                let s = slot.starts[k];
                for r in 0..=k {
                    self.values[s + r] += m[(r, k)];
                }
            }
        } else if a < b {
            for k in 0..B {
                let s = slot.starts[k];
                for r in 0..B {
                    self.values[s + r] += m[(r, k)];
                }
            }
        } else {
            for k in 0..B {
                let s = slot.starts[k];
                for r in 0..B {
                    self.values[s + r] += m[(k, r)];
                }
            }
        }
    }

    /// The scalar diagonal of `H`.
    pub(crate) fn diagonal(&self) -> Vec<f64> {
        self.diagonal_positions
            .iter()
            .map(|&p| self.values[p])
            .collect()
    }

    /// Adds `d[k]` to the `k`-th scalar diagonal entry.
    pub(crate) fn add_to_diagonal(&mut self, d: &[f64]) {
        for (&p, v) in self.diagonal_positions.iter().zip(d) {
            self.values[p] += v;
        }
    }

    /// Solves `H x = rhs` in place for the `ncols` right-hand sides stored column-major in `rhs`.
    pub(crate) fn solve_in_place(
        &mut self,
        rhs: &mut [f64],
        ncols: usize,
        stage: &'static str,
    ) -> Result<(), GraphError> {
        if ncols > B {
            return Err(GraphError::Factorisation {
                stage,
                message: format!("{ncols} right-hand sides, scratch memory for {B}"),
            });
        }
        self.factorise_numeric()
            .map_err(|message| GraphError::Factorisation { stage, message })?;
        self.solve_with_factor(rhs, ncols);
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(GraphError::Factorisation {
                stage,
                message: "non-finite solution".into(),
            })
        }
    }

    /// Factorises `H = LLᵀ` and keeps the factor for [`Self::solve_factored`]; `false` when
    /// `H` is not positive definite (a pivot not positive, or not finite).
    pub(crate) fn factorise(&mut self) -> bool {
        self.factorise_numeric().is_ok() && self.factor.iter().all(|v| v.is_finite())
    }

    /// The numeric LLᵀ factorisation of the stored values into `factor`, the solver's error
    /// as text when a pivot is not positive.
    fn factorise_numeric(&mut self) -> Result<(), String> {
        let matrix = SparseColMatRef::new(self.pattern.as_ref(), &self.values);
        self.symbolic
            .factorize_numeric_llt(
                &mut self.factor,
                matrix,
                Side::Upper,
                Default::default(),
                PAR,
                MemStack::new(&mut self.scratch),
                Default::default(),
            )
            .map(|_| ())
            .map_err(|e| format!("{e:?}"))
    }

    /// Solves `H x = rhs` in place (one right-hand side) with the factor of the last successful
    /// [`Self::factorise`].
    pub(crate) fn solve_factored(&mut self, rhs: &mut [f64]) {
        self.solve_with_factor(rhs, 1);
    }

    /// Solves `H X = rhs` in place for `ncols` right-hand sides (column-major) with the factor
    /// in `factor`.
    fn solve_with_factor(&mut self, rhs: &mut [f64], ncols: usize) {
        let llt = LltRef::new(&self.symbolic, &self.factor);
        let n = self.n_blocks * B;
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, ncols),
            PAR,
            MemStack::new(&mut self.scratch),
        );
    }

    /// `y = H x` with the stored (upper-triangle) values.
    pub(crate) fn multiply(&self, x: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        let col_ptr = self.pattern.col_ptr();
        let row_idx = self.pattern.row_idx();
        for col in 0..self.n_blocks * B {
            let range = col_ptr[col]..col_ptr[col + 1];
            for (&row, &v) in row_idx[range.clone()].iter().zip(&self.values[range]) {
                y[row] += v * x[col];
                if row != col {
                    y[col] += v * x[row];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix2};
    use std::ops::AddAssign;

    #[test]
    fn matches_dense_solve() {
        // A chain of 4 blocks with a loop pair (0, 3), pairs given in both orders.
        let pairs = [(0, 1), (2, 1), (2, 3), (3, 0)];
        let mut sys = BlockSystem::<2>::new(4, &pairs).unwrap();
        let mut dense = DMatrix::<f64>::zeros(8, 8);
        for b in 0..4 {
            let m = Matrix2::new(4.0 + b as f64, 0.5, 0.5, 3.0);
            let s = sys.slot(b, b).unwrap();
            sys.add(s, b, b, &m);
            dense.view_mut((2 * b, 2 * b), (2, 2)).add_assign(&m);
        }
        for (k, &(a, b)) in pairs.iter().enumerate() {
            let m = Matrix2::new(-0.3, 0.1 * k as f64, -0.2, 0.25);
            let s = sys.slot(a, b).unwrap();
            sys.add(s, a, b, &m);
            dense.view_mut((2 * a, 2 * b), (2, 2)).add_assign(&m);
            dense
                .view_mut((2 * b, 2 * a), (2, 2))
                .add_assign(&m.transpose());
        }
        let rhs = DVector::from_fn(8, |i, _| (i as f64).sin());
        let expected = dense.clone().cholesky().unwrap().solve(&rhs);
        let mut x: Vec<f64> = rhs.iter().copied().collect();
        sys.solve_in_place(&mut x, 1, "test").unwrap();
        for i in 0..8 {
            assert!((x[i] - expected[i]).abs() < 1e-12);
        }
        let diag = sys.diagonal();
        for i in 0..8 {
            assert!((diag[i] - dense[(i, i)]).abs() < 1e-15);
        }
        assert!(sys.slot(0, 2).is_none());

        // the factor's values and the scratch are reused: a second factorisation after a change
        // of the values solves the new system, with two right-hand sides at once
        let shift = [1.5; 8];
        sys.add_to_diagonal(&shift);
        for i in 0..8 {
            dense[(i, i)] += 1.5;
        }
        let rhs2 = DMatrix::from_fn(8, 2, |i, j| (i as f64 + 3.0 * j as f64).cos());
        let expected2 = dense.cholesky().unwrap().solve(&rhs2);
        let mut x2: Vec<f64> = rhs2.iter().copied().collect();
        sys.solve_in_place(&mut x2, 2, "test").unwrap();
        for (got, want) in x2.iter().zip(expected2.iter()) {
            assert!((got - want).abs() < 1e-12);
        }
        // more right-hand sides than the scratch was sized for: an error, not a panic
        let mut x3 = vec![0.0; 8 * 3];
        assert!(sys.solve_in_place(&mut x3, 3, "test").is_err());
    }
}
