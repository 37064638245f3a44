//! The loop-closure stage (§5, last paragraph, of Ng, Li and Kim 2021) of the monocular pipeline
//! and, with the depth maps of its stereo features, of the stereo one (issue #25: the same
//! stages, the PnP points triangulated by the stereo matcher; [`LoopConfig::stereo`]).
//!
//! [`LoopCloser::process`] takes each frame of the run after the odometry:
//!
//! 1. the frame becomes a vertex of the pose graph ([`LoopGraph`]), linked to the previous one by
//!    the odometry motion (noise model [`OdometryNoise`]);
//! 2. [`CandidateSearch`] proposes, every `every_n_frames` frames, at most three earlier frames
//!    within `max_distance_m` of the current (corrected) position, at least `min_index_gap`
//!    frames older, with thumbnail SSIM ≥ 0.38;
//! 3. only for those candidates: dense flow with uncertainty from the earlier image to the
//!    current one (visnav-flow); the candidate is **accepted only when more than
//!    `min_reliable_fraction` (20 %) of the pixels are reliable** — valid and with flow standard
//!    deviation at most `max_flow_sigma_px` ([`reliable_fraction`]);
//! 4. the relative pose comes from the monocular motion estimation with its small-motion rules
//!    ([`visnav_odometry::mono::relative_pose_from_flow`]: PnP against the earlier frame's fused
//!    depth map, fused with the eight-point when there is parallax); its information is the PnP
//!    Hessian, floored by `loop_sigma_floor_*` (flow errors of neighbouring pixels are correlated,
//!    so the raw Hessian is over-confident); with `min_pnp_inlier_fraction` set (stereo: 0.5), a
//!    closure whose PnP explains fewer of its correspondences is rejected;
//! 5. each accepted closure enters the graph, which is optimised (robust kernel on by default,
//!    [`GraphConfig`]); the corrected poses replace the current ones and later frames continue
//!    from them.
//!
//! A candidate that fails verification is logged and reported as rejected; every frame keeps
//! exactly one pose.

use std::time::Instant;

use nalgebra::{Matrix6, Vector6};
use serde::{Deserialize, Serialize};
use visnav_core::{GrayImage, Information2, PinholeCamera, Pose};
use visnav_flow::{DenseFlow, FlowConfig, FlowEstimator, FlowInput};
use visnav_graph::GraphConfig;
use visnav_odometry::mono::{DepthMap, MonoConfig, PoseSource, relative_pose_from_flow};

use crate::graph::{LoopGraph, OdometryNoise};
use crate::{CandidateConfig, CandidateSearch, LoopError};

/// Configuration of [`LoopCloser`]; defaults from §5 of the paper where it gives them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Candidate search (every 10 frames, SSIM ≥ 0.38, at most 3).
    pub candidates: CandidateConfig,
    /// Thumbnails for the SSIM are box-downsampled to at most this width, pixels. Default 160.
    pub thumbnail_max_width_px: usize,
    /// A pixel's flow is reliable when it is valid and the larger standard deviation of its
    /// covariance is at most this, pixels. The paper leaves the value open; default 1.0.
    pub max_flow_sigma_px: f64,
    /// A candidate is verified only when more than this share of all pixels is reliable.
    /// Paper: 0.2 (20 %).
    pub min_reliable_fraction: f64,
    /// Noise model of the odometry edges.
    pub odometry_noise: OdometryNoise,
    /// Smallest translation standard deviation per axis of a loop-closure edge, metres (added in
    /// quadrature to the PnP covariance). Default 0.05.
    pub loop_sigma_floor_m: f64,
    /// Smallest rotation standard deviation per axis of a loop-closure edge, radians. Default
    /// 0.002.
    pub loop_sigma_floor_rad: f64,
    /// A closure is accepted only when at least this share of its PnP correspondences are
    /// inliers of its pose. Default 0 (off: the monocular figures were measured without it);
    /// the stereo loop closure's default ([`LoopConfig::stereo`]) is 0.5.
    pub min_pnp_inlier_fraction: f64,
    /// The pose-graph optimiser (robust GNC Geman–McClure kernel on loop closures by default).
    pub graph: GraphConfig,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            candidates: CandidateConfig::default(),
            thumbnail_max_width_px: 160,
            max_flow_sigma_px: 1.0,
            min_reliable_fraction: 0.2,
            odometry_noise: OdometryNoise::default(),
            loop_sigma_floor_m: 0.05,
            loop_sigma_floor_rad: 0.002,
            min_pnp_inlier_fraction: 0.0,
            // GNC (Geman–McClure): the pairwise-consistency default of `visnav-graph` needs two
            // mutually consistent closures within its window, while the mono pipeline adds them a
            // few at a time; the loop-closure figures in docs/benchmarks.md were measured with GNC
            graph: GraphConfig {
                robust: visnav_graph::RobustKernel::GncGemanMcClure,
                ..GraphConfig::default()
            },
        }
    }
}

