//! Dense optical flow with per-pixel bivariate Gaussian uncertainty.
//!
//! Spec: Ng, Li, Kim 2021, section 3 (epipolar cost §3.1, uncertainty eq. 1–4 §3.2), built on
//! DCFlow (Xu, Ranftl, Koltun 2017). The pipeline of [`FlowEstimator::compute`]:
//!
//! 1. both images box-downsampled by `scale` (3) to the matching resolution; unit-norm
//!    hand-crafted descriptors ([`descriptor`]);
//! 2. per level of a small pyramid (coarse-to-fine mode) or once with a ±80 px window
//!    (reference mode): u8 cost volume over a `(2R+1)²` window centred on a prior, optional
//!    truncated L2 epipolar cost, 4-direction semi-global matching over the 2-D label space,
//!    winner-take-all with sub-pixel refinement, forward and backward ([`volume`]);
//! 3. forward–backward check (0.8 px at 1/3 resolution), geodesic, edge-aware filling of the
//!    removed pixels ([`interp`]) and a median filter;
//! 4. at the matching resolution, the Gaussian fit of eq. 4 to the regularised cost slice,
//!    calibrated and made positive definite ([`uncertainty`]); removed pixels get the maximum
//!    uncertainty;
//! 5. upsampling to full resolution (flow ×3; information via covariance ×9 and inversion); the
//!    flow is refined by a variational pass at half resolution, then dense Lucas–Kanade and a
//!    variational pass at full resolution ([`refine`]); with the uncertainty model on, the
//!    backward flow is refined too (fewer iterations) for the model's full-resolution
//!    forward–backward term, and the forward matching result a second time with a weak
//!    smoothness term for its smoothness-sensitivity term ([`model`]).
//!
//! [`epipolar::estimate_from_tracks`] estimates the fundamental matrix for the epipolar cost
//! from Shi–Tomasi corners tracked by KLT and the normalised eight-point algorithm.
//!
//! Coordinates: pixel centres at integers; flow `(u, v)` maps `(x, y)` in image 1 to
//! `(x + u, y + v)` in image 2, in pixels.

pub mod config;
pub mod descriptor;
pub mod epipolar;
pub mod error;
pub mod interp;
pub mod model;
pub mod ops;
pub mod refine;
pub mod synthetic;
pub mod uncertainty;
pub mod volume;

use std::time::Instant;

use nalgebra::Matrix3;
use visnav_core::GrayImage;

pub use config::{
    EpipolarConfig, FlowConfig, InterpolationConfig, RefinementConfig, SearchMode, SgmConfig,
    UncertaintyConfig, VarianceModel,
};
pub use error::FlowError;
pub use uncertainty::UncertaintyTerms;

use volume::{EpipolarLevel, FitParams, LevelProblem};

/// Dense flow from image 1 to image 2 at full resolution, with its uncertainty.
///
/// Per pixel `i = y * width + x`: `flow[i] = (u, v)` in pixels (`x2 = x + u`, `y2 = y + v`);
/// `information[i] = (Yxx, Yxy, Yyy)` the information matrix (inverse covariance) of the flow,
/// in 1/px², always positive definite; `valid[i]` whether the pixel passed the forward–backward
/// check (invalid pixels carry interpolated flow and the maximum uncertainty).
#[derive(Debug, Clone, PartialEq)]
pub struct DenseFlow {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `(u, v)` per pixel, row-major.
    pub flow: Vec<[f32; 2]>,
    /// `(Yxx, Yxy, Yyy)` per pixel, 1/px².
    pub information: Vec<[f32; 3]>,
    /// Forward–backward consistency per pixel.
    pub valid: Vec<bool>,
}

impl DenseFlow {
    /// Flow `(u, v)` at pixel `(x, y)`, pixels.
    #[must_use]
    pub fn at(&self, x: usize, y: usize) -> [f32; 2] {
        self.flow[y * self.width + x]
    }

    /// Covariance `(Pxx, Pxy, Pyy)` at pixel index `i`, px² (the inverse of the information).
    #[must_use]
    pub fn covariance(&self, i: usize) -> [f32; 3] {
        uncertainty::invert(self.information[i]).unwrap_or([f32::INFINITY, 0.0, f32::INFINITY])
    }

