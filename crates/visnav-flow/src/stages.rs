//! The stages of [`crate::FlowEstimator`]'s pipeline (see the crate docs for the steps), each a
//! plain struct or function returning a named result:
//!
//! 1. [`check_inputs`] and [`SearchPlan`]: sizes, the window radius and the pyramid depth;
//! 2. [`Features`]: the matching-resolution pyramid with descriptors and gradients (step 1);
//! 3. [`Matching`]: per level, coarse to fine, [`LevelMatch`] (cost volumes, SGM, WTA with the
//!    Gaussian fit of eq. 1–4 at the matching level), [`ConsistencyCheck`] (forward–backward)
//!    and [`FilledFlows`] (geodesic fill, median); the matching level's result is a
//!    [`Matching`] (steps 2–3);
//! 4. [`FittedUncertainty`]: the calibrated eq. 4 fit at full resolution (step 4);
//! 5. [`Refined`]: the full-resolution refinements (step 5);
//! 6. [`FinalUncertainty`]: the terms of the full model ([`crate::model`]), the residual
//!    inflation and the no-match fallback (§3.2: removed pixels get the maximum uncertainty).

use nalgebra::Matrix3;
use visnav_core::GrayImage;

use crate::config::{FlowConfig, RefinementConfig, SearchMode, SgmConfig};
use crate::descriptor::{self, Descriptors, HalfNorms};
use crate::error::FlowError;
use crate::uncertainty::{self, UncertaintyTerms};
use crate::volume::{self, EpipolarLevel, FitParams, LevelFlow, LevelProblem};
use crate::{FlowInput, interp, model, ops, refine};

/// Bytes a cost volume takes per pixel and label while it is aggregated (u8 costs, u16 sums).
const VOLUME_BYTES_PER_LABEL: usize = 3;

/// Largest cost volume (bytes) whose forward and backward matching run side by side; larger ones
/// run one after the other so that the peak memory is that of one direction.
const SIDE_BY_SIDE_VOLUME_LIMIT: usize = 512 << 20;

/// Stage 0: the two images have the same size, at least `8 * scale` on each side, and the
/// prior (if any) has one flow per pixel. Returns `(width, height)`.
pub(crate) fn check_inputs(
    cfg: &FlowConfig,
    img1: &GrayImage,
    img2: &GrayImage,
    input: &FlowInput<'_>,
) -> Result<(usize, usize), FlowError> {
    let (w, h) = FlowError::check_sizes(img1, img2, cfg.scale * 8)?;
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
    Ok((w, h))
}

/// The search of one computation: the window half-width and the number of coarser levels.
pub(crate) struct SearchPlan {
    /// Window half-width R, level px.
    pub radius: usize,
    /// Coarser pyramid levels above the matching resolution (0 with a prior or in reference
    /// mode).
    pub levels: usize,
}

impl SearchPlan {
    pub(crate) fn new(cfg: &FlowConfig, input: &FlowInput<'_>) -> Self {
        let (radius, levels) = match cfg.mode {
            SearchMode::Reference => (cfg.reference_radius, 0),
            SearchMode::CoarseToFine if input.prior.is_some() => (cfg.radius, 0),
            SearchMode::CoarseToFine => (cfg.radius, cfg.levels),
        };
        Self { radius, levels }
    }
}

/// Which optional terms of the uncertainty model this computation needs (each costs work).
pub(crate) struct ModelWants {
    /// The second minimum of the cost slice (ambiguity term).
    pub ambiguity: bool,
    /// The refined backward flow (full-resolution forward–backward term).
    pub backward: bool,
    /// The weakly smoothed refinement (smoothness-sensitivity term).
    pub sensitivity: bool,
}

impl ModelWants {
    pub(crate) fn new(cfg: &FlowConfig, want_terms: bool) -> Self {
        let model = &cfg.uncertainty.variance_model;
        Self {
            ambiguity: want_terms || (model.enabled && model.ambiguity != 0.0),
            backward: want_terms || (model.enabled && model.fb_full_resolution != 0.0),
            sensitivity: want_terms || (model.enabled && model.smoothness_sensitivity != 0.0),
        }
    }
}

/// One pyramid level: image 1 (image 2 enters through its features); level pixel `i` is at
/// full-resolution `scale * i + offset`.
pub(crate) struct LevelData {
    img1: GrayImage,
    scale: f64,
    offset: f64,
}

