//! The dense flow the monocular pipeline consumes: [`visnav_flow`] (Ng, Li, Kim 2021 §3) run on
//! images box-downsampled by the smallest integer factor `s` that brings their width to at most
//! `MonoFlowConfig::max_width_px`, then brought back to the camera's resolution.
//!
//! Speed lever for VO (issue 5): at KITTI's 1241x376 the flow at full resolution costs ~2.4 s a
//! pair; on a 2x-downsampled pair every stage (matching, uncertainty, variational refinement)
//! touches a quarter of the pixels (opt-in, `max_width_px = 700`: it costs accuracy, see the
//! field's docs). Going back to full resolution (pixel `i` of the downsampled
//! image sits at full-resolution coordinate `s·i + (s−1)/2`):
//!
//! * flow: bilinear resampling, vectors multiplied by `s`, pixels;
//! * information: a flow error of `e` downsampled pixels is `s·e` full-resolution pixels, so the
//!   covariance (eq. 4's `Σ`) scales by `s²` and the information matrix `Y = Σ⁻¹` by `1/s²`
//!   (resampled as a covariance, inverted and clamped to the configured eigenvalue range by
//!   [`visnav_flow::uncertainty::upsample_information`]);
//! * the forward–backward validity: nearest downsampled pixel.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use visnav_core::GrayImage;
use visnav_flow::{
    DenseFlow, FastFlow, FastFlowConfig, FlowConfig, FlowEstimator, FlowInput, FlowMethod,
    FlowTimings, RefinementConfig, ops, refine, uncertainty,
};

use super::error::MonoError;

/// The flow configuration of the monocular pipeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonoFlowConfig {
    /// Widest image the flow runs on, pixels: wider images are box-downsampled by the smallest
    /// integer factor `s = ceil(width / max_width_px)` (at most 4) and the flow is brought back
    /// to full resolution. Default 2048 (KITTI's 1241x376 at full resolution, the accuracy of
    /// issue 5). The speed setting 700 runs KITTI at 620x188 (`s = 2`): about 3x less CPU, but
    /// on KITTI 00 (300 frames) 5.1 % / 1.13 deg/100 m instead of 1.36 % / 0.98 — measured
    /// trade-off in docs/benchmarks.md (mono section).
    pub max_width_px: usize,
    /// Dense Lucas–Kanade iterations at full resolution on the upsampled flow (0: none), with
    /// the window, damping and high-pass of `flow.refinement`. Default 0.
    pub full_resolution_lk_iterations: usize,
    /// Variational (re-warping) outer iterations at full resolution on the upsampled flow
    /// (0: none), with the inner iterations and smoothness of `flow.refinement`. Default 0.
    pub full_resolution_variational_outer: usize,
    /// Extra pyramid levels of the retry on a refused frame: when the odometry refuses a frame
    /// for its flow (no rigid motion, inconsistent flow), the driver computes the flow again
    /// with `flow.levels` plus this many levels, which doubles the search range each (faster
    /// motion than the default search reaches: a car at 2 m a frame), and tries once more. 0: no
    /// retry. Default 1. Not in the paper.
    pub retry_extra_levels: usize,
    /// The flow stage, applied at the downsampled resolution (its pixel units are downsampled
    /// pixels). Default: [`FlowConfig::odometry`] (the paper's cost-slice uncertainty, eq. 1–4).
    pub flow: FlowConfig,
    /// Which flow the odometry runs: `paper` (`flow`, the default) or `fast` (dense inverse
    /// search, `fast`; the real-time preset). With `fast`, `max_width_px`, the full-resolution
    /// passes and the retry do not apply (its pyramid already reaches the whole image).
    pub method: FlowMethod,
    /// The fast flow (used when `method` is `fast`), at the camera's resolution.
    pub fast: FastFlowConfig,
}

impl Default for MonoFlowConfig {
    fn default() -> Self {
        Self {
            max_width_px: 2048,
            full_resolution_lk_iterations: 0,
            full_resolution_variational_outer: 0,
            retry_extra_levels: 1,
            flow: FlowConfig::odometry(),
            method: FlowMethod::Paper,
            fast: FastFlowConfig::realtime(),
        }
    }
}

impl MonoFlowConfig {
    /// The real-time preset's flow: [`FlowMethod::Fast`] with [`FastFlowConfig::realtime`].
    #[must_use]
    pub fn realtime() -> Self {
        Self {
            method: FlowMethod::Fast,
            ..Self::default()
        }
    }

    /// Checks the downsampling factor and the flow configuration.
    ///
    /// # Errors
    /// [`MonoError::InvalidConfig`] or [`MonoError::Flow`] naming the bad field.
    pub fn validate(&self) -> Result<(), MonoError> {
        if self.max_width_px < 64 {
            return Err(MonoError::InvalidConfig {
                field: "flow.max_width_px",
                value: self.max_width_px as f64,
                expected: ">= 64",
            });
        }
        if self.flow.levels + self.retry_extra_levels > 6 {
            return Err(MonoError::InvalidConfig {
                field: "flow.retry_extra_levels",
                value: self.retry_extra_levels as f64,
                expected: "flow.flow.levels + retry_extra_levels <= 6",
            });
        }
        self.flow.validate()?;
        self.fast.validate()?;
        Ok(())
    }
}