impl LoopConfig {
    /// The defaults of the stereo loop closure: those of [`LoopConfig::default`] with
    /// `min_pnp_inlier_fraction` 0.5. A stereo frame's depth map has a point per tracked
    /// feature only (about a hundred PnP correspondences at 620x188), and in a city of repeated
    /// facades a wrong candidate passes the reliable-pixel rule and PnP's 10 inliers often
    /// (synthetic 2,000-frame loop drive, candidates up to 50 m apart: 418 wrong closures
    /// accepted, with 10–29 inliers of 47–109 correspondences, at most 42 %); a true revisit's
    /// points mostly agree with its pose.
    #[must_use]
    pub fn stereo() -> Self {
        Self {
            min_pnp_inlier_fraction: 0.5,
            ..Self::default()
        }
    }

    /// Checks the fields.
    ///
    /// # Errors
    /// [`LoopError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), LoopError> {
        self.candidates.validate()?;
        let invalid = |field, message: String| Err(LoopError::InvalidConfig { field, message });
        if self.thumbnail_max_width_px < 8 {
            return invalid(
                "thumbnail_max_width_px",
                format!("must be >= 8, got {}", self.thumbnail_max_width_px),
            );
        }
        let positive = [
            ("max_flow_sigma_px", self.max_flow_sigma_px),
            (
                "odometry_noise.rotation_rad",
                self.odometry_noise.rotation_rad,
            ),
            ("loop_sigma_floor_m", self.loop_sigma_floor_m),
            ("loop_sigma_floor_rad", self.loop_sigma_floor_rad),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return invalid(field, format!("must be finite and > 0, got {v}"));
            }
        }
        let n = &self.odometry_noise;
        if !(n.translation_fraction >= 0.0
            && n.translation_floor_m > 0.0
            && n.translation_fraction.is_finite()
            && n.translation_floor_m.is_finite())
        {
            return invalid(
                "odometry_noise.translation_floor_m",
                format!(
                    "translation_fraction must be >= 0 and translation_floor_m > 0, got {} and {}",
                    n.translation_fraction, n.translation_floor_m
                ),
            );
        }
        if !(0.0..=1.0).contains(&self.min_pnp_inlier_fraction) {
            return invalid(
                "min_pnp_inlier_fraction",
                format!("must be in [0, 1], got {}", self.min_pnp_inlier_fraction),
            );
        }
        if !(0.0..1.0).contains(&self.min_reliable_fraction) {
            return invalid(
                "min_reliable_fraction",
                format!("must be in [0, 1), got {}", self.min_reliable_fraction),
            );
        }
        self.graph.validate().map_err(|e| LoopError::InvalidConfig {
            field: "graph",
            message: e.to_string(),
        })
    }
}