/// What a level's matching needs of each image.
pub(crate) struct LevelFeatures {
    /// Unit-norm descriptors of image 1.
    d1: Descriptors,
    /// Unit-norm descriptors of image 2.
    d2: Descriptors,
    /// Gradient magnitude of image 1 (P2 on edges, fill costs).
    g1: Vec<f32>,
    /// Gradient magnitude of image 2.
    g2: Vec<f32>,
}

/// Geometry of the matching level: level pixel `i` is at full-resolution `scale * i + offset`.
pub(crate) struct LevelGeometry {
    pub width: usize,
    pub height: usize,
    pub scale: f32,
    pub offset: f32,
}

/// Stage 1 (step 1): the box-downsampled pyramid, matching resolution first, with the
/// descriptors and gradients of every level and the half-label norms of the matching level.
pub(crate) struct Features {
    levels: Vec<LevelData>,
    per_level: Vec<LevelFeatures>,
    /// The half-label cost's norms of image 1 and image 2, matching level only (the coarser
    /// levels only place its window).
    half_norms: Option<(HalfNorms, HalfNorms)>,
    /// Image 2's pyramid (matching resolution first), for [`Self::into_second`].
    images2: Vec<GrayImage>,
}

/// What the matching needs of one image: its box-downsampled pyramid (matching resolution
/// first), the descriptors and gradient magnitude of every level, and the half-label norms of
/// the matching level. Image 2 of a pair is image 1 of the next pair of a video, so the flow
/// can keep it ([`crate::FlowEstimator::with_image_cache`]).
pub(crate) struct ImageFeatures {
    images: Vec<GrayImage>,
    descriptors: Vec<Descriptors>,
    gradients: Vec<Vec<f32>>,
    half_norms: Option<HalfNorms>,
}

impl ImageFeatures {
    fn build(cfg: &FlowConfig, img: &GrayImage, n_levels: usize) -> Self {
        let mut images = vec![ops::downsample_box(img, cfg.scale)];
        for _ in 0..n_levels {
            let last = &images[images.len() - 1];
            if last.width() < 16 || last.height() < 16 {
                break;
            }
            let next = ops::downsample_box(last, 2);
            images.push(next);
        }
        let descriptors: Vec<Descriptors> = images.iter().map(descriptor::compute).collect();
        let gradients = images.iter().map(ops::gradient_magnitude).collect();
        let half_norms = cfg
            .half_label_cost
            .then(|| descriptor::half_norms(&descriptors[0]));
        Self {
            images,
            descriptors,
            gradients,
            half_norms,
        }
    }
}

impl Features {
    /// The features of both images; image 1's from `cached` when given (the image 2 of the
    /// previous pair, built with the same configuration and `n_levels`).
    pub(crate) fn build(
        cfg: &FlowConfig,
        (img1, img2): (&GrayImage, &GrayImage),
        n_levels: usize,
        cached: Option<ImageFeatures>,
    ) -> Self {
        let (f1, f2) = match cached {
            Some(f1) => (f1, ImageFeatures::build(cfg, img2, n_levels)),
            None => rayon::join(
                || ImageFeatures::build(cfg, img1, n_levels),
                || ImageFeatures::build(cfg, img2, n_levels),
            ),
        };
        let s = cfg.scale as f64;
        let (mut scale, mut offset) = (s, (s - 1.0) / 2.0);
        let mut levels = Vec::new();
        let mut per_level = Vec::new();
        let half_norms = f1.half_norms.zip(f2.half_norms);
        let parts1 = f1.images.into_iter().zip(f1.descriptors).zip(f1.gradients);
        let images2 = f2.images;
        let parts2 = f2.descriptors.into_iter().zip(f2.gradients);
        for (((img1, d1), g1), (d2, g2)) in parts1.zip(parts2) {
            levels.push(LevelData {
                img1,
                scale,
                offset,
            });
            per_level.push(LevelFeatures { d1, d2, g1, g2 });
            offset += 0.5 * scale;
            scale *= 2.0;
        }
        Self {
            levels,
            per_level,
            half_norms,
            images2,
        }
    }

    /// Image 2's features, moved out for the next pair of a video (image 1's are dropped).
    pub(crate) fn into_second(self) -> ImageFeatures {
        let (descriptors, gradients) = self.per_level.into_iter().map(|l| (l.d2, l.g2)).unzip();
        ImageFeatures {
            images: self.images2,
            descriptors,
            gradients,
            half_norms: self.half_norms.map(|(_, h2)| h2),
        }
    }

