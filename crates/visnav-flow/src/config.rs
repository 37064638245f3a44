//! Typed configuration of the flow stage. Defaults follow DCFlow (Xu, Ranftl, Koltun 2017) and
//! Ng, Li, Kim 2021 §3 where they apply; the rest were chosen by measured EPE
//! (docs/notes/2026-12-02-flow-history.md and the lab notebook it names).

use serde::{Deserialize, Serialize};

use crate::error::FlowError;

/// How the displacement window of the cost volume is placed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SearchMode {
    /// Coarse-to-fine (default): a full window of `radius` labels at the coarsest level of a
    /// pyramid of the 1/3-resolution image, then at each finer level a window of `radius` labels
    /// centred on the upsampled flow of the coarser level (or on a caller's prior).
    CoarseToFine,
    /// DCFlow reference: one full window of `reference_radius` labels at 1/3 resolution
    /// ((2R+1)² labels per pixel, ±80 px at 1/3 resolution by default).
    Reference,
}

/// Configuration of [`crate::FlowEstimator`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowConfig {
    /// Downsampling factor of the matching resolution (DCFlow: 3).
    pub scale: usize,
    /// Window placement.
    pub mode: SearchMode,
    /// Half-width of the label window per level in coarse-to-fine mode, in level pixels.
    pub radius: usize,
    /// Extra pyramid levels (factor 2 each) below the 1/3 resolution in coarse-to-fine mode.
    pub levels: usize,
    /// Half-width of the window in reference mode, in 1/3-resolution pixels (DCFlow KITTI: 80).
    pub reference_radius: usize,
    /// Semi-global matching penalties.
    pub sgm: SgmConfig,
    /// Cost of a label whose target leaves the image (u8 cost units; 127 = orthogonal features).
    pub outside_cost: u8,
    /// Half-label cost at the matching resolution: each label costs the lowest over the
    /// half-label points around it (Birchfield–Tomasi's sampling-insensitive dissimilarity in
    /// 2-D; see [`crate::volume::cost_volume`]). It keeps a texture that repeats every few
    /// pixels from locking onto the neighbouring period and lowers the EPE on every real set
    /// measured, but it is off by default: with it the uncertainty model (refitted) puts
    /// Middlebury's 1-sigma share just outside the range and the monocular odometry
    /// drifts more (docs/notes/2026-12-02-flow-history.md, `6a6598e`; round 9 of
    /// `git show 0a7500f:docs/benchmarks.md`). About 35 ms more a KITTI pair.
    pub half_label_cost: bool,
    /// What a half-label point gives up against a label, in cost units (127 = orthogonal
    /// descriptors): a label wins a tie, so the slice keeps some curvature where the
    /// descriptors match equally well. 2 by default (0 to 6 measured).
    pub half_label_penalty: f32,
    /// Forward–backward consistency threshold in 1/3-resolution pixels (DCFlow: 0.8).
    pub fb_threshold_px: f32,
    /// Edge-aware interpolation.
    pub interpolation: InterpolationConfig,
    /// Full-resolution refinement.
    pub refinement: RefinementConfig,
    /// Uncertainty fit (eq. 1–4) and calibration.
    pub uncertainty: UncertaintyConfig,
    /// Epipolar cost (§3.1).
    pub epipolar: EpipolarConfig,
}

impl Default for FlowConfig {
    fn default() -> Self {
        Self {
            scale: 3,
            mode: SearchMode::CoarseToFine,
            radius: 4,
            levels: 2,
            reference_radius: 80,
            sgm: SgmConfig::default(),
            outside_cost: 100,
            half_label_cost: false,
            half_label_penalty: 2.0,
            fb_threshold_px: 0.8,
            interpolation: InterpolationConfig::default(),
            refinement: RefinementConfig::default(),
            uncertainty: UncertaintyConfig::default(),
            epipolar: EpipolarConfig::default(),
        }
    }
}

