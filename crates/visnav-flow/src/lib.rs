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
//! `visnav_geometry::tracks::fundamental_from_tracks` estimates the fundamental matrix for the
//! epipolar cost from Shi–Tomasi corners tracked by KLT and the normalised eight-point algorithm.
//!
//! Coordinates: pixel centres at integers; flow `(u, v)` maps `(x, y)` in image 1 to
//! `(x + u, y + v)` in image 2, in pixels.
//!
//! The fast flow ([`FastFlow`], dense inverse search with the same output) on a texture moved
//! by two pixels; every pixel gets its flow and a positive-definite 2x2 information matrix:
//!
//! ```
//! use visnav_core::GrayImage;
//! use visnav_flow::{FastFlow, FastFlowConfig};
//!
//! let texture = |x: f32, y: f32| 128.0 + 50.0 * (0.21 * x).sin() * (0.17 * y).cos() + 30.0 * (0.11 * x + 0.07 * y).sin();
//! let img1 = GrayImage::from_fn(96, 64, |x, y| texture(x as f32, y as f32));
//! let img2 = GrayImage::from_fn(96, 64, |x, y| texture(x as f32 - 2.0, y as f32));
//! let flow = FastFlow::new(FastFlowConfig::default())?.compute(&img1, &img2)?;
//! let centre = 32 * 96 + 48;
//! assert!((flow.flow[centre][0] - 2.0).abs() < 0.1 && flow.flow[centre][1].abs() < 0.1);
//! let [yxx, yxy, yyy] = flow.information[centre];
//! assert!(yxx > 0.0 && yxx * yyy - yxy * yxy > 0.0);
//! # Ok::<(), visnav_flow::FlowError>(())
//! ```

pub mod config;
pub mod descriptor;
pub mod error;
pub mod fast;
pub mod interp;
pub mod model;
pub mod ops;
pub mod refine;
mod stages;
/// Synthetic image pairs with exact flow, for tests, calibration examples and benchmarks: compiled
/// only with the `test-support` feature (dev-dependencies enable it), not the library's API.
#[cfg(any(test, feature = "test-support"))]
pub mod synthetic;
pub mod uncertainty;
pub mod volume;

use std::sync::Mutex;
use std::time::Instant;

use nalgebra::Matrix3;
use visnav_core::{GrayImage, Information2};

pub use config::{
    EpipolarConfig, FlowConfig, InterpolationConfig, RefinementConfig, SearchMode, SgmConfig,
    UncertaintyConfig, VarianceModel,
};
pub use error::FlowError;
pub use fast::{FastFlow, FastFlowConfig, FastUncertaintyConfig};
pub use stages::refine_from_full_resolution;
pub use uncertainty::UncertaintyTerms;

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
    /// `(Yxx, Yxy, Yyy)` per pixel, 1/px² (the layout of [`Information2::to_array`];
    /// [`DenseFlow::information_at`] gives the typed matrix).
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

    /// The information matrix (eq. 1) at pixel index `i`, 1/px².
    #[must_use]
    #[inline]
    pub fn information_at(&self, i: usize) -> Information2 {
        Information2::from_array(self.information[i])
    }

    /// Covariance `(Pxx, Pxy, Pyy)` at pixel index `i`, px² (the inverse of the information;
    /// infinite variances where it is singular).
    #[must_use]
    pub fn covariance(&self, i: usize) -> [f32; 3] {
        self.information_at(i)
            .covariance_px2()
            .unwrap_or([f32::INFINITY, 0.0, f32::INFINITY])
    }

    /// Squared Mahalanobis distance (eq. 1) of a flow error `(du, dv)` at pixel index `i`
    /// (`f32` arithmetic).
    #[must_use]
    pub fn mahalanobis_sq(&self, i: usize, du: f32, dv: f32) -> f32 {
        self.information_at(i).mahalanobis_sq(du, dv)
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

impl std::ops::AddAssign for FlowTimings {
    /// Stage by stage: the time of two computations of one frame (a retry after the first).
    fn add_assign(&mut self, other: Self) {
        self.features_ms += other.features_ms;
        self.matching_ms += other.matching_ms;
        self.uncertainty_ms += other.uncertainty_ms;
        self.refinement_ms += other.refinement_ms;
        self.total_ms += other.total_ms;
    }
}

/// The flow stage: holds its configuration and, when asked for
/// ([`FlowEstimator::with_image_cache`]), what it computed of the last pair's second image.
#[derive(Debug)]
pub struct FlowEstimator {
    config: FlowConfig,
    /// `None`: no caching; `Some(None)`: caching, nothing kept yet.
    cache: Option<Mutex<Option<ImageCache>>>,
}

/// What the flow keeps of the second image of a pair for the next pair, which starts from it
/// (a video): the image itself (the key: the next first image must equal it exactly), the pyramid
/// depth it was built for, its matching features and its prefiltered refinement images.
struct ImageCache {
    image: GrayImage,
    levels: usize,
    features: stages::ImageFeatures,
    refinement: stages::RefinementImage,
}

impl ImageCache {
    /// Whether the kept image is `img`: the same size and the same pixels (a flat image of
    /// another shape with as many pixels is not).
    fn is_of(&self, img: &GrayImage) -> bool {
        self.image.width() == img.width()
            && self.image.height() == img.height()
            && self.image.data() == img.data()
    }
}

impl std::fmt::Debug for ImageCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageCache")
            .field("width", &self.image.width())
            .field("height", &self.image.height())
            .field("levels", &self.levels)
            .finish_non_exhaustive()
    }
}

impl Clone for FlowEstimator {
    /// The same configuration and caching, with nothing kept yet.
    fn clone(&self) -> Self {
        Self {
            config: self.config.clone(),
            cache: self.cache.as_ref().map(|_| Mutex::new(None)),
        }
    }
}