    /// The matching level's geometry.
    pub(crate) fn matching_level(&self) -> LevelGeometry {
        let l0 = &self.levels[0];
        LevelGeometry {
            width: l0.img1.width(),
            height: l0.img1.height(),
            scale: l0.scale as f32,
            offset: l0.offset as f32,
        }
    }

    /// The window centres at the coarsest level: the prior (rounded, at the matching level, for
    /// which the prior skips the coarser levels) or zero.
    fn initial_centres(&self, prior: Option<&[[f32; 2]]>, (w, h): (usize, usize)) -> Centres {
        let top = self.levels.len() - 1;
        let (tw, th) = (
            self.levels[top].img1.width(),
            self.levels[top].img1.height(),
        );
        match prior {
            Some(prior) => {
                let l = &self.levels[0];
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
                Centres {
                    forward: c,
                    backward: b,
                }
            }
            None => Centres {
                forward: vec![[0, 0]; tw * th],
                backward: vec![[0, 0]; tw * th],
            },
        }
    }
}

/// Integer window centres per pixel of a level, level px, of both directions.
struct Centres {
    forward: Vec<[i32; 2]>,
    backward: Vec<[i32; 2]>,
}

/// P2 per pixel: reduced on image edges.
fn p2_weights(gradient: &[f32], sgm: &SgmConfig) -> Vec<u16> {
    gradient
        .iter()
        .map(|v| {
            if *v > sgm.edge_gradient {
                (sgm.p2 / sgm.p2_edge_divisor).max(sgm.p1)
            } else {
                sgm.p2
            }
        })
        .collect()
}

/// Both directions' winner-take-all result of one level (step 2): cost volume, optional
/// epipolar cost (§3.1), 4-direction SGM, WTA with sub-pixel refinement; at the matching level
/// the forward one carries the raw Gaussian fit of eq. 1–4 ([`volume::match_level`]).
struct LevelMatch {
    forward: LevelFlow,
    backward: LevelFlow,
}

impl LevelMatch {
    fn run(
        cfg: &FlowConfig,
        features: &Features,
        k: usize,
        centres: &Centres,
        radius: usize,
        fundamental: Option<Matrix3<f64>>,
        fit: Option<FitParams>,
    ) -> Self {
        let l = &features.levels[k];
        let f = &features.per_level[k];
        let (lw, lh) = (l.img1.width(), l.img1.height());
        let (p2_1, p2_2) = (p2_weights(&f.g1, &cfg.sgm), p2_weights(&f.g2, &cfg.sgm));
        let epi = |f: Matrix3<f64>| EpipolarLevel {
            fundamental: f,
            scale: l.scale,
            offset: l.offset,
            weight: cfg.epipolar.weight,
            truncation: cfg.epipolar.truncation,
        };
        let half_norms = features.half_norms.as_ref().filter(|_| k == 0);
        let pb_f = LevelProblem {
            d1: &f.d1,
            d2: &f.d2,
            centres: &centres.forward,
            radius,
            p2: &p2_1,
            p1: cfg.sgm.p1,
            outside_cost: cfg.outside_cost,
            epipolar: fundamental.map(epi),
            half: half_norms.map(|h| &h.1),
            half_penalty: cfg.half_label_penalty / 127.0,
        };
        let pb_b = LevelProblem {
            d1: &f.d2,
            d2: &f.d1,
            centres: &centres.backward,
            radius,
            p2: &p2_2,
            p1: cfg.sgm.p1,
            outside_cost: cfg.outside_cost,
            epipolar: fundamental.map(|f| epi(f.transpose())),
            half: half_norms.map(|h| &h.0),
            half_penalty: cfg.half_label_penalty / 127.0,
        };
        // the two directions are independent: run them side by side (the geodesic fill is
        // sequential, the rest parallel by rows) unless their cost volumes are large (the
        // ±80 px reference mode: ≈ 4 GB each on a KITTI pair), then one after the other
        let n_labels = (2 * radius + 1) * (2 * radius + 1);
        let volume_bytes = lw * lh * n_labels * VOLUME_BYTES_PER_LABEL;
        let (forward, backward) = if volume_bytes <= SIDE_BY_SIDE_VOLUME_LIMIT {
            rayon::join(
                || volume::match_level(&pb_f, fit),
                || volume::match_level(&pb_b, None),
            )
        } else {
            (
                volume::match_level(&pb_f, fit),
                volume::match_level(&pb_b, None),
            )
        };
        Self { forward, backward }
    }
}