/// Dense flow with uncertainty for the monocular pipeline, at the camera's resolution.
#[derive(Debug, Clone)]
pub struct MonoFlow {
    estimator: FlowEstimator,
    /// The fast flow, when `method` is `fast`.
    fast: Option<FastFlow>,
    /// The retry's estimator (`retry_extra_levels` more pyramid levels), if any.
    wide: Option<FlowEstimator>,
    config: MonoFlowConfig,
}

impl MonoFlow {
    /// A flow stage with a validated configuration.
    ///
    /// # Errors
    /// As [`MonoFlowConfig::validate`].
    pub fn new(config: &MonoFlowConfig) -> Result<Self, MonoError> {
        config.validate()?;
        let wide = (config.retry_extra_levels > 0)
            .then(|| {
                let mut flow = config.flow.clone();
                flow.levels += config.retry_extra_levels;
                FlowEstimator::new(flow)
            })
            .transpose()?;
        let fast = (config.method == FlowMethod::Fast)
            .then(|| FastFlow::new(config.fast.clone()))
            .transpose()?;
        let wide = if fast.is_some() { None } else { wide };
        Ok(Self {
            estimator: FlowEstimator::new(config.flow.clone())?.with_image_cache(),
            fast,
            wide,
            config: config.clone(),
        })
    }

    /// Dense flow from `prev` to `cur` at their resolution, with the time per stage (the
    /// downsampling and the return to full resolution are counted in `uncertainty_ms` and
    /// `total_ms`).
    ///
    /// # Errors
    /// [`MonoError::Flow`]: different sizes, images too small for the downsampled flow.
    pub fn compute_timed(
        &self,
        prev: &GrayImage,
        cur: &GrayImage,
    ) -> Result<(DenseFlow, FlowTimings), MonoError> {
        if let Some(fast) = &self.fast {
            return Ok(fast.compute_timed(prev, cur)?);
        }
        self.compute_with(&self.estimator, prev, cur)
    }

    /// The retry's flow (`retry_extra_levels` more pyramid levels: a search range 2^extra times
    /// wider), as [`Self::compute_timed`]; `None` when the retry is off.
    ///
    /// # Errors
    /// As [`Self::compute_timed`].
    pub fn compute_wide_timed(
        &self,
        prev: &GrayImage,
        cur: &GrayImage,
    ) -> Option<Result<(DenseFlow, FlowTimings), MonoError>> {
        let wide = self.wide.as_ref()?;
        Some(self.compute_with(wide, prev, cur))
    }

    fn compute_with(
        &self,
        estimator: &FlowEstimator,
        prev: &GrayImage,
        cur: &GrayImage,
    ) -> Result<(DenseFlow, FlowTimings), MonoError> {
        let (w, h) = (prev.width(), prev.height());
        let s = self.downsample_factor(w);
        if s == 1 || (w, h) != (cur.width(), cur.height()) {
            // full resolution, or let the flow stage report the mismatch with the real sizes
            return Ok(estimator.compute_timed(prev, cur, &FlowInput::default())?);
        }
        let t_start = Instant::now();
        let small_prev = ops::downsample_box(prev, s);
        let small_cur = ops::downsample_box(cur, s);
        let down_ms = t_start.elapsed().as_secs_f64() * 1e3;
        let (small, mut timings) =
            estimator.compute_timed(&small_prev, &small_cur, &FlowInput::default())?;
        let t_up = Instant::now();
        let mut full = upsample_dense_flow(&small, w, h, s, &estimator.config().uncertainty);
        let up_ms = t_up.elapsed().as_secs_f64() * 1e3;
        let t_ref = Instant::now();
        self.polish(prev, cur, &mut full.flow);
        timings.refinement_ms += t_ref.elapsed().as_secs_f64() * 1e3;
        timings.features_ms += down_ms;
        timings.uncertainty_ms += up_ms;
        timings.total_ms = t_start.elapsed().as_secs_f64() * 1e3;
        Ok((full, timings))
    }
}

impl MonoFlow {
    /// The box-downsampling factor for images `width_px` wide (1 = full resolution).
    #[must_use]
    pub fn downsample_factor(&self, width_px: usize) -> usize {
        width_px.div_ceil(self.config.max_width_px).clamp(1, 4)
    }

    /// The optional full-resolution Lucas–Kanade and variational passes on the upsampled flow.
    fn polish(&self, prev: &GrayImage, cur: &GrayImage, flow: &mut [[f32; 2]]) {
        let c = &self.config;
        if c.full_resolution_lk_iterations == 0 && c.full_resolution_variational_outer == 0 {
            return;
        }
        let r = RefinementConfig {
            iterations: c.full_resolution_lk_iterations,
            variational_outer: c.full_resolution_variational_outer,
            ..c.flow.refinement.clone()
        };
        let (p1, p2) = refine::prefilter(prev, cur, &r);
        refine::refine(&p1, &p2, flow, &r);
        refine::variational(&p1, &p2, flow, &r);
    }
}