impl FlowConfig {
    /// The default flow with the paper's uncertainty alone
    /// ([`UncertaintyConfig::cost_slice_fit`]) and the odometry's refinement
    /// ([`RefinementConfig::odometry`]): the configuration of the monocular odometry and its
    /// loop closure.
    #[must_use]
    pub fn odometry() -> Self {
        Self {
            uncertainty: UncertaintyConfig::cost_slice_fit(),
            refinement: RefinementConfig::odometry(),
            interpolation: InterpolationConfig {
                affine_neighbours: 0,
                ..InterpolationConfig::default()
            },
            ..Self::default()
        }
    }
}

/// Semi-global matching over the 2-D label space (DCFlow).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SgmConfig {
    /// Penalty for a label step of one (u8 cost units).
    pub p1: u16,
    /// Penalty for larger label steps (u8 cost units).
    pub p2: u16,
    /// `p2` is divided by this where the image gradient is strong (DCFlow: 3).
    pub p2_edge_divisor: u16,
    /// Gradient magnitude (intensity levels per level pixel) above which an edge is strong.
    pub edge_gradient: f32,
}

impl Default for SgmConfig {
    fn default() -> Self {
        Self {
            p1: 7,
            p2: 100,
            p2_edge_divisor: 3,
            edge_gradient: 12.0,
        }
    }
}

/// EpicFlow-style edge-aware interpolation of the pixels removed by the forward–backward check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InterpolationConfig {
    /// Weight of the edge map in the geodesic distance (per intensity level of gradient).
    pub edge_weight: f32,
    /// Raster passes of the geodesic distance transform (forward + backward each).
    pub passes: usize,
    /// Half-width of the median filter applied to the filled flow at each level (0: none).
    pub median_radius: usize,
    /// Kept matches the locally weighted affine model of a seed is fitted to (EpicFlow's `K`;
    /// 0: a removed pixel copies its seed's flow).
    pub affine_neighbours: usize,
    /// Half-width of the window those matches are searched in, level px.
    pub affine_radius: usize,
    /// Scale `τ` of the weights `exp(-D_G / τ)` of the affine fit, geodesic level px.
    pub affine_distance_scale: f32,
}

impl Default for InterpolationConfig {
    fn default() -> Self {
        Self {
            edge_weight: 0.5,
            passes: 2,
            median_radius: 7,
            affine_neighbours: 50,
            affine_radius: 8,
            affine_distance_scale: 8.0,
        }
    }
}

/// Dense Lucas–Kanade refinement of the upsampled flow at full resolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefinementConfig {
    /// Gauss–Newton iterations (0 disables the refinement).
    pub iterations: usize,
    /// Half-width of the square window, pixels.
    pub window_radius: usize,
    /// Tikhonov damping of the 2x2 normal equations (intensity² per pixel).
    pub damping: f32,
    /// Largest update per iteration, pixels.
    pub max_step_px: f32,
    /// Outer (re-warping) iterations of the variational refinement (0 disables it).
    pub variational_outer: usize,
    /// Red-black Gauss–Seidel sweeps per outer iteration (of the half-resolution pass when
    /// `half_resolution_pass` is on, else of the full-resolution one).
    pub variational_inner: usize,
    /// Smoothness weight of the variational refinement (intensity levels per px of flow change);
    /// of its full-resolution pass when `half_resolution_pass` is on.
    pub variational_alpha: f32,
    /// Gradient normalisation of the variational data term (Zimmer, Bruhn, Weickert 2011,
    /// "Optic flow in harmony"; also in the refinement of DIS): the linearised brightness
    /// constraint of a pixel is weighted by `ζ² / (|∇I|² + ζ²)` with this `ζ` (intensity levels
    /// per px), so that a low-contrast region (a wall in shadow) is not smoothed over by its
    /// textured neighbours while a strong edge does not dominate its window. The normalisation
    /// scales the data term down, so α must come down with it. Of the full-resolution pass when
    /// `half_resolution_pass` is on; 0 switches it off (default: in the full-resolution pass it
    /// lowers the EPE but the uncertainty ranks the errors left less well; round 7 of
    /// `git show 0a7500f:docs/benchmarks.md`).
    pub gradient_normalisation: f32,
    /// Smoothness weight of the half-resolution pass (`half_resolution_pass`).
    pub half_resolution_alpha: f32,
    /// Gradient normalisation `ζ` of the half-resolution pass (0: off).
    pub half_resolution_normalisation: f32,
    /// Share of a local mean (box of radius `highpass_radius`) subtracted from both images
    /// before refinement, for robustness to illumination change (0: raw intensities).
    pub highpass: f32,
    /// Radius of that box, pixels.
    pub highpass_radius: usize,
    /// Run the variational refinement at half resolution (`variational_outer` warps) before
    /// full resolution (`full_resolution_outer` warps).
    pub half_resolution_pass: bool,
    /// Outer iterations at full resolution when `half_resolution_pass` is on.
    pub full_resolution_outer: usize,
    /// Gauss–Seidel sweeps per outer iteration at full resolution when `half_resolution_pass`
    /// is on (`variational_inner` applies to the half-resolution pass).
    pub full_resolution_inner: usize,
    /// Over-relaxation factor of the red-black sweeps (successive over-relaxation; 1: plain
    /// Gauss–Seidel, must lie in (0, 2) for convergence).
    pub sor_omega: f32,
}