/// The forward–backward check of one level (step 3): the continuous discrepancy of each
/// direction, level px, and which pixels pass `fb_threshold_px`.
struct ConsistencyCheck {
    fb_forward: Vec<f32>,
    keep_forward: Vec<bool>,
    keep_backward: Vec<bool>,
}

impl ConsistencyCheck {
    fn run(cfg: &FlowConfig, m: &LevelMatch, lw: usize, lh: usize) -> Self {
        let (fwd, bwd) = (&m.forward.flow, &m.backward.flow);
        let (fb_f, fb_b) = rayon::join(
            || ops::forward_backward_discrepancy(fwd, bwd, lw, lh),
            || ops::forward_backward_discrepancy(bwd, fwd, lw, lh),
        );
        let keep_forward: Vec<bool> = fb_f.iter().map(|e| *e < cfg.fb_threshold_px).collect();
        let keep_backward: Vec<bool> = fb_b.iter().map(|e| *e < cfg.fb_threshold_px).collect();
        Self {
            fb_forward: fb_f,
            keep_forward,
            keep_backward,
        }
    }
}

/// The filled and median-filtered flows of one level (step 3), and the forward fill distance.
struct FilledFlows {
    forward: Vec<[f32; 2]>,
    backward: Vec<[f32; 2]>,
    fill_distance: Vec<f32>,
}

impl FilledFlows {
    /// Geodesic, edge-aware fill of the removed pixels from the kept ones, then a median
    /// filter. With no match kept there is nothing to fill from: the flow stays the prior (the
    /// windows' centres), not the winners of slices that said nothing. The backward flow is
    /// filled only when `need_backward` (a coarser level's backward flow centres the next
    /// level's windows; at the matching level only the refined backward flow of the uncertainty
    /// model reads it): otherwise it is returned as matched, unread.
    fn run(
        cfg: &FlowConfig,
        flows: (Vec<[f32; 2]>, Vec<[f32; 2]>),
        check: &ConsistencyCheck,
        centres: &Centres,
        (g1, g2): (&[f32], &[f32]),
        (lw, lh): (usize, usize),
        need_backward: bool,
    ) -> Self {
        let prior_if_none_kept = |flow: Vec<[f32; 2]>, keep: &[bool], centres: &[[i32; 2]]| {
            if keep.iter().any(|k| *k) {
                flow
            } else {
                centres.iter().map(|c| [c[0] as f32, c[1] as f32]).collect()
            }
        };
        let (keep_f, keep_b) = (&check.keep_forward, &check.keep_backward);
        let mut flow_f = prior_if_none_kept(flows.0, keep_f, &centres.forward);
        let mut flow_b = prior_if_none_kept(flows.1, keep_b, &centres.backward);
        let mr = cfg.interpolation.median_radius;
        let ((forward, fill_distance), backward) = rayon::join(
            || {
                let fill = interp::geodesic_fill_with_distance(
                    &mut flow_f,
                    keep_f,
                    g1,
                    lw,
                    lh,
                    &cfg.interpolation,
                );
                (ops::median_filter(&flow_f, lw, lh, mr), fill)
            },
            || {
                if !need_backward {
                    return flow_b;
                }
                interp::geodesic_fill(&mut flow_b, keep_b, g2, lw, lh, &cfg.interpolation);
                ops::median_filter(&flow_b, lw, lh, mr)
            },
        );
        Self {
            forward,
            backward,
            fill_distance,
        }
    }
}

/// Stage 2 (steps 2–3): the matching result at the matching level (1/scale resolution).
pub(crate) struct Matching {
    /// Filtered forward flow, level px.
    pub flow: Vec<[f32; 2]>,
    /// Filtered backward flow, level px (as matched, unfiltered, when the uncertainty model
    /// does not refine it: [`ModelWants::backward`]).
    pub backward_flow: Vec<[f32; 2]>,
    /// Forward–backward check of the forward flow (true: kept).
    pub keep: Vec<bool>,
    /// Raw Gaussian fit of eq. 4 to the regularised cost slice (not yet calibrated).
    pub raw_information: Vec<[f32; 3]>,
    /// Second minimum of the slice, `(cost margin, distance)`, when wanted.
    pub second_minimum: Vec<[f32; 2]>,
    /// Variance the slice cannot see, level px²: raw winner to filtered flow, squared, plus
    /// the squared forward–backward discrepancy.
    pub extra_variance: Vec<f32>,
    /// Forward–backward discrepancy of the forward flow, level px (infinite off-image).
    pub fb_discrepancy: Vec<f32>,
    /// Geodesic fill distance, level px.
    pub fill_distance: Vec<f32>,
}