/// Brings a flow computed on images box-downsampled by `s` back to `w` x `h` (see the module
/// docs: flow ×`s`, covariance ×`s²`, i.e. information ×`1/s²`; validity of the nearest pixel).
#[must_use]
pub fn upsample_dense_flow(
    small: &DenseFlow,
    w: usize,
    h: usize,
    s: usize,
    uncertainty_cfg: &visnav_flow::UncertaintyConfig,
) -> DenseFlow {
    let (lw, lh) = (small.width, small.height);
    let sc = s as f32;
    let off = (sc - 1.0) / 2.0;
    let flow = ops::upsample_flow(&small.flow, lw, lh, w, h, sc, off);
    let information = uncertainty::upsample_information(
        &small.information,
        (lw, lh),
        (w, h),
        sc,
        off,
        uncertainty_cfg,
    );
    let valid = uncertainty::upsample_valid_nearest(&small.valid, lw, lh, w, h, sc, off);
    DenseFlow {
        width: w,
        height: h,
        flow,
        information,
        valid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upsampling_scales_flow_by_s_and_information_by_one_over_s_squared() {
        let (lw, lh) = (8, 6);
        let small = DenseFlow {
            width: lw,
            height: lh,
            flow: vec![[1.5, -0.5]; lw * lh],
            information: vec![[4.0, 1.0, 2.0]; lw * lh],
            valid: (0..lw * lh).map(|i| i % lw < 4).collect(),
        };
        let cfg = visnav_flow::UncertaintyConfig::default();
        let full = upsample_dense_flow(&small, 16, 12, 2, &cfg);
        assert_eq!((full.width, full.height), (16, 12));
        for (i, (f, y)) in full.flow.iter().zip(&full.information).enumerate() {
            assert!(
                (f[0] - 3.0).abs() < 1e-5 && (f[1] + 1.0).abs() < 1e-5,
                "{f:?}"
            );
            for (k, expected) in [1.0, 0.25, 0.5].iter().enumerate() {
                assert!((y[k] - expected).abs() < 1e-4, "pixel {i}: {y:?}");
            }
        }
        // pixel x of the full grid maps to small pixel round((x - 0.5) / 2)
        assert!(full.valid[7] && !full.valid[9]);
    }

    #[test]
    fn downsampled_flow_recovers_a_translation_at_full_resolution() {
        // a smooth texture shifted by (4, 2) px
        let (w, h) = (160, 96);
        let tex = |x: f32, y: f32| {
            128.0 + 50.0 * (x * 0.21).sin() * (y * 0.17).cos() + 30.0 * ((x + 2.0 * y) * 0.07).sin()
        };
        let img = |dx: f32, dy: f32| {
            let data = (0..w * h)
                .map(|i| tex((i % w) as f32 - dx, (i / w) as f32 - dy))
                .collect();
            GrayImage::from_vec(w, h, data).unwrap()
        };
        let cfg = MonoFlowConfig {
            max_width_px: 80,
            ..MonoFlowConfig::default()
        };
        let flow = MonoFlow::new(&cfg).unwrap();
        assert_eq!(flow.downsample_factor(w), 2);
        let (f, _) = flow.compute_timed(&img(0.0, 0.0), &img(4.0, 2.0)).unwrap();
        assert_eq!((f.width, f.height), (w, h));
        let mut errs: Vec<f32> = (20..h - 20)
            .flat_map(|y| (20..w - 20).map(move |x| y * w + x))
            .map(|i| (f.flow[i][0] - 4.0).hypot(f.flow[i][1] - 2.0))
            .collect();
        errs.sort_by(f32::total_cmp);
        let median = errs[errs.len() / 2];
        assert!(median < 0.3, "median end-point error {median} px");
    }

    #[test]
    fn downsample_factor_follows_the_width_limit() {
        let full = MonoFlow::new(&MonoFlowConfig::default()).unwrap();
        assert_eq!(full.downsample_factor(1241), 1);
        let fast = MonoFlow::new(&MonoFlowConfig {
            max_width_px: 700,
            ..MonoFlowConfig::default()
        })
        .unwrap();
        assert_eq!(fast.downsample_factor(1241), 2);
        assert_eq!(fast.downsample_factor(700), 1);
        assert_eq!(fast.downsample_factor(320), 1);
        assert_eq!(fast.downsample_factor(10_000), 4);
    }

    #[test]
    fn invalid_width_limit_is_rejected() {
        let cfg = MonoFlowConfig {
            max_width_px: 0,
            ..MonoFlowConfig::default()
        };
        assert!(matches!(
            MonoFlow::new(&cfg),
            Err(MonoError::InvalidConfig {
                field: "flow.max_width_px",
                ..
            })
        ));
    }
}