/// Share of all pixels of `flow` that are reliable: valid, with the larger standard deviation of
/// the flow covariance (inverse of the information matrix, eq. 1) at most `max_sigma_px`.
#[must_use]
pub fn reliable_fraction(flow: &DenseFlow, max_sigma_px: f64) -> f64 {
    if flow.valid.is_empty() {
        return 0.0;
    }
    let max_var = max_sigma_px * max_sigma_px;
    let reliable = (0..flow.valid.len())
        .filter(|&i| flow.valid[i])
        .filter(|&i| {
            // the larger eigenvalue of the covariance (a symmetric 2x2 like the information)
            let [largest, _] = Information2::from_array(flow.covariance(i)).eigenvalues();
            largest.is_finite() && largest <= max_var
        })
        .count();
    reliable as f64 / flow.valid.len() as f64
}

/// The acceptance rule of §5: more than `min_fraction` of the pixels reliable.
#[must_use]
pub fn flow_is_reliable(flow: &DenseFlow, max_sigma_px: f64, min_fraction: f64) -> bool {
    reliable_fraction(flow, max_sigma_px) > min_fraction
}

/// The known cells of a [`DepthMap`] (grid, then `(cell, depth_m, variance_m2)`): what the
/// closer keeps of every frame. A stereo frame's map has a cell per tracked feature on a
/// fine grid, mostly unknown, so keeping whole maps over a long run would cost gigabytes.
#[derive(Debug, Clone, PartialEq)]
struct KnownDepth {
    stride: usize,
    cols: usize,
    rows: usize,
    /// `(cell, depth, variance, offset of the point from the cell's pixel)`.
    cells: Vec<(u32, f32, f32, [f32; 2])>,
}

impl KnownDepth {
    fn of(map: &DepthMap) -> Self {
        let cells = (0..map.depth_m.len())
            .filter(|&i| map.depth_m[i].is_finite())
            .filter_map(|i| {
                let cell = u32::try_from(i).ok()?;
                Some((cell, map.depth_m[i], map.variance_m2[i], map.offset_px[i]))
            })
            .collect();
        Self {
            stride: map.stride,
            cols: map.cols,
            rows: map.rows,
            cells,
        }
    }

    fn map(&self) -> DepthMap {
        let mut map = DepthMap {
            stride: self.stride,
            cols: self.cols,
            rows: self.rows,
            depth_m: vec![f32::NAN; self.cols * self.rows],
            variance_m2: vec![f32::NAN; self.cols * self.rows],
            offset_px: vec![[0.0; 2]; self.cols * self.rows],
        };
        for &(i, d, v, o) in &self.cells {
            map.depth_m[i as usize] = d;
            map.variance_m2[i as usize] = v;
            map.offset_px[i as usize] = o;
        }
        map
    }
}

/// The relative pose of an accepted (or pose-checked) closure, for reports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct ClosurePose {
    /// Translation of `later_from_earlier`, metres.
    pub translation_m: [f64; 3],
    /// Its rotation angle, degrees.
    pub rotation_deg: f64,
    /// Which estimator produced it (`pnp` or `fused`).
    pub source: PoseSource,
    /// PnP inliers.
    pub pnp_inliers: usize,
    /// PnP correspondences (known depth and valid flow), inliers or not.
    #[serde(default)]
    pub pnp_correspondences: usize,
}

/// The outcome of one verified candidate.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ClosureReport {
    /// The current frame (position in the run).
    pub step: usize,
    /// The earlier frame (position in the run).
    pub candidate: usize,
    /// SSIM of the thumbnails.
    pub ssim: f64,
    /// Distance between the two position estimates at the search, metres.
    pub distance_m: f64,
    /// Share of reliable pixels (None when the flow failed).
    pub reliable_fraction: Option<f64>,
    /// Share of valid (forward–backward consistent) pixels.
    pub valid_fraction: Option<f64>,
    /// The relative pose `later_from_earlier` (None when not estimated).
    pub relative_pose: Option<ClosurePose>,
    /// Whether the closure entered the pose graph.
    pub accepted: bool,
    /// Whether the robust optimiser set this closure aside (in the latest optimisation that saw it).
    pub rejected_by_graph: bool,
    /// Why the candidate was rejected.
    pub reason: Option<String>,
    /// Time for the flow and the pose, milliseconds.
    pub verify_ms: f64,
}