impl Matching {
    /// Coarse to fine over the pyramid: each level's filtered flows, upsampled and rounded,
    /// centre the next level's windows. `None` when the pyramid is empty (cannot happen with
    /// checked inputs).
    pub(crate) fn run(
        cfg: &FlowConfig,
        features: &Features,
        plan: &SearchPlan,
        input: &FlowInput<'_>,
        size: (usize, usize),
        wants: &ModelWants,
    ) -> Option<Self> {
        let mut centres = features.initial_centres(input.prior, size);
        let fit = FitParams {
            radius: cfg.uncertainty.fit_radius,
            threshold: cfg.uncertainty.cost_threshold,
            second_minimum: wants.ambiguity,
        };
        let mut result = None;
        for k in (0..features.levels.len()).rev() {
            let l = &features.levels[k];
            let f = &features.per_level[k];
            let (lw, lh) = (l.img1.width(), l.img1.height());
            let want_fit = (k == 0).then_some(fit);
            let m = LevelMatch::run(
                cfg,
                features,
                k,
                &centres,
                plan.radius,
                input.fundamental,
                want_fit,
            );
            let check = ConsistencyCheck::run(cfg, &m, lw, lh);
            let wta_f = (k == 0).then(|| m.forward.flow.clone());
            let LevelMatch { forward, backward } = m;
            let filled = FilledFlows::run(
                cfg,
                (forward.flow, backward.flow),
                &check,
                &centres,
                (&f.g1, &f.g2),
                (lw, lh),
                k > 0 || wants.backward,
            );
            if k > 0 {
                let nl = &features.levels[k - 1];
                let (nw, nh) = (nl.img1.width(), nl.img1.height());
                let to_centres = |f: &[[f32; 2]]| -> Vec<[i32; 2]> {
                    ops::upsample_flow(f, lw, lh, nw, nh, 2.0, 0.5)
                        .iter()
                        .map(|v| [v[0].round() as i32, v[1].round() as i32])
                        .collect()
                };
                centres = Centres {
                    forward: to_centres(&filled.forward),
                    backward: to_centres(&filled.backward),
                };
            } else {
                result = Some(Self::at_matching_level(
                    wta_f.unwrap_or_default(),
                    filled,
                    check,
                    forward.information,
                    forward.second_minimum,
                ));
            }
        }
        result
    }

    fn at_matching_level(
        wta: Vec<[f32; 2]>,
        filled: FilledFlows,
        check: ConsistencyCheck,
        information: Option<Vec<[f32; 3]>>,
        second_minimum: Option<Vec<[f32; 2]>>,
    ) -> Self {
        // variance the regularised cost slice cannot see: the discrepancy between the raw
        // winner and the filtered flow, and the forward-backward discrepancy
        let extra: Vec<f32> = wta
            .iter()
            .zip(&filled.forward)
            .zip(&check.fb_forward)
            .map(|((a, b), e)| {
                let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                d2 + if e.is_finite() { e * e } else { 0.0 }
            })
            .collect();
        Self {
            flow: filled.forward,
            backward_flow: filled.backward,
            keep: check.keep_forward,
            raw_information: information.unwrap_or_default(),
            second_minimum: second_minimum.unwrap_or_default(),
            extra_variance: extra,
            fb_discrepancy: check.fb_forward,
            fill_distance: filled.fill_distance,
        }
    }
}

/// Stage 3 (step 4): the eq. 4 fit calibrated and made positive definite at the matching level,
/// upsampled to full resolution (covariance ×scale², inverted); the validity mask upsampled.
pub(crate) struct FittedUncertainty {
    /// Information `(Yxx, Yxy, Yyy)`, 1/px², full resolution.
    pub information: Vec<[f32; 3]>,
    /// Forward–backward check result, full resolution (nearest).
    pub valid: Vec<bool>,
}