impl Default for RefinementConfig {
    /// The `visnav flow` refinement: over-relaxed sweeps (ω 1.7), 6 warps of 5 sweeps at half
    /// resolution and 4 of 5 at full resolution. Against the plain Gauss–Seidel 12 x 10 + 12 x 10
    /// of [`RefinementConfig::odometry`] it converges further in a third of the sweeps: lower
    /// mean EPE on KITTI 2012 and Middlebury (0.552 / 0.534 px against 0.554 / 0.540) for
    /// about 35 % less time a pair (docs/notes/2026-12-02-realtime-history.md, #24 step 17).
    fn default() -> Self {
        Self {
            variational_outer: 6,
            variational_inner: 5,
            full_resolution_outer: 4,
            full_resolution_inner: 5,
            sor_omega: 1.7,
            ..Self::odometry()
        }
    }
}

impl RefinementConfig {
    /// The monocular odometry's refinement (and its loop closure's): plain Gauss–Seidel, 12
    /// warps of 10 sweeps at half resolution and 12 of 10 at full resolution. The odometry's
    /// accuracy was measured with it (KITTI 00,
    /// docs/notes/2026-12-02-realtime-history.md: fewer or over-relaxed sweeps
    /// cost rotation accuracy there), so it keeps it.
    #[must_use]
    pub fn odometry() -> Self {
        Self {
            iterations: 3,
            window_radius: 3,
            damping: 10.0,
            max_step_px: 1.0,
            variational_outer: 12,
            variational_inner: 10,
            variational_alpha: 10.0,
            gradient_normalisation: 0.0,
            half_resolution_alpha: 10.0,
            half_resolution_normalisation: 0.0,
            highpass: 0.5,
            highpass_radius: 7,
            half_resolution_pass: true,
            full_resolution_outer: 12,
            full_resolution_inner: 10,
            sor_omega: 1.0,
        }
    }
}

