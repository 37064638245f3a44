//! The fast dense flow: dense inverse search (DIS; Kroeger, Timofte, Dai, Van Gool, *Fast
//! Optical Flow using Dense Inverse Search*, ECCV 2016) with a per-pixel bivariate Gaussian
//! uncertainty from the same alignment. Built for the real-time monocular preset; the same
//! [`crate::DenseFlow`] output as the paper's flow ([`crate::FlowEstimator`]), so every consumer
//! works unchanged.
//!
//! Per pyramid level, coarse to fine (box-downsampled by 2; level `l` pixel `i` sits at
//! `2^l i + (2^l − 1)/2` at full resolution):
//!
//! 1. patches on a regular grid of image 1, each started from the coarser level's flow at its
//!    centre and aligned into image 2 by inverse-compositional Gauss–Newton with the Hessian
//!    precomputed on the template (DIS eq. 1–2, [`patches`]);
//! 2. densification: per pixel the residual-weighted mean of the covering patches' flows (DIS
//!    eq. 3, [`densify`]);
//! 3. a short variational refinement (DIS §2.3, the paper flow's [`crate::refine::variational`]).
//!
//! Below `finest_level` the flow is upsampled and refined variationally only. The uncertainty
//! (on the finest patch level): each patch's flow is Gaussian with covariance `σ² H⁻¹` — its
//! Gauss–Newton Hessian over its residual variance, the information of eq. 1 of Ng, Li, Kim
//! 2021 with the patch alignment's curvature in place of the cost slice's — densified as the
//! moment-matched mixture of the covering patches (with the same weights as the flow), plus the
//! squared distance the variational refinement moved the flow, then scaled by a global
//! calibration, floored, and clamped to a positive-definite eigenvalue range as in §3.2.
//!
//! Every stage runs row-parallel with per-row arithmetic independent of the others, so the flow
//! is bit-identical for any thread count.

pub mod config;
pub mod densify;
pub mod patches;

use std::time::Instant;

use rayon::prelude::*;
use visnav_core::{GrayImage, Information2};

pub use config::{FastFlowConfig, FastUncertaintyConfig};

use crate::config::RefinementConfig;
use crate::ops::{downsample_box, gradients, resample_field, sample_field, upsample_flow};
use crate::{DenseFlow, FlowError, FlowTimings};
use patches::{LevelImages, Padded, PatchGrid};

/// Replicated border of image 2 beyond a patch's side, pixels: a patch displaced up to this far
/// past the image is sampled with one set of weights over contiguous rows; farther out it takes
/// the clamped path (the same values, about ten times the work). On KITTI the flow at the left
/// and right borders reaches tens of pixels, so a border of a few pixels sent many patches down
/// the clamped path (callgrind, KITTI 00 pair 100–101: 103 M instructions in the sampling with
/// 4 px, see docs/benchmarks.md).
const BORDER_PX: usize = 64;

/// The fast flow stage (see the module docs).
#[derive(Debug, Clone)]
pub struct FastFlow {
    config: FastFlowConfig,
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The box pyramids of both images: level 0 the images themselves (borrowed), the coarser
/// levels owned.
struct Pyramids<'a> {
    base: (&'a GrayImage, &'a GrayImage),
    coarser: Vec<(GrayImage, GrayImage)>,
}

impl<'a> Pyramids<'a> {
    fn build(img1: &'a GrayImage, img2: &'a GrayImage, coarsest: usize) -> Self {
        let mut coarser: Vec<(GrayImage, GrayImage)> = Vec::with_capacity(coarsest);
        for _ in 1..=coarsest {
            let (a, b) = coarser.last().map_or((img1, img2), |(a, b)| (a, b));
            let level = rayon::join(|| downsample_box(a, 2), || downsample_box(b, 2));
            coarser.push(level);
        }
        Self {
            base: (img1, img2),
            coarser,
        }
    }

    /// Both images at level `l`.
    fn level(&self, l: usize) -> (&GrayImage, &GrayImage) {
        match l {
            0 => self.base,
            _ => {
                let (a, b) = &self.coarser[l - 1];
                (a, b)
            }
        }
    }

    /// `(width, height)` of level `l`.
    fn size(&self, l: usize) -> (usize, usize) {
        let a = self.level(l).0;
        (a.width(), a.height())
    }
}