impl FittedUncertainty {
    pub(crate) fn compute(
        cfg: &FlowConfig,
        m: &Matching,
        level: &LevelGeometry,
        (w, h): (usize, usize),
    ) -> Self {
        let (lw, lh, sc, off) = (level.width, level.height, level.scale, level.offset);
        let info0 = uncertainty::calibrate(
            &m.raw_information,
            &m.extra_variance,
            &m.keep,
            sc,
            &cfg.uncertainty,
        );
        let information =
            uncertainty::upsample_information(&info0, (lw, lh), (w, h), sc, off, &cfg.uncertainty);
        let valid = uncertainty::upsample_valid_nearest(&m.keep, lw, lh, w, h, sc, off);
        Self { information, valid }
    }
}

/// The prefiltered images of the full-resolution refinement ([`refine::prefilter`]), made once
/// for every refinement of a pair (forward, backward, weakly smoothed): at half resolution when
/// the configuration has a half-resolution pass, and at full resolution.
pub(crate) struct RefinementImages {
    half: Option<(GrayImage, GrayImage)>,
    full: (GrayImage, GrayImage),
}

/// One image of [`RefinementImages`]: (half resolution, full resolution).
pub(crate) type RefinementImage = (Option<GrayImage>, GrayImage);

impl RefinementImages {
    /// Both images prefiltered; image 1's from `cached` when given (the image 2 of the previous
    /// pair).
    fn new(
        (img1, img2): (&GrayImage, &GrayImage),
        r: &RefinementConfig,
        cached: Option<RefinementImage>,
    ) -> Self {
        let one = |img: &GrayImage| -> RefinementImage {
            let half = r
                .half_resolution_pass
                .then(|| refine::prefilter_one(&ops::downsample_box(img, 2), r));
            (half, refine::prefilter_one(img, r))
        };
        let (i1, i2) = match cached {
            Some(i1) => (i1, one(img2)),
            None => (one(img1), one(img2)),
        };
        Self {
            half: i1.0.zip(i2.0),
            full: (i1.1, i2.1),
        }
    }