/// The Gaussian fit of eq. 1–4 and its global calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UncertaintyConfig {
    /// Half-width of the cost slice fitted around the winner, labels.
    pub fit_radius: usize,
    /// Only costs at most this far above the minimum enter the fit (u8 cost units, aggregated).
    pub cost_threshold: f32,
    /// Global calibration factor from aggregated cost units per label² to 1/px² of the
    /// cost-slice fit (eq. 1–4), fitted on synthetic scenes together with the weights below.
    pub calibration: f32,
    /// Weight (cost units per level px², i.e. the inverse calibration scale) of the extra
    /// variance from the winner-to-filtered-flow and forward–backward discrepancies.
    pub extra_variance_weight: f32,
    /// Variance added per squared `residual_scale` of local brightness residual after
    /// refinement, px² (0 disables it).
    pub residual_variance_px2: f32,
    /// Brightness residual (intensity levels) that adds `residual_variance_px2`.
    pub residual_scale: f32,
    /// Variance added per px² of squared forward–backward discrepancy (measured at the matching
    /// level, continuous rather than only the binary check), px² per px² (0 disables it).
    pub fb_variance_weight: f32,
    /// Variance added per px² of squared geodesic distance from an interpolated pixel to the
    /// kept match its flow was taken from (0 for kept pixels), px² per px².
    pub fill_variance_weight: f32,
    /// Variance added per px² of squared gradient-normalised brightness residual after
    /// refinement, `max(r̄ - 2 median(r̄), 0)² / (ḡ² + residual_gradient_floor²)` (7x7 means of
    /// `|I2(x + u) - I1(x)|` and of `|∇I1|²`), px² per px².
    pub normalised_residual_weight: f32,
    /// Gradient floor of that normalisation, intensity levels per px.
    pub residual_gradient_floor: f32,
    /// Variance added per px² of local flow variation (variance of the refined flow over a 5x5
    /// window beyond its local linear trend: motion boundaries), px² per px².
    pub flow_variation_weight: f32,
    /// Variance added per px² of squared flow length, px² per px².
    pub flow_magnitude_weight: f32,
    /// Variance added everywhere, px².
    pub base_variance_px2: f32,
    /// Smallest eigenvalue of the information matrix, 1/px² (the maximum uncertainty).
    pub min_information: f32,
    /// Largest eigenvalue of the information matrix, 1/px².
    pub max_information: f32,
    /// The log-linear variance model (default on).
    pub variance_model: VarianceModel,
    /// Outer iterations of the full-resolution variational pass of the *backward* flow, refined
    /// only for the model's full-resolution forward–backward predictor
    /// ([`VarianceModel::fb_full_resolution`]); fewer than the forward flow's to save time.
    pub backward_full_resolution_outer: usize,
    /// Cost scale τ of the ambiguity term `d² exp(-margin / τ)`, aggregated cost units.
    pub ambiguity_cost_scale: f32,
    /// Smoothness weight of the second, weakly regularised refinement whose distance to the
    /// flow is the model's smoothness-sensitivity predictor
    /// ([`VarianceModel::smoothness_sensitivity`]), intensity levels per px of flow change
    /// (the flow's own is [`RefinementConfig::variational_alpha`]).
    pub sensitivity_alpha: f32,
    /// Outer iterations of that refinement's full-resolution variational pass.
    pub sensitivity_full_resolution_outer: usize,
    /// Outer iterations of the half-resolution variational pass of both of the model's own
    /// refinements (the backward flow and the weakly smoothed one; their sweeps and
    /// over-relaxation are the flow's). More than the forward flow's: better converged, their predictors
    /// rank the errors better (lower AUSE on both evaluation sets,
    /// docs/notes/2026-12-02-realtime-history.md). Without
    /// the half-resolution pass the refinements take the flow's `variational_outer`.
    pub model_half_resolution_outer: usize,
}

/// Number of log-linear predictors of the variance model (its coefficients without the
/// constant, [`VarianceModel::coefficients`]; the terms are `UncertaintyTerms::log_features`).
pub const LOG_FEATURES: usize = 13;