/// What [`LoopCloser::process`] returns for a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopStep {
    /// The frame's position in the run.
    pub step: usize,
    /// The corrected pose of the frame (after this frame's optimisation, if any).
    pub world_from_cam: Pose,
    /// The candidates verified at this frame.
    pub closures: Vec<ClosureReport>,
    /// Whether the graph was optimised at this frame.
    pub optimised: bool,
}

/// The loop-closure stage (see the module docs). It owns the pose graph (one vertex a frame,
/// the odometry's motions as its edges), the keyframes' thumbnails and depth maps; the driver
/// (`visnav-pipeline`) owns the odometry and the images ([`Self::process`]'s `load`).
///
/// # Examples
///
/// A drive past four different places and back to the first one: the search proposes the
/// revisit, and only it; without depth maps the closure cannot be verified (its PnP needs the
/// points of one of the two frames), so it is reported, rejected, and the odometry stands.
///
/// ```
/// use visnav_core::{GrayImage, PinholeCamera, Pose};
/// use visnav_flow::FlowConfig;
/// use visnav_loop::{CandidateConfig, LoopCloser, LoopConfig};
/// use visnav_odometry::mono::MonoConfig;
///
/// // a textured 64x48 view of place `p`: different places look different
/// let view = |p: f64| {
///     GrayImage::from_fn(64, 48, |x, y| {
///         let (x, y) = (x as f64, y as f64);
///         let v = 127.5
///             + 60.0 * (x * (0.3 + 0.07 * p) + p).sin() * (y * (0.25 + 0.05 * p) - p).cos()
///             + 40.0 * ((x + y) * (0.11 + 0.03 * p)).sin();
///         v as f32
///     })
/// };
/// let images: Vec<GrayImage> = [0.0, 1.0, 2.0, 3.0, 0.0].into_iter().map(view).collect();
/// let camera = PinholeCamera::new(60.0, 60.0, 31.5, 23.5, 64, 48)?;
/// // search at every frame, among the frames at least 3 older (the paper: every 10th, 50)
/// let candidates = CandidateConfig {
///     every_n_frames: 1,
///     min_index_gap: 3,
///     ..CandidateConfig::default()
/// };
/// let config = LoopConfig {
///     candidates,
///     ..LoopConfig::default()
/// };
/// let mono = MonoConfig::default();
/// let mut closer = LoopCloser::new(camera, config, mono, FlowConfig::default())?;
/// let forward = Pose::translation(0.0, 0.0, 1.0); // the odometry: 1 m forward a frame
/// let load = |k: usize| Ok::<_, String>(images[k].clone());
/// for (k, image) in images.iter().enumerate() {
///     let step = closer.process(Some(image), &forward, None, load)?;
///     if k < 4 {
///         assert!(step.closures.is_empty(), "frame {k}: {:?}", step.closures);
///         continue;
///     }
///     // frame 4 sees place 0 again: frame 0 is proposed and verified
///     let [closure] = step.closures.as_slice() else {
///         panic!("one candidate at the revisit, got {:?}", step.closures);
///     };
///     assert_eq!((closure.step, closure.candidate), (4, 0));
///     assert!(closure.ssim > 0.99);
///     assert!(!closure.accepted);
///     assert!(closure.reason.as_deref().unwrap().contains("no depth map"));
/// }
/// // no closure entered the graph: the poses are the odometry's, 4 m ahead at the end
/// assert_eq!(closer.optimisations(), 0);
/// let last = closer.corrected_poses()[4];
/// assert!((last.translation.vector.z - 4.0).abs() < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct LoopCloser {
    config: LoopConfig,
    mono: MonoConfig,
    camera: PinholeCamera,
    flow: FlowEstimator,
    search: CandidateSearch,
    graph: LoopGraph,
    /// Depth map of every frame in its own camera, its known cells only (None when unknown).
    depth: Vec<Option<KnownDepth>>,
    /// Odometry-only poses.
    odometry: Vec<Pose>,
    /// All verified candidates and, for accepted ones, their graph edge.
    closures: Vec<(ClosureReport, Option<usize>)>,
    optimisations: usize,
}