    /// Squared Mahalanobis distance (eq. 1) of a flow error `(du, dv)` at pixel index `i`.
    #[must_use]
    pub fn mahalanobis_sq(&self, i: usize, du: f32, dv: f32) -> f32 {
        let [a, b, c] = self.information[i];
        a * du * du + 2.0 * b * du * dv + c * dv * dv
    }

    /// Share of pixels that passed the forward–backward check.
    #[must_use]
    pub fn valid_fraction(&self) -> f64 {
        if self.valid.is_empty() {
            return 0.0;
        }
        self.valid.iter().filter(|v| **v).count() as f64 / self.valid.len() as f64
    }
}

/// Optional inputs of one flow computation.
#[derive(Debug, Clone, Copy, Default)]
pub struct FlowInput<'a> {
    /// Fundamental matrix in full-resolution pixels (`x2ᵀ F x1 = 0`): adds the epipolar cost.
    pub fundamental: Option<Matrix3<f64>>,
    /// A prior flow at full resolution (row-major, `width * height`): the 1/3-resolution window
    /// is centred on it and the coarse levels are skipped.
    pub prior: Option<&'a [[f32; 2]]>,
}

/// Wall-clock time per stage of one computation, milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlowTimings {
    /// Downsampling and descriptors.
    pub features_ms: f64,
    /// Cost volumes, SGM, WTA, forward–backward check and interpolation, all levels.
    pub matching_ms: f64,
    /// Uncertainty calibration, upsampling and the terms of the full model.
    pub uncertainty_ms: f64,
    /// Full-resolution refinement.
    pub refinement_ms: f64,
    /// Everything.
    pub total_ms: f64,
}

/// The flow stage: holds its configuration.
#[derive(Debug, Clone)]
pub struct FlowEstimator {
    config: FlowConfig,
}

/// Geometry of the matching level: level pixel `i` is at full-resolution `scale * i + offset`.
struct LevelGeometry {
    width: usize,
    height: usize,
    scale: f32,
    offset: f32,
}

struct LevelData {
    img1: GrayImage,
    img2: GrayImage,
    scale: f64,
    offset: f64,
}

/// The prefiltered images of the full-resolution refinement ([`refine::prefilter`]), made once
/// for every refinement of a pair (forward, backward, weakly smoothed): at half resolution when
/// the configuration has a half-resolution pass, and at full resolution.
struct RefinementImages {
    half: Option<(GrayImage, GrayImage)>,
    full: (GrayImage, GrayImage),
}

impl RefinementImages {
    fn new(img1: &GrayImage, img2: &GrayImage, r: &RefinementConfig) -> Self {
        let half = r.half_resolution_pass.then(|| {
            let h1 = ops::downsample_box(img1, 2);
            let h2 = ops::downsample_box(img2, 2);
            refine::prefilter(&h1, &h2, r)
        });
        Self {
            half,
            full: refine::prefilter(img1, img2, r),
        }
    }
}

/// Bytes a cost volume takes per pixel and label while it is aggregated (u8 costs, u16 sums).
const VOLUME_BYTES_PER_LABEL: usize = 3;

/// Largest cost volume (bytes) whose forward and backward matching run side by side; larger ones
/// run one after the other so that the peak memory is that of one direction.
const SIDE_BY_SIDE_VOLUME_LIMIT: usize = 512 << 20;

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