    /// Image 2's prefiltered images, moved out for the next pair of a video.
    pub(crate) fn into_second(self) -> RefinementImage {
        (self.half.map(|(_, h2)| h2), self.full.1)
    }
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

/// The estimator's refinements (the half-resolution variational pass when configured, dense
/// Lucas–Kanade, the full-resolution variational pass, on the prefiltered pair: what
/// [`crate::FlowEstimator`] runs after its matching) started from a full-resolution flow `start` from `img1` to `img2` instead of the
/// matching's: where the refinement goes from a given flow, e.g. the exact one of a rendered
/// pair (the `refine_from_truth` example).
#[must_use]
pub fn refine_from_full_resolution(
    (img1, img2): (&GrayImage, &GrayImage),
    start: &[[f32; 2]],
    cfg: &RefinementConfig,
) -> Vec<[f32; 2]> {
    let images = RefinementImages::new((img1, img2), cfg, None);
    let full_resolution = LevelGeometry {
        width: img1.width(),
        height: img1.height(),
        scale: 1.0,
        offset: 0.0,
    };
    let half = images.half.as_ref().map(|(a, b)| (a, b));
    let (r1, r2) = (&images.full.0, &images.full.1);
    refine_full(half, (r1, r2), start, &full_resolution, cfg)
}

/// The refinement of the uncertainty model's own refinements (backward, weakly smoothed): the
/// flow's, with [`crate::UncertaintyConfig::model_half_resolution_outer`] warps at half
/// resolution when that pass is on.
fn model_refinement(cfg: &FlowConfig) -> RefinementConfig {
    let r = &cfg.refinement;
    RefinementConfig {
        variational_outer: if r.half_resolution_pass {
            cfg.uncertainty.model_half_resolution_outer
        } else {
            r.variational_outer
        },
        ..r.clone()
    }
}

/// Stage 4 (step 5): the refined full-resolution flow, and for the uncertainty model the
/// refined backward flow and the weakly smoothed refinement of the same matching result.
pub(crate) struct Refined {
    /// The prefiltered images (the model measures its residuals on them).
    pub images: RefinementImages,
    /// Refined forward flow, px.
    pub flow: Vec<[f32; 2]>,
    /// Refined backward flow, px, when the model wants it.
    pub backward: Option<Vec<[f32; 2]>>,
    /// The forward matching result refined with a weak smoothness term, when wanted.
    pub weakly_smoothed: Option<Vec<[f32; 2]>>,
}

impl Refined {
    /// The refinements of the pair; image 1's prefiltered images from `cached` when given
    /// ([`RefinementImages::new`]).
    pub(crate) fn run(
        cfg: &FlowConfig,
        pair: (&GrayImage, &GrayImage),
        m: &Matching,
        level: &LevelGeometry,
        wants: &ModelWants,
        cached: Option<RefinementImage>,
    ) -> Self {
        // prefiltered once for all refinements of the pair (the backward one takes them swapped)
        let images = RefinementImages::new(pair, &cfg.refinement, cached);
        let half = images.half.as_ref().map(|(a, b)| (a, b));
        let half_swapped = images.half.as_ref().map(|(a, b)| (b, a));
        let (r1, r2) = (&images.full.0, &images.full.1);
        let flow = refine_full(half, (r1, r2), &m.flow, level, &cfg.refinement);
        // the backward flow is refined after the forward one (side by side, the memory-bound
        // sweeps of the two compete and take longer)
        let backward = wants.backward.then(|| {
            let backward_cfg = RefinementConfig {
                full_resolution_outer: cfg.uncertainty.backward_full_resolution_outer,
                ..model_refinement(cfg)
            };
            refine_full(
                half_swapped,
                (r2, r1),
                &m.backward_flow,
                level,
                &backward_cfg,
            )
        });
        // the same matching result refined again with a weaker smoothness term (the model's
        // smoothness-sensitivity predictor)
        let weakly_smoothed = wants.sensitivity.then(|| {
            // both passes' smoothness weakened in the same ratio
            let weaken = cfg.uncertainty.sensitivity_alpha / cfg.refinement.variational_alpha;
            let weak_cfg = RefinementConfig {
                variational_alpha: cfg.uncertainty.sensitivity_alpha,
                half_resolution_alpha: cfg.refinement.half_resolution_alpha * weaken,
                full_resolution_outer: cfg.uncertainty.sensitivity_full_resolution_outer,
                ..model_refinement(cfg)
            };
            refine_full(half, (r1, r2), &m.flow, level, &weak_cfg)
        });
        Self {
            images,
            flow,
            backward,
            weakly_smoothed,
        }
    }
}

/// Stage 5: the information of the output. With the full model, its terms
/// ([`model::terms`]) replace the eq. 4 fit's information; then the optional residual
/// inflation; and with no match kept at all every pixel gets the maximum uncertainty, as a
/// removed pixel does (§3.2).
pub(crate) struct FinalUncertainty {
    /// Information `(Yxx, Yxy, Yyy)`, 1/px², full resolution.
    pub information: Vec<[f32; 3]>,
    /// The model's terms, when computed.
    pub terms: Option<UncertaintyTerms>,
}

impl FinalUncertainty {
    pub(crate) fn compute(
        cfg: &FlowConfig,
        m: &Matching,
        level: &LevelGeometry,
        information: Vec<[f32; 3]>,
        refined: &Refined,
        want_terms: bool,
    ) -> Self {
        let (r1, r2) = (&refined.images.full.0, &refined.images.full.1);
        let flow = &refined.flow;
        let terms = (want_terms || UncertaintyTerms::model_enabled(&cfg.uncertainty)).then(|| {
            model::terms(
                &model::Inputs {
                    img1: r1,
                    img2: r2,
                    flow,
                    backward_flow: refined.backward.as_deref(),
                    weakly_smoothed_flow: refined.weakly_smoothed.as_deref(),
                    information: &information,
                    fb_level: &m.fb_discrepancy,
                    fill_level: &m.fill_distance,
                    second_minimum_level: &m.second_minimum,
                    keep_level: &m.keep,
                    flow_level: &m.flow,
                    level_width: level.width,
                    level_height: level.height,
                    scale: level.scale,
                    offset: level.offset,
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
            refine::inflate_by_residual(r1, r2, flow, information, &cfg.uncertainty)
        } else {
            information
        };
        // no match survived (flat or unrelated images): the flow is the prior everywhere, a
        // guess, and every pixel gets the maximum uncertainty, as a removed pixel does (§3.2)
        let information = if m.keep.iter().any(|k| *k) {
            information
        } else {
            let mm = cfg.uncertainty.min_information;
            vec![[mm, 0.0, mm]; information.len()]
        };
        Self { information, terms }
    }
}
