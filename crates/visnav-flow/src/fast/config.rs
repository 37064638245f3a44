//! Typed configuration of the fast flow ([`crate::fast::FastFlow`]). The search defaults follow
//! dense inverse search (Kroeger, Timofte, Dai, Van Gool, ECCV 2016) as OpenCV's DIS presets set
//! them; the uncertainty's constants were fitted on rendered pairs with exact flow
//! (`examples/fast_flow_uncertainty.rs`).

use serde::{Deserialize, Serialize};

use crate::error::FlowError;

/// Configuration of [`crate::fast::FastFlow`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FastFlowConfig {
    /// Side of a square patch, level pixels (DIS θ_ps; OpenCV's fast preset 8).
    pub patch_size: usize,
    /// Distance between neighbouring patches of the grid, level pixels (DIS θ_ps − θ_ov; 4:
    /// every pixel is covered by four patches).
    pub patch_stride: usize,
    /// Inverse-compositional Gauss–Newton iterations per patch and level (DIS θ_it: 12 in
    /// OpenCV's ultrafast preset, 16 in its fast and medium ones).
    pub iterations: usize,
    /// A patch stops iterating when its step is shorter than this, level pixels.
    pub min_step_px: f32,
    /// Finest pyramid level the patches are aligned on (0: full resolution, 1: half). Below
    /// it the flow is upsampled and refined by the variational pass alone.
    pub finest_level: usize,
    /// The coarsest level is the deepest whose width still holds this many patches (OpenCV:
    /// about 4 patches across the coarsest image).
    pub coarsest_patches_across: usize,
    /// Subtract each patch's mean brightness difference (DIS's mean normalisation: robust to a
    /// change of exposure between the frames).
    pub mean_normalisation: bool,
    /// Halfway through the iterations each patch takes the flow of a grid neighbour when that
    /// fits its template better (DIS's spatial propagation, done in parallel over the grid).
    pub propagation: bool,
    /// The propagation tries a neighbour's flow only when it differs from the best so far by
    /// at least this (L1), level pixels.
    pub propagation_min_px: f32,
    /// Tikhonov damping of each patch's 2x2 Hessian, intensity² per pixel of the patch (keeps
    /// a flat patch from taking a step it has no texture for).
    pub damping: f32,
    /// Variational refinement (Brox et al. 2004, as DIS) after each patch level: outer
    /// (re-warping) iterations; 0 switches it off.
    pub variational_outer: usize,
    /// Outer iterations of the variational refinement at the finest patch level, where one
    /// costs about three at the coarser levels together (a number, not an option: a preset's
    /// value must survive its round trip through a TOML configuration file).
    pub finest_variational_outer: usize,
    /// Red-black Gauss–Seidel sweeps per outer iteration.
    pub variational_inner: usize,
    /// Smoothness weight of the variational refinement, intensity levels per pixel of flow
    /// change.
    pub variational_alpha: f32,
    /// Outer iterations of the variational refinement at each level finer than
    /// `finest_level` (the upsampled flow refined without patches).
    pub upsampled_outer: usize,
    /// Per-pixel uncertainty.
    pub uncertainty: FastUncertaintyConfig,
}

impl Default for FastFlowConfig {
    fn default() -> Self {
        Self {
            patch_size: 12,
            patch_stride: 6,
            iterations: 4,
            min_step_px: 0.01,
            finest_level: 0,
            coarsest_patches_across: 4,
            mean_normalisation: true,
            propagation: true,
            propagation_min_px: 0.5,
            damping: 0.5,
            variational_outer: 1,
            finest_variational_outer: 0,
            variational_inner: 10,
            variational_alpha: 10.0,
            upsampled_outer: 2,
            uncertainty: FastUncertaintyConfig::default(),
        }
    }
}

/// The fast flow's uncertainty: each patch's Gauss–Newton information (its Hessian over its
/// residual variance), densified as a Gaussian mixture, then calibrated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FastUncertaintyConfig {
    /// Smallest residual variance a patch is credited with, intensity² (image noise and
    /// quantisation: a patch that matches to the last grey level is not infinitely certain).
    pub noise_floor: f32,
    /// Multiplies the densified covariance (the global calibration, as
    /// [`crate::UncertaintyConfig::calibration`] for the paper's fit).
    pub calibration: f32,
    /// Weight of the spread of the patches' flows at a pixel (the mixture's second moment:
    /// high at motion boundaries, where overlapping patches disagree).
    pub spread_weight: f32,
    /// Weight of the squared distance the variational refinement moved the patches' flow
    /// (high where the refinement, not the patches, decided).
    pub refinement_weight: f32,
    /// Variance added to every pixel, px² (the floor of the calibrated covariance).
    pub floor_px2: f32,
    /// Eigenvalue range of the information matrix, 1/px² (positive definite, as in the paper's
    /// §3.2 clamp).
    pub min_information: f32,
    /// See `min_information`.
    pub max_information: f32,
}