impl FlowEstimator {
    /// A flow estimator with a validated configuration.
    ///
    /// # Errors
    /// [`FlowError::InvalidConfig`] when a field is out of range.
    pub fn new(config: FlowConfig) -> Result<Self, FlowError> {
        config.validate()?;
        Ok(Self { config })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &FlowConfig {
        &self.config
    }

    /// Dense flow from `img1` to `img2` with uncertainty, at full resolution.
    ///
    /// # Errors
    /// Different image sizes, images too small, or a prior of the wrong size.
    pub fn compute(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
    ) -> Result<DenseFlow, FlowError> {
        self.compute_timed(img1, img2, input).map(|(f, _)| f)
    }

    /// As [`Self::compute`], with the time per stage.
    ///
    /// # Errors
    /// As [`Self::compute`].
    pub fn compute_timed(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
    ) -> Result<(DenseFlow, FlowTimings), FlowError> {
        self.run(img1, img2, input, false).map(|(f, t, _)| (f, t))
    }

    /// As [`Self::compute_timed`], with the per-pixel terms of the uncertainty model
    /// ([`UncertaintyTerms`]), for calibration and diagnostics.
    ///
    /// # Errors
    /// As [`Self::compute`].
    pub fn compute_detailed(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
    ) -> Result<(DenseFlow, FlowTimings, UncertaintyTerms), FlowError> {
        let (flow, timings, terms) = self.run(img1, img2, input, true)?;
        let terms = terms.ok_or(FlowError::TooSmall {
            width: img1.width(),
            height: img1.height(),
            min: self.config.scale * 8,
        })?;
        Ok((flow, timings, terms))
    }

    /// Full-resolution flow from image 1 to image 2 refined from the matching-level flow
    /// `flow_level`: a variational pass at half resolution (when `half` images are given),
    /// dense Lucas–Kanade and a variational pass at full resolution ([`refine`]). The images
    /// are the prefiltered pair ([`RefinementImages`]), image 1 first.
    fn refine_full(
        half: Option<(&GrayImage, &GrayImage)>,
        (r1, r2): (&GrayImage, &GrayImage),
        flow_level: &[[f32; 2]],
        level: &LevelGeometry,
        r: &RefinementConfig,
    ) -> Vec<[f32; 2]> {
        let (w, h) = (r1.width(), r1.height());
        let (lw, lh, sc, off) = (level.width, level.height, level.scale, level.offset);
        let mut flow = if let Some((q1, q2)) = half {
            // variational pass at half resolution first (pixel i at 2i + 0.5)
            let (hw, hh) = (q1.width(), q1.height());
            let (hs, ho) = (sc / 2.0, (off - 0.5) / 2.0);
            let mut fh = ops::upsample_flow(flow_level, lw, lh, hw, hh, hs, ho);
            let half_cfg = RefinementConfig {
                variational_alpha: r.half_resolution_alpha,
                gradient_normalisation: r.half_resolution_normalisation,
                ..r.clone()
            };
            refine::variational(q1, q2, &mut fh, &half_cfg);
            ops::upsample_flow(&fh, hw, hh, w, h, 2.0, 0.5)
        } else {
            ops::upsample_flow(flow_level, lw, lh, w, h, sc, off)
        };
        refine::refine(r1, r2, &mut flow, r);
        let (variational_outer, variational_inner) = if half.is_some() {
            (r.full_resolution_outer, r.full_resolution_inner)
        } else {
            (r.variational_outer, r.variational_inner)
        };
        let full = RefinementConfig {
            variational_outer,
            variational_inner,
            ..r.clone()
        };
        refine::variational(r1, r2, &mut flow, &full);
        flow
    }

    #[allow(clippy::too_many_lines)]
    fn run(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
        want_terms: bool,
    ) -> Result<(DenseFlow, FlowTimings, Option<UncertaintyTerms>), FlowError> {
        let cfg = &self.config;
        let t_start = Instant::now();
        let (w, h) = (img1.width(), img1.height());
        if (w, h) != (img2.width(), img2.height()) {
            return Err(FlowError::SizeMismatch {
                width1: w,
                height1: h,
                width2: img2.width(),
                height2: img2.height(),
            });
        }
        let min_side = cfg.scale * 8;
        if w < min_side || h < min_side {
            return Err(FlowError::TooSmall {
                width: w,
                height: h,
                min: min_side,
            });
        }
        if let Some(p) = input.prior
            && p.len() != w * h
        {
            return Err(FlowError::PriorSize {
                width: w,
                height: h,
                got_width: p.len() % w.max(1),
                got_height: p.len() / w.max(1),
            });
        }
        let s = cfg.scale;
        let (radius, n_levels) = match cfg.mode {
            SearchMode::Reference => (cfg.reference_radius, 0),
            SearchMode::CoarseToFine if input.prior.is_some() => (cfg.radius, 0),
            SearchMode::CoarseToFine => (cfg.radius, cfg.levels),
        };
        // pyramid
        let mut levels = vec![LevelData {
            img1: ops::downsample_box(img1, s),
            img2: ops::downsample_box(img2, s),
            scale: s as f64,
            offset: (s as f64 - 1.0) / 2.0,
        }];
        for _ in 0..n_levels {
            let last = &levels[levels.len() - 1];
            if last.img1.width() < 16 || last.img1.height() < 16 {
                break;
            }
            let next = LevelData {
                img1: ops::downsample_box(&last.img1, 2),
                img2: ops::downsample_box(&last.img2, 2),
                scale: last.scale * 2.0,
                offset: last.offset + 0.5 * last.scale,
            };
            levels.push(next);
        }
        let features: Vec<_> = levels
            .iter()
            .map(|l| {
                (
                    descriptor::compute(&l.img1),
                    descriptor::compute(&l.img2),
                    ops::gradient_magnitude(&l.img1),
                    ops::gradient_magnitude(&l.img2),
                )
            })
            .collect();
        // the half-label cost at the matching resolution only (the coarser levels only place
        // its window)
        let half_norms = cfg.half_label_cost.then(|| {
            let (d1, d2, _, _) = &features[0];
            rayon::join(|| descriptor::half_norms(d1), || descriptor::half_norms(d2))
        });
        let features_ms = ms(t_start);
        let t_match = Instant::now();

        // initial centres at the coarsest level
        let top = levels.len() - 1;
        let (tw, th) = (levels[top].img1.width(), levels[top].img1.height());
        let (mut centres_f, mut centres_b) = match input.prior {
            Some(prior) => {
                let l = &levels[0];
                let c: Vec<[i32; 2]> = (0..tw * th)
                    .map(|i| {
                        let xf = l.scale * (i % tw) as f64 + l.offset;
                        let yf = l.scale * (i / tw) as f64 + l.offset;
                        let p = ops::sample_field(prior, w, h, xf as f32, yf as f32);
                        let sc = l.scale as f32;
                        [(p[0] / sc).round() as i32, (p[1] / sc).round() as i32]
                    })
                    .collect();
                // backward prior: negated forward prior at the same pixel (first order)
                let b = c.iter().map(|v| [-v[0], -v[1]]).collect();
                (c, b)
            }
            None => (vec![[0, 0]; tw * th], vec![[0, 0]; tw * th]),
        };

        // the model's terms that need extra work: the second minimum of the cost slice
        // (ambiguity) and the refined backward flow (full-resolution forward-backward term)
        let model = &cfg.uncertainty.variance_model;
        let want_ambiguity = want_terms || (model.enabled && model.ambiguity != 0.0);
        let want_backward = want_terms || (model.enabled && model.fb_full_resolution != 0.0);
        let want_sensitivity = want_terms || (model.enabled && model.smoothness_sensitivity != 0.0);
        let fit = FitParams {
            radius: cfg.uncertainty.fit_radius,
            threshold: cfg.uncertainty.cost_threshold,
            second_minimum: want_ambiguity,
        };
        let mut result = None;
        for k in (0..levels.len()).rev() {
            let l = &levels[k];
            let (d1, d2, g1, g2) = &features[k];
            let (lw, lh) = (l.img1.width(), l.img1.height());
            let p2 = |g: &[f32]| -> Vec<u16> {
                g.iter()
                    .map(|v| {
                        if *v > cfg.sgm.edge_gradient {
                            (cfg.sgm.p2 / cfg.sgm.p2_edge_divisor).max(cfg.sgm.p1)
                        } else {
                            cfg.sgm.p2
                        }
                    })
                    .collect()
            };
            let (p2_1, p2_2) = (p2(g1), p2(g2));
            let epi = |f: Matrix3<f64>| EpipolarLevel {
                fundamental: f,
                scale: l.scale,
                offset: l.offset,
                weight: cfg.epipolar.weight,
                truncation: cfg.epipolar.truncation,
            };
            let pb_f = LevelProblem {
                d1,
                d2,
                centres: &centres_f,
                radius,
                p2: &p2_1,
                p1: cfg.sgm.p1,
                outside_cost: cfg.outside_cost,
                epipolar: input.fundamental.map(epi),
                half: half_norms.as_ref().filter(|_| k == 0).map(|h| &h.1),
                half_penalty: cfg.half_label_penalty / 127.0,
            };
            let pb_b = LevelProblem {
                d1: d2,
                d2: d1,
                centres: &centres_b,
                radius,
                p2: &p2_2,
                p1: cfg.sgm.p1,
                outside_cost: cfg.outside_cost,
                epipolar: input.fundamental.map(|f| epi(f.transpose())),
                half: half_norms.as_ref().filter(|_| k == 0).map(|h| &h.0),
                half_penalty: cfg.half_label_penalty / 127.0,
            };
            let want_fit = (k == 0).then_some(fit);
            // the two directions are independent: run them side by side (the geodesic fill is
            // sequential, the rest parallel by rows) unless their cost volumes are large (the
            // ±80 px reference mode: ≈ 4 GB each on a KITTI pair), then one after the other
            let n_labels = (2 * radius + 1) * (2 * radius + 1);
            let volume_bytes = lw * lh * n_labels * VOLUME_BYTES_PER_LABEL;
            let (fwd, bwd) = if volume_bytes <= SIDE_BY_SIDE_VOLUME_LIMIT {
                rayon::join(
                    || volume::match_level(&pb_f, want_fit),
                    || volume::match_level(&pb_b, None),
                )
            } else {
                (
                    volume::match_level(&pb_f, want_fit),
                    volume::match_level(&pb_b, None),
                )
            };
            let (fb_f, fb_b) = rayon::join(
                || ops::forward_backward_discrepancy(&fwd.flow, &bwd.flow, lw, lh),
                || ops::forward_backward_discrepancy(&bwd.flow, &fwd.flow, lw, lh),
            );
            let keep_f: Vec<bool> = fb_f.iter().map(|e| *e < cfg.fb_threshold_px).collect();
            let keep_b: Vec<bool> = fb_b.iter().map(|e| *e < cfg.fb_threshold_px).collect();
            let wta_f = (k == 0).then(|| fwd.flow.clone());
            // with no match kept there is nothing to fill from: the flow stays the prior (the
            // windows' centres), not the winners of slices that said nothing
            let prior_if_none_kept = |flow: Vec<[f32; 2]>, keep: &[bool], centres: &[[i32; 2]]| {
                if keep.iter().any(|k| *k) {
                    flow
                } else {
                    centres.iter().map(|c| [c[0] as f32, c[1] as f32]).collect()
                }
            };
            let mut flow_f = prior_if_none_kept(fwd.flow, &keep_f, &centres_f);
            let mut flow_b = prior_if_none_kept(bwd.flow, &keep_b, &centres_b);
            let mr = cfg.interpolation.median_radius;
            let ((flow_f, fill_f), flow_b) = rayon::join(
                || {
                    let fill = interp::geodesic_fill_with_distance(
                        &mut flow_f,
                        &keep_f,
                        g1,
                        lw,
                        lh,
                        &cfg.interpolation,
                    );
                    (ops::median_filter(&flow_f, lw, lh, mr), fill)
                },
                || {
                    interp::geodesic_fill(&mut flow_b, &keep_b, g2, lw, lh, &cfg.interpolation);
                    ops::median_filter(&flow_b, lw, lh, mr)
                },
            );
            if k > 0 {
                let nl = &levels[k - 1];
                let (nw, nh) = (nl.img1.width(), nl.img1.height());
                let to_centres = |f: &[[f32; 2]]| -> Vec<[i32; 2]> {
                    ops::upsample_flow(f, lw, lh, nw, nh, 2.0, 0.5)
                        .iter()
                        .map(|v| [v[0].round() as i32, v[1].round() as i32])
                        .collect()
                };
                centres_f = to_centres(&flow_f);
                centres_b = to_centres(&flow_b);
            } else {
                // variance the regularised cost slice cannot see: the discrepancy between the
                // raw winner and the filtered flow, and the forward-backward discrepancy
                let extra: Vec<f32> = wta_f
                    .unwrap_or_default()
                    .iter()
                    .zip(&flow_f)
                    .zip(&fb_f)
                    .map(|((a, b), e)| {
                        let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                        d2 + if e.is_finite() { e * e } else { 0.0 }
                    })
                    .collect();
                result = Some((
                    flow_f,
                    flow_b,
                    keep_f,
                    fwd.information.unwrap_or_default(),
                    fwd.second_minimum.unwrap_or_default(),
                    extra,
                    fb_f,
                    fill_f,
                ));
            }
        }
        let matching_ms = ms(t_match);
        let Some((flow0, flow0_b, keep0, raw_info, second0, extra_var, fb0, fill0)) = result else {
            return Err(FlowError::TooSmall {
                width: w,
                height: h,
                min: min_side,
            });
        };
        let l0 = &levels[0];
        let (lw, lh) = (l0.img1.width(), l0.img1.height());
        let (sc, off) = (l0.scale as f32, l0.offset as f32);

        let t_unc = Instant::now();
        let info0 = uncertainty::calibrate(&raw_info, &extra_var, &keep0, sc, &cfg.uncertainty);
        let information =
            uncertainty::upsample_information(&info0, lw, lh, w, h, sc, off, &cfg.uncertainty);
        let valid = uncertainty::upsample_valid_nearest(&keep0, lw, lh, w, h, sc, off);
        let uncertainty_ms = ms(t_unc);

        let t_ref = Instant::now();
        let level = LevelGeometry {
            width: lw,
            height: lh,
            scale: sc,
            offset: off,
        };
        // prefiltered once for all refinements of the pair (the backward one takes them swapped)
        let images = RefinementImages::new(img1, img2, &cfg.refinement);
        let half = images.half.as_ref().map(|(a, b)| (a, b));
        let half_swapped = images.half.as_ref().map(|(a, b)| (b, a));
        let (r1, r2) = (&images.full.0, &images.full.1);
        let flow = Self::refine_full(half, (r1, r2), &flow0, &level, &cfg.refinement);
        // the backward flow is refined after the forward one (side by side, the memory-bound
        // sweeps of the two compete and take longer)
        let backward = want_backward.then(|| {
            let backward_cfg = RefinementConfig {
                full_resolution_outer: cfg.uncertainty.backward_full_resolution_outer,
                ..cfg.refinement.clone()
            };
            Self::refine_full(half_swapped, (r2, r1), &flow0_b, &level, &backward_cfg)
        });
        // the same matching result refined again with a weaker smoothness term (the model's
        // smoothness-sensitivity predictor)
        let weakly_smoothed = want_sensitivity.then(|| {
            // both passes' smoothness weakened in the same ratio
            let weaken = cfg.uncertainty.sensitivity_alpha / cfg.refinement.variational_alpha;
            let weak_cfg = RefinementConfig {
                variational_alpha: cfg.uncertainty.sensitivity_alpha,
                half_resolution_alpha: cfg.refinement.half_resolution_alpha * weaken,
                full_resolution_outer: cfg.uncertainty.sensitivity_full_resolution_outer,
                ..cfg.refinement.clone()
            };
            Self::refine_full(half, (r1, r2), &flow0, &level, &weak_cfg)
        });
        let refinement_ms = ms(t_ref);
        let t_model = Instant::now();
        let terms = (want_terms || UncertaintyTerms::model_enabled(&cfg.uncertainty)).then(|| {
            model::terms(
                &model::Inputs {
                    img1: r1,
                    img2: r2,
                    flow: &flow,
                    backward_flow: backward.as_deref(),
                    weakly_smoothed_flow: weakly_smoothed.as_deref(),
                    information: &information,
                    fb_level: &fb0,
                    fill_level: &fill0,
                    second_minimum_level: &second0,
                    keep_level: &keep0,
                    flow_level: &flow0,
                    level_width: lw,
                    level_height: lh,
                    scale: sc,
                    offset: off,
                },
                &cfg.uncertainty,
            )
        });
        let information = match &terms {
            Some(t) if UncertaintyTerms::model_enabled(&cfg.uncertainty) => {
                t.information(&cfg.uncertainty)
            }
            _ => information,
        };
        let information = if cfg.uncertainty.residual_variance_px2 > 0.0 {
            refine::inflate_by_residual(r1, r2, &flow, information, &cfg.uncertainty)
        } else {
            information
        };
        // no match survived (flat or unrelated images): the flow is the prior everywhere, a
        // guess, and every pixel gets the maximum uncertainty, as a removed pixel does (§3.2)
        let information = if keep0.iter().any(|k| *k) {
            information
        } else {
            let m = cfg.uncertainty.min_information;
            vec![[m, 0.0, m]; information.len()]
        };
        let uncertainty_ms = uncertainty_ms + ms(t_model);
        let timings = FlowTimings {
            features_ms,
            matching_ms,
            uncertainty_ms,
            refinement_ms,
            total_ms: ms(t_start),
        };
        Ok((
            DenseFlow {
                width: w,
                height: h,
                flow,
                information,
                valid,
            },
            timings,
            terms,
        ))
    }
}