/// The default uncertainty model: the covariance of the cost-slice fit (eq. 1–4) keeps its
/// orientation and, blended towards a circle by `shape_isotropy`, its axis ratio, and is scaled
/// to the variance
/// `v = exp(log_scale + Σ θ_k φ_k)` px² (half its trace becomes `v`), with the predictors
///
/// `φ = (ln tr Σ_fit, ln(fb + 0.1), ln(|f| + 1), ln(texture + 1), removed share,
///        ln(refinement change + 0.02), ln(variation 5x5 + 0.05), ln(variation 11x11 + 0.05),
///        ln(1 - NCC + 0.1), ln(refined forward–backward discrepancy + 0.05),
///        ln(ambiguity of a second cost minimum + 0.1),
///        ln(smoothness sensitivity + 0.05),
///        ln(mean over the image of (1 - NCC) + 0.1))`
///
/// (px, intensity levels per px; [`crate::UncertaintyTerms`]). The coefficients come from a
/// fit on synthetic pairs only (`examples/calibrate_uncertainty.rs`): a least-squares fit of
/// the log end-point error, then the shape blend and one global variance scale for the
/// 2-sigma share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VarianceModel {
    /// Whether the model replaces the fit's own scale (false: the fit alone, plus the additive
    /// terms of [`UncertaintyConfig`]).
    pub enabled: bool,
    /// Constant `c` of the log-variance (includes the global calibration).
    pub log_scale: f32,
    /// How far the covariance's shape is blended from the cost-slice fit's ellipse towards a
    /// circle of the same trace, 0..=1 ([`crate::uncertainty::model_covariance`]): the fit's
    /// axis ratio is only partly right, a full-resolution error is not confined to the
    /// direction the 1/3-resolution cost slice singles out.
    pub shape_isotropy: f32,
    /// Coefficient of `ln tr Σ_fit` (the cost-slice fit's own variance).
    pub fit_trace: f32,
    /// Coefficient of `ln(fb + 0.1)`, forward–backward discrepancy in px.
    pub fb_discrepancy: f32,
    /// Coefficient of `ln(|f| + 1)`, flow length in px.
    pub flow_magnitude: f32,
    /// Coefficient of `ln(texture + 1)`, texture in intensity levels per px.
    pub texture: f32,
    /// Coefficient of the share of pixels removed by the forward–backward check nearby.
    pub removed_share: f32,
    /// Coefficient of `ln(refinement change + 0.02)`, px.
    pub refinement_change: f32,
    /// Coefficient of `ln(flow variation 5x5 + 0.05)`, px.
    pub flow_variation: f32,
    /// Coefficient of `ln(flow variation 11x11 + 0.05)`, px.
    pub flow_variation_wide: f32,
    /// Coefficient of `ln(1 - NCC + 0.1)`.
    pub ncc_dissimilarity: f32,
    /// Coefficient of `ln(fb full + 0.05)`: the forward–backward discrepancy of the refined
    /// full-resolution flows in px. Non-zero makes the estimator refine the backward flow at
    /// full resolution too (about 0.15 s more a KITTI pair on 2 cores).
    pub fb_full_resolution: f32,
    /// Coefficient of `ln(ambiguity + 0.1)`, the variance a second minimum of the regularised
    /// cost slice stands for, px² ([`crate::UncertaintyTerms::ambiguity_px2`]).
    pub ambiguity: f32,
    /// Coefficient of `ln(sensitivity + 0.05)`: how far the flow moves, in px, when it is
    /// refined again from the matching result with a weaker smoothness term
    /// ([`UncertaintyConfig::sensitivity_alpha`]): large where the flow is what the regulariser
    /// made of weak data rather than what the images say (flat or one-directional texture,
    /// regions the smoothness term pulled along). Non-zero makes the estimator run that second
    /// refinement (about 0.14 s more a KITTI pair on 2 cores).
    pub smoothness_sensitivity: f32,
    /// Coefficient of `ln(mean(1 - NCC) + 0.1)`, the image-wide mean: one variance factor for
    /// the whole pair (how hard the pair is), fitted after the per-pixel coefficients so that it
    /// does not change the order of the pixels within a pair.
    pub image_ncc_dissimilarity: f32,
}

impl Default for VarianceModel {
    fn default() -> Self {
        // fitted on synthetic pairs by `examples/calibrate_uncertainty.rs`
        Self {
            enabled: true,
            log_scale: 4.209_9,
            shape_isotropy: 1.0,
            fit_trace: -0.006_2,
            fb_discrepancy: -0.058,
            flow_magnitude: 0.139_1,
            texture: -0.835_1,
            removed_share: 0.803_4,
            refinement_change: 0.350_8,
            flow_variation: 0.818_8,
            flow_variation_wide: 0.553_9,
            ncc_dissimilarity: 0.604_8,
            fb_full_resolution: 0.563_4,
            ambiguity: 0.132_9,
            smoothness_sensitivity: 0.414_3,
            image_ncc_dissimilarity: 0.218_5,
        }
    }
}

impl VarianceModel {
    /// The model switched off.
    #[must_use]
    pub fn off() -> Self {
        Self {
            enabled: false,
            ..Self::default()
        }
    }