/// Which dense flow algorithm.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlowMethod {
    /// The paper's flow (Ng, Li, Kim 2021 §3 on DCFlow): [`FlowEstimator`]. The default.
    #[default]
    Paper,
    /// Dense inverse search with the alignment's own uncertainty, built for speed:
    /// [`FastFlow`].
    Fast,
}

/// Either flow algorithm behind one call (the `--method` of the CLI's flow commands).
#[derive(Debug, Clone)]
pub enum AnyFlow {
    /// The paper's flow (boxed: its configuration is large).
    Paper(Box<FlowEstimator>),
    /// The fast flow.
    Fast(FastFlow),
}

impl AnyFlow {
    /// Dense flow from `img1` to `img2` with the time per stage. The fast flow takes neither a
    /// fundamental matrix nor a prior (they are ignored).
    ///
    /// # Errors
    /// As [`FlowEstimator::compute`] and [`FastFlow::compute`].
    pub fn compute_timed(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
    ) -> Result<(DenseFlow, FlowTimings), FlowError> {
        match self {
            Self::Paper(e) => e.compute_timed(img1, img2, input),
            Self::Fast(f) => f.compute_timed(img1, img2),
        }
    }

    /// The method.
    #[must_use]
    pub fn method(&self) -> FlowMethod {
        match self {
            Self::Paper(_) => FlowMethod::Paper,
            Self::Fast(_) => FlowMethod::Fast,
        }
    }
}

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
        Ok(Self {
            config,
            cache: None,
        })
    }

    /// Keeps what the flow computed of each pair's second image (its features and prefiltered
    /// images, about 5 % of a pair's work) and reuses it when the next pair's first image is
    /// the same image (compared exactly), as in a video: the same flow, computed faster.
    #[must_use]
    pub fn with_image_cache(mut self) -> Self {
        self.cache = Some(Mutex::new(None));
        self
    }

    /// The kept second image of the last pair when `img1` is that image and its features have
    /// `levels` pyramid levels.
    fn cached(&self, img1: &GrayImage, levels: usize) -> Option<ImageCache> {
        let mut guard = self.cache.as_ref()?.lock().ok()?;
        let c = guard.take()?;
        (c.levels == levels && c.is_of(img1)).then_some(c)
    }

    /// Whether the kept second image of the last pair is `img` (same size, same pixels; always
    /// false without [`Self::with_image_cache`]): a pair starting from `img` reuses its features
    /// unless its search needs a different pyramid depth (a prior given to one pair only).
    #[must_use]
    pub fn keeps(&self, img: &GrayImage) -> bool {
        self.cache
            .as_ref()
            .and_then(|c| c.lock().ok())
            .is_some_and(|g| g.as_ref().is_some_and(|c| c.is_of(img)))
    }

    fn keep(&self, cache: ImageCache) {
        if let Some(Ok(mut guard)) = self.cache.as_ref().map(Mutex::lock) {
            *guard = Some(cache);
        }
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

    /// The pipeline of the module docs as named stages ([`stages`]): input check, features
    /// (step 1), matching (steps 2–3), calibrated cost-slice uncertainty (step 4, eq. 1–4),
    /// refinement (step 5) and the full uncertainty model.
    fn run(
        &self,
        img1: &GrayImage,
        img2: &GrayImage,
        input: &FlowInput<'_>,
        want_terms: bool,
    ) -> Result<(DenseFlow, FlowTimings, Option<UncertaintyTerms>), FlowError> {
        let cfg = &self.config;
        let t_start = Instant::now();
        let (w, h) = stages::check_inputs(cfg, img1, img2, input)?;
        let min_side = cfg.scale * 8;
        let plan = stages::SearchPlan::new(cfg, input);
        let keep = self.cache.is_some();
        let (cached_features, cached_refinement) = self
            .cached(img1, plan.levels)
            .map(|c| (c.features, c.refinement))
            .unzip();
        let features = stages::Features::build(cfg, (img1, img2), plan.levels, cached_features);
        let features_ms = ms(t_start);

        let t_match = Instant::now();
        let wants = stages::ModelWants::new(cfg, want_terms);
        let matching = stages::Matching::run(cfg, &features, &plan, input, (w, h), &wants);
        let matching_ms = ms(t_match);
        let Some(matching) = matching else {
            return Err(FlowError::TooSmall {
                width: w,
                height: h,
                min: min_side,
            });
        };
        let level = features.matching_level();
        // image 2's features move to the cache for the next pair (no copy); image 1's are freed
        let kept_features = keep.then(|| features.into_second());

        let t_unc = Instant::now();
        let fitted = stages::FittedUncertainty::compute(cfg, &matching, &level, (w, h));
        let uncertainty_ms = ms(t_unc);

        let t_ref = Instant::now();
        let refined = stages::Refined::run(
            cfg,
            (img1, img2),
            &matching,
            &level,
            &wants,
            cached_refinement,
        );
        let refinement_ms = ms(t_ref);

        let t_model = Instant::now();
        let stages::FinalUncertainty { information, terms } = stages::FinalUncertainty::compute(
            cfg,
            &matching,
            &level,
            fitted.information,
            &refined,
            want_terms,
        );
        let uncertainty_ms = uncertainty_ms + ms(t_model);
        let stages::Refined { images, flow, .. } = refined;
        if let Some(features) = kept_features {
            self.keep(ImageCache {
                image: img2.clone(),
                levels: plan.levels,
                features,
                refinement: images.into_second(),
            });
        }
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
                valid: fitted.valid,
            },
            timings,
            terms,
        ))
    }
}