/// What the patch levels leave: the flow and its covariance at the finest patch level.
struct PatchLevels {
    flow: Vec<[f32; 2]>,
    covariance: Vec<[f32; 3]>,
}

impl FastFlow {
    /// A fast flow stage with a validated configuration.
    ///
    /// # Errors
    /// [`FlowError::InvalidConfig`] naming the field out of range.
    pub fn new(config: FastFlowConfig) -> Result<Self, FlowError> {
        config.validate()?;
        Ok(Self { config })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &FastFlowConfig {
        &self.config
    }

    /// The coarsest level for a `w` x `h` image: the deepest (at least `finest_level`) whose
    /// width holds `coarsest_patches_across` patches and whose height holds one.
    #[must_use]
    pub fn coarsest_level(&self, w: usize, h: usize) -> usize {
        let c = &self.config;
        let mut l = c.finest_level;
        while (w >> (l + 1)) >= c.coarsest_patches_across * c.patch_size
            && (h >> (l + 1)) >= c.patch_size
        {
            l += 1;
        }
        l
    }

    /// Dense flow from `img1` to `img2` with its uncertainty, at full resolution.
    ///
    /// # Errors
    /// Different image sizes, or images too small for one patch at the finest patch level.
    pub fn compute(&self, img1: &GrayImage, img2: &GrayImage) -> Result<DenseFlow, FlowError> {
        self.compute_timed(img1, img2).map(|(f, _)| f)
    }

    /// As [`Self::compute`], with the time per stage (`features_ms`: pyramids; `matching_ms`:
    /// patch alignment and densification; `refinement_ms`: the variational passes;
    /// `uncertainty_ms`: the covariance's upsampling and calibration).
    ///
    /// # Errors
    /// As [`Self::compute`].
    pub fn compute_timed(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
    ) -> Result<(DenseFlow, FlowTimings), FlowError> {
        let c = &self.config;
        let t_start = Instant::now();
        let (w, h) = FlowError::check_sizes(img1, img2, c.patch_size << c.finest_level)?;
        let coarsest = self.coarsest_level(w, h);
        let pyr = Pyramids::build(img1, img2, coarsest);
        let mut timings = FlowTimings {
            features_ms: ms(t_start),
            ..FlowTimings::default()
        };
        let levels = self.patch_levels(&pyr, coarsest, &mut timings);
        let (flow, covariance) = self.to_full_resolution(&pyr, levels, &mut timings);
        let t_unc = Instant::now();
        let information = self.calibrated_information(&covariance);
        let valid = flow
            .par_iter()
            .enumerate()
            .map(|(i, f)| {
                let (x, y) = ((i % w) as f32 + f[0], (i / w) as f32 + f[1]);
                x >= 0.0 && y >= 0.0 && x <= (w - 1) as f32 && y <= (h - 1) as f32
            })
            .collect();
        timings.uncertainty_ms += ms(t_unc);
        timings.total_ms = ms(t_start);
        Ok((
            DenseFlow {
                width: w,
                height: h,
                flow,
                information,
                valid,
            },
            timings,
        ))
    }

    /// The variational refinement's settings with `outer` re-warping iterations.
    fn refinement(&self, outer: usize) -> RefinementConfig {
        let c = &self.config;
        RefinementConfig {
            variational_outer: outer,
            variational_inner: c.variational_inner,
            variational_alpha: c.variational_alpha,
            gradient_normalisation: 0.0,
            sor_omega: 1.0,
            ..RefinementConfig::odometry()
        }
    }

    /// Steps 1–3 of the module docs from the coarsest level down to `finest_level`; the
    /// finest level's densified covariance with the refinement's move added (level px²).
    fn patch_levels(&self, pyr: &Pyramids, coarsest: usize, t: &mut FlowTimings) -> PatchLevels {
        let c = &self.config;
        let (cw, ch) = pyr.size(coarsest);
        let mut flow = vec![[0.0_f32; 2]; cw * ch];
        let mut covariance = Vec::new();
        for l in (c.finest_level..=coarsest).rev() {
            let t_match = Instant::now();
            let (i1, i2) = pyr.level(l);
            let (w, h) = (i1.width(), i1.height());
            if l < coarsest {
                let (pw, ph) = pyr.size(l + 1);
                flow = upsample_flow(&flow, pw, ph, w, h, 2.0, 0.5);
            }
            let (gx, gy) = gradients(i1);
            let grid = PatchGrid::new(w, h, c.patch_size, c.patch_stride);
            let start: Vec<[f32; 2]> = (0..grid.len())
                .map(|k| {
                    let [x, y] = grid.centre(k % grid.xs.len(), k / grid.xs.len());
                    sample_field(&flow, w, h, x, y)
                })
                .collect();
            let padded = Padded::new(i2, c.patch_size + BORDER_PX);
            let lv = LevelImages {
                img1: i1,
                gx: &gx,
                gy: &gy,
                img2: &padded,
            };
            let fits = patches::align(&lv, &grid, &start, c);
            let finest = l == c.finest_level;
            let dense = densify::densify(i1, i2, &grid, &fits, finest.then_some(&c.uncertainty));
            flow = dense.flow;
            t.matching_ms += ms(t_match);
            let t_ref = Instant::now();
            let outer = if finest {
                c.finest_variational_outer
            } else {
                c.variational_outer
            };
            if outer > 0 {
                let before = finest.then(|| flow.clone());
                crate::refine::variational(i1, i2, &mut flow, &self.refinement(outer));
                if let Some(before) = before {
                    covariance = dense.covariance;
                    self.add_refinement_move(&mut covariance, &before, &flow);
                }
            } else if finest {
                covariance = dense.covariance;
            }
            t.refinement_ms += ms(t_ref);
        }
        PatchLevels { flow, covariance }
    }

    /// Adds `refinement_weight · |after − before|²` (px²) to each pixel's variances.
    fn add_refinement_move(
        &self,
        covariance: &mut [[f32; 3]],
        before: &[[f32; 2]],
        after: &[[f32; 2]],
    ) {
        let k = self.config.uncertainty.refinement_weight;
        for ((c, b), a) in covariance.iter_mut().zip(before).zip(after) {
            let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
            c[0] += k * d2;
            c[2] += k * d2;
        }
    }

    /// From the finest patch level to full resolution: the flow upsampled (×2 a level) and
    /// refined variationally at each level, the covariance upsampled (×4 a level, resampled as
    /// a covariance) with the refinement's move added.
    fn to_full_resolution(
        &self,
        pyr: &Pyramids,
        levels: PatchLevels,
        t: &mut FlowTimings,
    ) -> (Vec<[f32; 2]>, Vec<[f32; 3]>) {
        let c = &self.config;
        let PatchLevels {
            mut flow,
            mut covariance,
        } = levels;
        for l in (0..c.finest_level).rev() {
            let t_unc = Instant::now();
            let (i1, i2) = pyr.level(l);
            let (w, h) = (i1.width(), i1.height());
            let (pw, ph) = pyr.size(l + 1);
            // a level pixel is two finer pixels: covariance ×4
            covariance = resample_field(&covariance, (pw, ph), (w, h), 2.0, 0.5, 4.0);
            t.uncertainty_ms += ms(t_unc);
            let t_ref = Instant::now();
            flow = upsample_flow(&flow, pw, ph, w, h, 2.0, 0.5);
            if c.upsampled_outer > 0 {
                let before = flow.clone();
                crate::refine::variational(i1, i2, &mut flow, &self.refinement(c.upsampled_outer));
                self.add_refinement_move(&mut covariance, &before, &flow);
            }
            t.refinement_ms += ms(t_ref);
        }
        (flow, covariance)
    }

    /// The calibrated information per pixel (1/px²): `(calibration · Σ + floor · I)⁻¹`, its
    /// eigenvalues clamped to `[min_information, max_information]` (§3.2 of Ng, Li, Kim 2021).
    fn calibrated_information(&self, covariance: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let u = &self.config.uncertainty;
        let worst = Information2::new(u.min_information, 0.0, u.min_information);
        covariance
            .par_iter()
            .map(|s| {
                let cov = [
                    u.calibration * s[0] + u.floor_px2,
                    u.calibration * s[1],
                    u.calibration * s[2] + u.floor_px2,
                ];
                let y = Information2::from_covariance_px2(cov).unwrap_or(worst);
                // most pixels need no clamping: keep them as inverted, skipping the eigen
                // decomposition (which would recompose the same matrix up to rounding)
                if y.eigenvalues_within(u.min_information, u.max_information) {
                    y.to_array()
                } else {
                    y.clamp_eigenvalues(u.min_information, u.max_information)
                        .to_array()
                }
            })
            .collect()
    }
}