impl Default for FastUncertaintyConfig {
    fn default() -> Self {
        Self {
            noise_floor: 1.0,
            calibration: 0.33,
            spread_weight: 1.0,
            refinement_weight: 1.0,
            floor_px2: 0.0025,
            min_information: 1e-3,
            max_information: 400.0,
        }
    }
}

impl FastFlowConfig {
    /// The settings of the real-time monocular preset: 16 Gauss–Newton iterations a patch and two
    /// re-warpings of the variational refinement at every level, the finest included. Their flow
    /// is less accurate than the defaults' (EPE 0.594 / 0.642 px on KITTI 2012 / Middlebury
    /// against 0.552 / 0.594) and costs 1.7x their instructions, but it ranks its pixels better
    /// (AUSE/EPE 0.211 / 0.139 against 0.271 / 0.169), and the odometry takes its
    /// correspondences by certainty: on the KITTI 00 clip t_err 1.23 % / r_err 0.87 deg/100 m,
    /// where the defaults give 1.59 % / 0.93 (docs/benchmarks.md).
    #[must_use]
    pub fn realtime() -> Self {
        Self {
            iterations: 16,
            variational_outer: 2,
            finest_variational_outer: 2,
            variational_inner: 5,
            uncertainty: FastUncertaintyConfig {
                calibration: 0.33,
                ..FastUncertaintyConfig::default()
            },
            ..Self::default()
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`FlowError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), FlowError> {
        fn bad(
            field: &'static str,
            value: impl std::fmt::Display,
            expected: &'static str,
        ) -> Result<(), FlowError> {
            Err(FlowError::InvalidConfig {
                field,
                value: value.to_string(),
                expected,
            })
        }
        let u = &self.uncertainty;
        if !(4..=32).contains(&self.patch_size) {
            return bad("fast.patch_size", self.patch_size, "in 4..=32");
        }
        if self.patch_stride == 0 || self.patch_stride > self.patch_size {
            return bad("fast.patch_stride", self.patch_stride, "in 1..=patch_size");
        }
        if self.iterations == 0 || self.iterations > 200 {
            return bad("fast.iterations", self.iterations, "in 1..=200");
        }
        if !(self.min_step_px >= 0.0 && self.min_step_px.is_finite()) {
            return bad("fast.min_step_px", self.min_step_px, "finite and >= 0");
        }
        if self.finest_level > 4 {
            return bad("fast.finest_level", self.finest_level, "at most 4");
        }
        if self.coarsest_patches_across == 0 {
            return bad(
                "fast.coarsest_patches_across",
                self.coarsest_patches_across,
                "at least 1",
            );
        }
        if !(self.propagation_min_px >= 0.0 && self.propagation_min_px.is_finite()) {
            return bad(
                "fast.propagation_min_px",
                self.propagation_min_px,
                "finite and >= 0",
            );
        }
        if !(self.damping >= 0.0 && self.damping.is_finite()) {
            return bad("fast.damping", self.damping, "finite and >= 0");
        }
        let finest_outer = self.finest_variational_outer;
        if self.variational_inner == 0
            && (self.variational_outer > 0 || self.upsampled_outer > 0 || finest_outer > 0)
        {
            return bad(
                "fast.variational_inner",
                self.variational_inner,
                "at least 1 when a variational pass runs",
            );
        }
        let most_outer = self
            .variational_outer
            .max(self.upsampled_outer)
            .max(finest_outer);
        if most_outer > 50 {
            return bad(
                "fast.variational_outer / finest_variational_outer / upsampled_outer",
                most_outer,
                "at most 50",
            );
        }
        if !(self.variational_alpha > 0.0 && self.variational_alpha.is_finite()) {
            return bad(
                "fast.variational_alpha",
                self.variational_alpha,
                "finite and > 0",
            );
        }
        let non_negative = [
            ("fast.uncertainty.noise_floor", u.noise_floor),
            ("fast.uncertainty.spread_weight", u.spread_weight),
            ("fast.uncertainty.refinement_weight", u.refinement_weight),
            ("fast.uncertainty.floor_px2", u.floor_px2),
        ];
        for (field, v) in non_negative {
            if !(v >= 0.0 && v.is_finite()) {
                return bad(field, v, "finite and >= 0");
            }
        }
        if !(u.calibration > 0.0 && u.calibration.is_finite()) {
            return bad(
                "fast.uncertainty.calibration",
                u.calibration,
                "finite and > 0",
            );
        }
        if !(u.min_information > 0.0
            && u.max_information > u.min_information
            && u.max_information.is_finite())
        {
            return bad(
                "fast.uncertainty.min_information / max_information",
                format!("{} / {}", u.min_information, u.max_information),
                "0 < min_information < max_information",
            );
        }
        Ok(())
    }
}
