//! Multi-view geometry of visnav (Ng, Li, Kim 2021, §4–5).
//!
//! * [`correspondence`]: a pixel match `p1_px ↔ p2_px` with the information matrix (1/px²) of the
//!   second pixel — the error of dense flow lives in the second image only.
//! * [`fundamental`]: Hartley-normalised eight-point, Sampson-weighted (eq. 7–8) and
//!   Mahalanobis-weighted (eq. 9–12) iteratively re-weighted eight-point, rank-2 enforcement.
//! * [`ransac`](mod@ransac): one generic RANSAC over a small [`ransac::RansacProblem`] trait, with
//!   certainty-weighted multinomial sampling, adaptive iteration count and an injected seeded RNG;
//!   [`fundamental::FundamentalProblem`] is the uncertainty-guided RANSAC for `F`.
//! * [`essential`]: `E = Kᵀ F K`, the four `(R, t)` candidates, cheirality by triangulation.
//! * [`triangulation`]: depth along the first ray with a first-order depth variance from the
//!   flow's information matrix.
//! * [`pnp`]: P3P (a Lambda-Twist-style solver), PnP RANSAC and Gauss–Newton refinement on SE(3).
//! * [`homography`]: two views of a plane: the homography's RANSAC, the model selection
//!   against `F` (ORB-SLAM's `R_H`) and the decomposition into motion and plane normal.
//! * [`plane`]: RANSAC ground-plane fit and the monocular scale `s = -(b·h)/d` (§5).
//!
//! Frames: a relative pose `cam2_from_cam1` maps points of camera 1 into camera 2
//! (`p_in_cam2 = R p_in_cam1 + t`), so `x2ᵀ E x1 = 0` with `E = [t]ₓ R`. Camera axes: x right,
//! y down, z forward. All geometry is `f64`.

pub mod correspondence;
pub mod essential;
pub mod fundamental;
pub mod homography;
pub mod plane;
pub mod pnp;
pub mod ransac;
pub mod tracks;
pub mod triangulation;

use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, DimDiff, DimSub, SMatrix, SVector, U1};

pub use correspondence::Correspondence;
pub use essential::{RelativePose, relative_pose_from_fundamental};
pub use fundamental::{EightPointConfig, Estimator, FundamentalRansacResult, estimate_fundamental};
pub use ransac::{ChaCha8Rng, RansacConfig, RansacProblem, RansacResult, ransac, seeded_rng};

/// Errors of this crate: invalid configuration. Degenerate geometry is an `Option`, not an error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A configuration field is out of its valid range.
    #[error("invalid config: {field} = {value}, expected {expected}")]
    InvalidConfig {
        /// Name of the field, e.g. `ransac.confidence`.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
}

/// Returns `InvalidConfig` unless `ok`.
pub(crate) fn check(
    ok: bool,
    field: &'static str,
    value: f64,
    expected: &'static str,
) -> Result<(), GeometryError> {
    if ok {
        Ok(())
    } else {
        Err(GeometryError::InvalidConfig {
            field,
            value,
            expected,
        })
    }
}

/// The unit eigenvector of the smallest eigenvalue of the symmetric `m` (a least-squares null
/// vector, a plane's normal); `None` only for an empty matrix.
pub(crate) fn smallest_eigenvector<const N: usize>(
    m: &SMatrix<f64, N, N>,
) -> Option<SVector<f64, N>>
where
    Const<N>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<N>, U1>>,
{
    let eig = m.clone_owned().symmetric_eigen();
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    Some(eig.eigenvectors.column(imin).into_owned())
}