    /// The coefficients `θ` in the order of [`crate::UncertaintyTerms::log_features`].
    #[must_use]
    pub fn coefficients(&self) -> [f32; LOG_FEATURES] {
        [
            self.fit_trace,
            self.fb_discrepancy,
            self.flow_magnitude,
            self.texture,
            self.removed_share,
            self.refinement_change,
            self.flow_variation,
            self.flow_variation_wide,
            self.ncc_dissimilarity,
            self.fb_full_resolution,
            self.ambiguity,
            self.smoothness_sensitivity,
            self.image_ncc_dissimilarity,
        ]
    }

    /// Sets the coefficients from `θ` in the order of [`Self::coefficients`].
    pub fn set_coefficients(&mut self, th: [f32; LOG_FEATURES]) {
        [
            self.fit_trace,
            self.fb_discrepancy,
            self.flow_magnitude,
            self.texture,
            self.removed_share,
            self.refinement_change,
            self.flow_variation,
            self.flow_variation_wide,
            self.ncc_dissimilarity,
            self.fb_full_resolution,
            self.ambiguity,
            self.smoothness_sensitivity,
            self.image_ncc_dissimilarity,
        ] = th;
    }
}

impl Default for UncertaintyConfig {
    fn default() -> Self {
        Self {
            fit_radius: 2,
            cost_threshold: 400.0,
            // the paper's calibration of the fit; with the variance model on, only the fit's
            // shape and (through `fit_trace`) part of its scale are used
            calibration: 12.4,
            extra_variance_weight: 0.0,
            residual_variance_px2: 0.0,
            residual_scale: 10.0,
            fb_variance_weight: 0.0,
            fill_variance_weight: 0.0,
            normalised_residual_weight: 0.0,
            residual_gradient_floor: 2.0,
            flow_variation_weight: 0.0,
            flow_magnitude_weight: 0.0,
            base_variance_px2: 0.0,
            min_information: 1e-3,
            max_information: 400.0,
            variance_model: VarianceModel::default(),
            backward_full_resolution_outer: 2,
            ambiguity_cost_scale: 20.0,
            sensitivity_alpha: 2.5,
            sensitivity_full_resolution_outer: 1,
            model_half_resolution_outer: 12,
        }
    }
}

impl UncertaintyConfig {
    /// The paper's uncertainty alone: the Gaussian fit to the regularised cost slice (eq. 1–4)
    /// with the global calibration fitted on synthetic scenes (12.4 cost units per label² to
    /// 1/px²), none of the additive variance terms of [`UncertaintyConfig::default`].
    ///
    /// This is what the monocular pipeline uses: the Mahalanobis eight-point algorithm (eq. 9–12)
    /// weights each correspondence by the *shape* of its information matrix, which the cost-slice
    /// fit gives and the isotropic terms of the default wash out (measured on KITTI 00, 300
    /// frames: 3.74 % / 4.79 deg/100 m with the default model against 1.36 % / 0.98 with this).
    #[must_use]
    pub fn cost_slice_fit() -> Self {
        Self {
            calibration: 12.4,
            extra_variance_weight: 0.0,
            residual_variance_px2: 0.0,
            fb_variance_weight: 0.0,
            fill_variance_weight: 0.0,
            normalised_residual_weight: 0.0,
            flow_variation_weight: 0.0,
            flow_magnitude_weight: 0.0,
            base_variance_px2: 0.0,
            variance_model: VarianceModel::off(),
            ..Self::default()
        }
    }
}

/// Truncated L2 epipolar cost (§3.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EpipolarConfig {
    /// Cost per squared pixel of distance to the epipolar line, in u8 cost units per
    /// matching-level px².
    pub weight: f32,
    /// Truncation of the epipolar cost, u8 cost units (moving objects pay at most this).
    pub truncation: f32,
}

impl Default for EpipolarConfig {
    fn default() -> Self {
        Self {
            weight: 8.0,
            truncation: 40.0,
        }
    }
}