impl LoopCloser {
    /// A stage for `camera`; `mono` and `flow` configure the verification (the run's own
    /// configurations).
    ///
    /// # Errors
    /// [`LoopError::InvalidConfig`] for an invalid configuration.
    pub fn new(
        camera: PinholeCamera,
        config: LoopConfig,
        mono: MonoConfig,
        flow: FlowConfig,
    ) -> Result<Self, LoopError> {
        config.validate()?;
        mono.validate().map_err(|e| LoopError::InvalidConfig {
            field: "mono",
            message: e.to_string(),
        })?;
        let flow = FlowEstimator::new(flow).map_err(|e| LoopError::InvalidConfig {
            field: "flow",
            message: e.to_string(),
        })?;
        Ok(Self {
            search: CandidateSearch::new(config.candidates.clone())?,
            config,
            mono,
            camera,
            flow,
            graph: LoopGraph::new(),
            depth: Vec::new(),
            odometry: Vec::new(),
            closures: Vec::new(),
            optimisations: 0,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &LoopConfig {
        &self.config
    }

    /// The thumbnail of an image for the SSIM: box-downsampled to at most
    /// `thumbnail_max_width_px` wide.
    #[must_use]
    pub fn thumbnail(&self, image: &GrayImage) -> GrayImage {
        let s = image
            .width()
            .div_ceil(self.config.thumbnail_max_width_px)
            .max(1);
        visnav_flow::ops::downsample_box(image, s)
    }

    /// Processes the next frame of the run.
    ///
    /// * `image`: the frame's image (`None` when it could not be read: the frame gets a vertex
    ///   but is never a candidate);
    /// * `prev_from_cur`: the odometry motion from the previous frame (ignored for the first);
    /// * `depth`: the frame's fused depth map in its own camera (the odometry's), if any;
    /// * `load`: loads the image of an earlier frame (position in the run) for verification.
    ///
    /// # Errors
    /// [`LoopError::ThumbnailSize`] when the image size changes within the run. Failed
    /// verifications are not errors: they are logged and reported as rejected closures.
    pub fn process<E: std::fmt::Display>(
        &mut self,
        image: Option<&GrayImage>,
        prev_from_cur: &Pose,
        depth: Option<&DepthMap>,
        mut load: impl FnMut(usize) -> Result<GrayImage, E>,
    ) -> Result<LoopStep, LoopError> {
        let info = self.config.odometry_noise.information(prev_from_cur);
        let step = self.graph.push_odometry(prev_from_cur, info);
        let odometry = match self.odometry.last() {
            Some(prev) => prev * prev_from_cur,
            None => Pose::identity(),
        };
        self.odometry.push(odometry);
        self.depth.push(depth.map(KnownDepth::of));
        let mut closures = Vec::new();
        let mut optimised = false;
        if let Some(image) = image {
            let position = self
                .graph
                .pose(step)
                .map_or_else(nalgebra::Vector3::zeros, |p| p.translation.vector);
            let thumbnail = self.thumbnail(image);
            let candidates = self.search.process(step, thumbnail, position)?;
            let mut accepted_any = false;
            for c in candidates {
                let (report, edge) = self.verify(step, image, c, &mut load);
                accepted_any |= edge.is_some();
                closures.push(self.closures.len());
                self.closures.push((report, edge));
            }
            if accepted_any {
                optimised = self.optimise(step);
            }
        }
        Ok(LoopStep {
            step,
            world_from_cam: self.graph.pose(step).unwrap_or_else(Pose::identity),
            closures: closures
                .into_iter()
                .map(|i| self.closures[i].0.clone())
                .collect(),
            optimised,
        })
    }

    /// Flow, acceptance rule and relative pose of one candidate; the graph edge when accepted.
    fn verify<E: std::fmt::Display>(
        &mut self,
        step: usize,
        image: &GrayImage,
        c: crate::Candidate,
        load: &mut impl FnMut(usize) -> Result<GrayImage, E>,
    ) -> (ClosureReport, Option<usize>) {
        let t = Instant::now();
        let mut report = ClosureReport {
            step,
            candidate: c.frame,
            ssim: c.ssim,
            distance_m: c.distance_m,
            reliable_fraction: None,
            valid_fraction: None,
            relative_pose: None,
            accepted: false,
            rejected_by_graph: false,
            reason: None,
            verify_ms: 0.0,
        };
        let outcome = self.verify_inner(image, c.frame, load, &mut report);
        report.verify_ms = t.elapsed().as_secs_f64() * 1e3;
        match outcome {
            Ok(edge) => {
                report.accepted = true;
                log::info!(
                    "loop closure {} -> {step} accepted (SSIM {:.3}, {:.1} % reliable pixels)",
                    c.frame,
                    c.ssim,
                    100.0 * report.reliable_fraction.unwrap_or(0.0)
                );
                (report, Some(edge))
            }
            Err(reason) => {
                log::info!(
                    "loop closure {} -> {step} rejected: {reason} (SSIM {:.3})",
                    c.frame,
                    c.ssim
                );
                report.reason = Some(reason);
                (report, None)
            }
        }
    }

    fn verify_inner<E: std::fmt::Display>(
        &mut self,
        image: &GrayImage,
        earlier: usize,
        load: &mut impl FnMut(usize) -> Result<GrayImage, E>,
        report: &mut ClosureReport,
    ) -> Result<usize, String> {
        // PnP needs a depth map: the earlier frame's (flow earlier → current); when it has none
        // (e.g. the first frame of the run), the current frame's (flow current → earlier, the
        // pose inverted)
        let step = report.step;
        let (depth, reversed) = match (
            self.depth.get(earlier).and_then(Option::as_ref),
            self.depth.get(step).and_then(Option::as_ref),
        ) {
            (Some(d), _) => (d.map(), false),
            (None, Some(d)) => (d.map(), true),
            (None, None) => return Err(format!("frames {earlier} and {step} have no depth map")),
        };
        let earlier_image = load(earlier).map_err(|e| format!("loading frame {earlier}: {e}"))?;
        let (first, second) = if reversed {
            (image, &earlier_image)
        } else {
            (&earlier_image, image)
        };
        let flow = self
            .flow
            .compute(first, second, &FlowInput::default())
            .map_err(|e| format!("flow: {e}"))?;
        let reliable = reliable_fraction(&flow, self.config.max_flow_sigma_px);
        report.reliable_fraction = Some(reliable);
        report.valid_fraction = Some(flow.valid_fraction());
        if reliable <= self.config.min_reliable_fraction {
            return Err(format!(
                "{:.1} % reliable pixels, need more than {:.1} %",
                100.0 * reliable,
                100.0 * self.config.min_reliable_fraction
            ));
        }
        let seed = ((earlier as u64) << 32) | step as u64;
        let rel = relative_pose_from_flow(&self.camera, &self.mono, &flow, &depth, seed)
            .map_err(|e| format!("relative pose: {e}"))?
            .ok_or_else(|| "no relative pose (PnP failed)".to_string())?;
        // the graph edge measures earlier_from_later; its residual covariance is the PnP one for
        // a pose later_from_earlier, and the one moved by the adjoint of the PnP pose otherwise
        let (later_from_earlier, pnp_information) = if reversed {
            let ad = visnav_graph::lie::adjoint(&rel.second_from_first);
            (
                rel.second_from_first.inverse(),
                ad.transpose() * rel.information * ad,
            )
        } else {
            (rel.second_from_first, rel.information)
        };
        report.relative_pose = Some(ClosurePose {
            translation_m: later_from_earlier.translation.vector.into(),
            rotation_deg: later_from_earlier.rotation.angle().to_degrees(),
            source: rel.source,
            pnp_inliers: rel.pnp_inliers,
            pnp_correspondences: rel.pnp_correspondences,
        });
        let inlier_fraction = rel.pnp_inliers as f64 / rel.pnp_correspondences.max(1) as f64;
        if inlier_fraction < self.config.min_pnp_inlier_fraction {
            return Err(format!(
                "{} of {} PnP correspondences inliers ({:.1} %), need {:.1} %",
                rel.pnp_inliers,
                rel.pnp_correspondences,
                100.0 * inlier_fraction,
                100.0 * self.config.min_pnp_inlier_fraction
            ));
        }
        let information = self.loop_information(&pnp_information);
        self.graph
            .add_loop(earlier, report.step, &later_from_earlier, information)
            .ok_or_else(|| "invalid vertex".to_string())
    }

    /// The PnP information with the covariance floor added (in quadrature).
    fn loop_information(&self, pnp_information: &Matrix6<f64>) -> Matrix6<f64> {
        let ft = self.config.loop_sigma_floor_m.powi(2);
        let fr = self.config.loop_sigma_floor_rad.powi(2);
        let floor = Matrix6::from_diagonal(&Vector6::new(ft, ft, ft, fr, fr, fr));
        let covariance = pnp_information
            .try_inverse()
            .filter(|c| c.iter().all(|v| v.is_finite()))
            .map_or(floor * 1e6, |c| c + floor);
        covariance
            .try_inverse()
            .unwrap_or_else(|| Matrix6::from_diagonal(&floor.diagonal().map(|v| 1.0 / v)))
    }

    /// Optimises the graph; on failure the poses stay as they are (logged).
    fn optimise(&mut self, step: usize) -> bool {
        let t = Instant::now();
        match self.graph.optimise(&self.config.graph) {
            Ok(solution) => {
                self.optimisations += 1;
                for (report, edge) in &mut self.closures {
                    if let Some(e) = edge {
                        report.rejected_by_graph = solution.rejected_edges.contains(e);
                    }
                }
                for (i, p) in self.graph.poses().iter().enumerate() {
                    self.search.update_position(i, p.translation.vector);
                }
                log::info!(
                    "pose graph at frame {step}: {} vertices, {} edges, {} closures set aside, χ² {:.3} -> {:.3}, {:.0} ms",
                    self.graph.len(),
                    self.graph.graph().edges.len(),
                    solution.rejected_edges.len(),
                    solution.initial.chi2,
                    solution.final_inliers.chi2,
                    t.elapsed().as_secs_f64() * 1e3
                );
                true
            }
            Err(e) => {
                log::warn!("pose graph at frame {step}: {e}; poses left uncorrected");
                false
            }
        }
    }

    /// The corrected poses of all frames so far (`world_from_cam`, one per frame).
    #[must_use]
    pub fn corrected_poses(&self) -> Vec<Pose> {
        self.graph.poses()
    }

    /// The odometry-only poses of all frames so far.
    #[must_use]
    pub fn odometry_poses(&self) -> &[Pose] {
        &self.odometry
    }

    /// Every verified candidate so far, in order.
    #[must_use]
    pub fn closures(&self) -> Vec<ClosureReport> {
        self.closures.iter().map(|(r, _)| r.clone()).collect()
    }

    /// Number of graph optimisations run.
    #[must_use]
    pub fn optimisations(&self) -> usize {
        self.optimisations
    }

    /// The pose graph.
    #[must_use]
    pub fn graph(&self) -> &LoopGraph {
        &self.graph
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10x10 flow whose pixel `i` has isotropic standard deviation `sigma(i)` px and validity
    /// `valid(i)`.
    fn flow_with(sigma: impl Fn(usize) -> f32, valid: impl Fn(usize) -> bool) -> DenseFlow {
        let n = 100;
        DenseFlow {
            width: 10,
            height: 10,
            flow: vec![[0.0, 0.0]; n],
            information: (0..n)
                .map(|i| {
                    let y = 1.0 / (sigma(i) * sigma(i));
                    [y, 0.0, y]
                })
                .collect(),
            valid: (0..n).map(valid).collect(),
        }
    }

    #[test]
    fn acceptance_needs_more_than_a_fifth_of_reliable_pixels() {
        let cfg = LoopConfig::default();
        let (sigma_px, share) = (cfg.max_flow_sigma_px, cfg.min_reliable_fraction);
        // 25 % of the pixels certain (σ = 0.5 px), the rest uncertain (σ = 3 px): accepted
        let flow = flow_with(|i| if i < 25 { 0.5 } else { 3.0 }, |_| true);
        assert!((reliable_fraction(&flow, sigma_px) - 0.25).abs() < 1e-12);
        assert!(flow_is_reliable(&flow, sigma_px, share));
        // exactly 20 % is not more than 20 %: rejected
        let flow = flow_with(|i| if i < 20 { 0.5 } else { 3.0 }, |_| true);
        assert!(!flow_is_reliable(&flow, sigma_px, share));
        // certain but invalid (failed forward–backward check) pixels do not count
        let flow = flow_with(|_| 0.5, |i| i % 10 == 0);
        assert!((reliable_fraction(&flow, sigma_px) - 0.1).abs() < 1e-12);
        assert!(!flow_is_reliable(&flow, sigma_px, share));
        // the larger axis of an anisotropic covariance decides: σx = 0.5 px, σy = 2 px
        let mut flow = flow_with(|_| 0.5, |_| true);
        for info in &mut flow.information {
            info[2] = 1.0 / 4.0;
        }
        assert!(reliable_fraction(&flow, sigma_px) < 1e-12);
        assert!(reliable_fraction(&flow, 2.0) > 0.99);
        // a singular information matrix (infinite covariance) is unreliable
        let flow = flow_with(|_| f32::INFINITY, |_| true);
        assert!(reliable_fraction(&flow, sigma_px) < 1e-12);
    }

    #[test]
    fn known_depth_keeps_exactly_the_known_cells() {
        let mut map = DepthMap::empty(40, 30, 4);
        map.set(3, 7.5, 0.25);
        map.set(55, 12.0, 1.0);
        let known = KnownDepth::of(&map);
        assert_eq!(known.cells.len(), 2);
        let back = known.map();
        assert_eq!((back.stride, back.cols, back.rows), (4, 10, 8));
        assert_eq!(back.known(), 2);
        assert_eq!(back.get(3), Some((7.5, 0.25)));
        assert_eq!(back.get(55), Some((12.0, 1.0)));
        assert_eq!(back.get(4), None);
    }

    #[test]
    fn config_defaults_serde_and_validation() {
        let cfg = LoopConfig::default();
        assert_eq!(cfg.candidates.every_n_frames, 10);
        assert!((cfg.candidates.min_ssim - 0.38).abs() < 1e-12);
        assert_eq!(cfg.candidates.max_candidates, 3);
        assert!((cfg.min_reliable_fraction - 0.2).abs() < 1e-12);
        assert_eq!(
            cfg.graph.robust,
            visnav_graph::RobustKernel::GncGemanMcClure
        );
        assert!(cfg.validate().is_ok());
        let parsed: LoopConfig =
            serde_json::from_str(r#"{"candidates":{"min_index_gap":5},"max_flow_sigma_px":2.0}"#)
                .unwrap();
        assert_eq!(parsed.candidates.min_index_gap, 5);
        assert_eq!(parsed.candidates.every_n_frames, 10);
        assert!(serde_json::from_str::<LoopConfig>(r#"{"nope":1}"#).is_err());
        let bad = LoopConfig {
            min_reliable_fraction: 1.5,
            ..LoopConfig::default()
        };
        assert!(matches!(
            bad.validate(),
            Err(LoopError::InvalidConfig {
                field: "min_reliable_fraction",
                ..
            })
        ));
        let bad = LoopConfig {
            max_flow_sigma_px: f64::NAN,
            ..LoopConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