impl FlowConfig {
    /// Checks every field's range.
    ///
    /// # Errors
    /// [`FlowError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), FlowError> {
        let bad = |field: &'static str, value: String, expected: &'static str| {
            Err(FlowError::InvalidConfig {
                field,
                value,
                expected,
            })
        };
        if !(1..=8).contains(&self.scale) {
            return bad("scale", self.scale.to_string(), "1..=8");
        }
        if !(1..=16).contains(&self.radius) {
            return bad("radius", self.radius.to_string(), "1..=16");
        }
        if self.levels > 6 {
            return bad("levels", self.levels.to_string(), "0..=6");
        }
        if !(1..=160).contains(&self.reference_radius) {
            return bad(
                "reference_radius",
                self.reference_radius.to_string(),
                "1..=160",
            );
        }
        if !(0.0..=254.0).contains(&self.half_label_penalty) {
            return bad(
                "half_label_penalty",
                self.half_label_penalty.to_string(),
                "0..=254 cost units",
            );
        }
        let ip = &self.interpolation;
        if !(ip.edge_weight >= 0.0
            && ip.affine_distance_scale > 0.0
            && ip.affine_distance_scale.is_finite()
            && (ip.affine_neighbours == 0 || (1..=64).contains(&ip.affine_radius)))
        {
            return bad(
                "interpolation",
                format!("{ip:?}"),
                "edge_weight >= 0, affine_distance_scale > 0, affine_radius 1..=64 when \
                 affine_neighbours > 0",
            );
        }
        if self.sgm.p2 < self.sgm.p1 || self.sgm.p2 > 2000 || self.sgm.p2_edge_divisor == 0 {
            return bad(
                "sgm",
                format!("{:?}", self.sgm),
                "p1 <= p2 <= 2000, p2_edge_divisor >= 1",
            );
        }
        if self.fb_threshold_px.is_nan() || self.fb_threshold_px <= 0.0 {
            return bad(
                "fb_threshold_px",
                self.fb_threshold_px.to_string(),
                "positive",
            );
        }
        if self.refinement.window_radius > 16
            || [
                self.refinement.gradient_normalisation,
                self.refinement.half_resolution_normalisation,
            ]
            .iter()
            .any(|z| z.is_nan() || *z < 0.0)
            || [
                self.refinement.variational_alpha,
                self.refinement.half_resolution_alpha,
            ]
            .iter()
            .any(|a| a.is_nan() || *a <= 0.0)
            || self.refinement.damping.is_nan()
            || self.refinement.damping < 0.0
            || !(self.refinement.sor_omega > 0.0 && self.refinement.sor_omega < 2.0)
        {
            return bad(
                "refinement",
                format!("{:?}", self.refinement),
                "window_radius <= 16, alphas > 0, gradient normalisations >= 0, damping >= 0, \
                 0 < sor_omega < 2",
            );
        }
        let u = &self.uncertainty;
        if !(u.calibration > 0.0
            && u.min_information > 0.0
            && u.max_information > u.min_information
            && u.cost_threshold > 0.0
            && u.fb_variance_weight >= 0.0
            && u.fill_variance_weight >= 0.0
            && u.normalised_residual_weight >= 0.0
            && u.residual_gradient_floor > 0.0
            && u.flow_variation_weight >= 0.0
            && u.flow_magnitude_weight >= 0.0
            && u.base_variance_px2 >= 0.0
            && u.ambiguity_cost_scale > 0.0
            && u.sensitivity_alpha > 0.0
            && u.variance_model.log_scale.is_finite()
            && (0.0..=1.0).contains(&u.variance_model.shape_isotropy)
            && u.variance_model
                .coefficients()
                .iter()
                .all(|t| t.is_finite()))
            || u.fit_radius == 0
        {
            return bad(
                "uncertainty",
                format!("{u:?}"),
                "positive calibration, gradient floor, ambiguity cost scale and sensitivity alpha, \
                 0 < min_information < max_information, \
                 non-negative variance weights, finite variance-model coefficients, shape_isotropy in 0..=1, \
                 fit_radius >= 1",
            );
        }
        if !(self.epipolar.weight >= 0.0 && self.epipolar.truncation >= 0.0) {
            return bad(
                "epipolar",
                format!("{:?}", self.epipolar),
                "non-negative weight and truncation",
            );
        }
        Ok(())
    }
}
