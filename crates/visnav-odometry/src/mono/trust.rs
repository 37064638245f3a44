//! Frames the monocular pipeline cannot trust (issue 21 item 3): no texture (a black, white or
//! blank frame), a sudden global change of the image's character (sensor noise instead of a
//! scene: structure at the pixel scale only; a flipped image: it matches the last accepted one
//! better upside down), a dense flow whose forward–backward check removes nearly everything, a
//! flow that no rigid motion explains (a frame of another place: few eight-point inliers, and
//! neither the motion nor the flow of the frames before; [`super::rigidity`]), or a motion
//! inconsistent with the previous one.
//!
//! [`super::MonoOdometry::process`] runs the image tests ([`TrustConfig::min_intensity_std`],
//! [`TrustConfig::min_structure_ratio`], [`TrustConfig::max_flip_gain`]) before anything else,
//! the flow test after the size checks, the rigid-motion test after the eight-point RANSAC and
//! (when configured) the motion test on the estimated pose; a failed test returns
//! [`super::MonoError::UntrustedFrame`] with the [`UntrustedReason`] and a warning, **without
//! changing the odometry's state**: the frame is as if never seen. The documented fallback is
//! the driver's: the frame gets the constant-velocity prediction, and the next frame's flow is
//! computed from the last accepted image.
//!
//! No test compares the image with the last accepted one alone (a plain correlation of the two
//! thumbnails): on small images with fast motion (the 320x96 rendered drive of the CLI tests)
//! consecutive frames correlate at −0.09..0.08, as noise does, and once a frame is refused every
//! later one would be too.
//!
//! Not in the paper (its §5 pipeline assumes a working camera); the thresholds are far from the
//! values of the real KITTI 00 clip (measured in `tests/mono_untrusted.rs`).

use serde::{Deserialize, Serialize};
use visnav_core::GrayImage;
use visnav_flow::DenseFlow;

use super::evidence::{MotionAgreement, RigidMotionEvidence};
use crate::RelativeMotion;

/// Thresholds of the trust tests.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrustConfig {
    /// Run the tests. Default true.
    pub enabled: bool,
    /// Side of the box-downsampled thumbnail the image tests use, pixels. Default 8.
    pub thumbnail_px: usize,
    /// No texture: the thumbnail's intensity standard deviation must reach this, grey levels
    /// (0–255). Default 4 (KITTI 00, 300 frames: at least 60.5; a black or white frame: 0).
    pub min_intensity_std: f64,
    /// Noise-like image: the thumbnail's standard deviation over the full-resolution image's
    /// must reach this (structure beyond the pixel scale; i.i.d. noise averages away in the
    /// thumbnail: 1/8 with 8-px cells). Default 0.35 (KITTI 00, 300 frames: at least 0.933;
    /// uniform noise: 0.13).
    pub min_structure_ratio: f64,
    /// Upside down: the thumbnail flipped vertically must not correlate with the last accepted
    /// image's better than the thumbnail itself by more than this. Default 0.1 (KITTI 00, 300
    /// frames: at most −0.035 for the real frames against the previous one or the one before,
    /// at least 0.248 for their upside-down copies). Only decided when the flipped thumbnail
    /// correlates with the last accepted one by at least `min_flipped_correlation`. Not applied
    /// in aerial mode: a downward view has no up (a rendered nadir flight along a street, whose
    /// two sides look alike, measured a gain of 0.114).
    pub max_flip_gain: f64,
    /// See `max_flip_gain`. Default 0.3 (KITTI 00: at least 0.445 for the upside-down copies;
    /// two unrelated images correlate near 0).
    pub min_flipped_correlation: f64,
    /// Inconsistent flow: the share of pixels passing the forward–backward check must reach
    /// this. Default 0.05.
    pub min_valid_fraction: f64,
    /// No rigid motion (a sudden global change: a frame of another place, a swapped camera):
    /// a frame where the share of the grid correspondences that the eight-point RANSAC's
    /// fundamental matrix explains (§4, eq. 6–12, Mahalanobis inlier test) reaches this is
    /// trusted; below it, only with the evidence of `super::rigidity` (the motion and the
    /// flow of the frames before). The mono analogue of the stereo odometry's
    /// `min_consistent_fraction`. Default 0.25. Measured 2026-11-25: real frames of the KITTI
    /// 00 clip (300) at least 0.344 (median 0.55), rendered drives (4 × 320x96, 2 × 620x188)
    /// at least 0.50; pairs of KITTI 00 frames 40 or 150 frames apart (78 pairs) 0.118–0.175;
    /// but good frames of harder drives go down to 0.12 (issue 53 item 10: KITTI 00 at every
    /// 3rd frame, 65 of 100 frames below 0.25), so the share alone refuses good frames.
    pub min_epipolar_inlier_fraction: f64,
    /// A frame below `min_epipolar_inlier_fraction` is still trusted when its share reaches
    /// this, its motion agrees with the previous accepted frame's
    /// (`max_consistent_rotation_change_rad`, `max_consistent_translation_angle_rad`) and its
    /// flow keeps the usual forward–backward share (`min_consistent_valid_ratio`); see
    /// `super::rigidity`. 1 turns the evidence off (the share alone decides, as before issue
    /// 53). Default 0.1 (measured 2026-12-02: good real frames down to 0.12, foreign frames
    /// 0.121–0.187; `docs/robustness.md`, issue 53 item 10).
    pub min_consistent_inlier_fraction: f64,
    /// See `min_consistent_inlier_fraction`: the largest rotation between the frame's motion
    /// and the previous accepted frame's, radians. Default 0.087 (5°). Measured 2026-12-02:
    /// good real frames below `min_epipolar_inlier_fraction` at most 3.1°; foreign frames from
    /// 1.4° (so the rotation alone does not separate them; a loose bound).
    pub max_consistent_rotation_change_rad: f64,
    /// See `min_consistent_inlier_fraction`: the largest angle between the translation
    /// directions of the frame's motion and of the previous accepted frame's, radians. Default
    /// 0.15 (8.6°). Measured 2026-12-02: good real frames below `min_epipolar_inlier_fraction`
    /// at most 5.9°; foreign frames at least 10.9° (56 frames, 112 tries).
    pub max_consistent_translation_angle_rad: f64,
    /// See `min_consistent_inlier_fraction`: the flow's forward–backward share must reach this
    /// times the median of the last `valid_history_frames` accepted frames'. Default 0.5.
    /// Measured 2026-12-02: good real frames below `min_epipolar_inlier_fraction` at least
    /// 0.67 (0.58 right after a sudden threefold speed-up); foreign frames at most 0.27.
    pub min_consistent_valid_ratio: f64,
    /// See `min_consistent_valid_ratio`. Default 10.
    pub valid_history_frames: usize,
    /// Inconsistent motion: when set, the rotation between the frame's motion and the previous
    /// frame's must not exceed this, radians. Default `None` (off): on the KITTI 00 clip the
    /// change stays below 1°, but on small images with fast turns (the 320x96 rendered drive of
    /// the CLI tests) the estimated rotation changes by 7–12° from one frame to the next, and
    /// after a refused frame the next motion spans two frames, so every later frame would be
    /// refused as well. The image tests above catch the corrupted frames without it.
    /// Measured with `Some(0.1)` (2026-11-25): KITTI 00, 300 frames, byte-identical trajectory
    /// (no frame refused, 1.2817 % / 0.9478); `mono_synthetic` and `mono_untrusted` pass; the
    /// 320x96 drives of visnav-pipeline fail (`policy`: a frame other than the dropped one is
    /// refused; `loop_drive`: odometry steps leave 0.4–3.2 m), so it stays off.
    pub max_rotation_change_rad: Option<f64>,
    /// Restart after a run of refused frames: a frame more than this many frames after the last
    /// accepted one (the image its flow would start from) is not matched against it; the
    /// driver starts a new map there instead ([`super::MonoOdometry::restart`]: its pose the
    /// constant-velocity prediction, the scale from the ground plane again). Without it, a
    /// stretch of unusable frames (a covered lens, a dropout) leaves a reference the camera has
    /// moved far from, and every later frame is refused too. Default 2: one refused or missing
    /// frame is bridged by a flow over two frames, a longer stretch restarts. Measured
    /// 2026-11-26 on the KITTI 00 clip played at every 2nd / 3rd / 4th frame (flows over 2, 3, 4
    /// frames): 110 of 150, 16 of 100 and 5 of 75 frames estimated, the others refused (beyond
    /// the flow's search range), so a flow over three frames is rarely worth its time. Applies
    /// whether or not the tests run (a failed flow, a missing image also leave the reference
    /// behind). Not in the paper.
    pub max_reference_gap_frames: usize,
}

impl Default for TrustConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            thumbnail_px: 8,
            min_intensity_std: 4.0,
            min_structure_ratio: 0.35,
            max_flip_gain: 0.1,
            min_flipped_correlation: 0.3,
            min_valid_fraction: 0.05,
            min_epipolar_inlier_fraction: 0.25,
            min_consistent_inlier_fraction: 0.1,
            max_consistent_rotation_change_rad: 0.087,
            max_consistent_translation_angle_rad: 0.15,
            min_consistent_valid_ratio: 0.5,
            valid_history_frames: 10,
            max_rotation_change_rad: None,
            max_reference_gap_frames: 2,
        }
    }
}

/// Which trust test a frame failed, with the measured value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum UntrustedReason {
    /// The image has no texture (black, white, blank): its thumbnail's intensity standard
    /// deviation, grey levels.
    NoTexture {
        /// Measured standard deviation.
        intensity_std: f64,
    },
    /// The image has structure at the pixel scale only (sensor noise, not a scene): the
    /// thumbnail's standard deviation over the full-resolution image's.
    NoiseLike {
        /// Measured ratio.
        structure_ratio: f64,
    },
    /// The dense flow's forward–backward check kept almost no pixel.
    InconsistentFlow {
        /// Measured share of valid pixels.
        valid_fraction: f64,
    },
    /// The image correlates better with the last accepted one upside down than as it is.
    UpsideDown {
        /// Correlation of the flipped thumbnail minus that of the thumbnail.
        flip_gain: f64,
    },
    /// Too few correspondences fit one rigid motion (the eight-point RANSAC's inlier share).
    NoRigidMotion {
        /// What the test weighed: the inlier share, the motion against the previous frame's,
        /// the flow's forward–backward share against the recent frames'
        /// ([`super::rigidity`]).
        evidence: RigidMotionEvidence,
    },
    /// The estimated rotation departs from the previous frame's motion.
    InconsistentMotion {
        /// Angle between this frame's and the previous frame's rotation, degrees.
        rotation_change_deg: f64,
    },
}

impl UntrustedReason {
    /// `true` for the tests a wrong flow fails (no rigid motion, inconsistent flow), which a
    /// flow with a wider search may pass (`MonoFlowConfig::retry_extra_levels`); `false` for
    /// the image tests and the motion test.
    #[must_use]
    pub fn is_flow_failure(&self) -> bool {
        matches!(
            self,
            Self::NoRigidMotion { .. } | Self::InconsistentFlow { .. }
        )
    }
}

impl std::fmt::Display for UntrustedReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoTexture { intensity_std } => write!(
                f,
                "no texture (intensity standard deviation {intensity_std:.2} grey levels)"
            ),
            Self::NoiseLike { structure_ratio } => write!(
                f,
                "noise-like image (thumbnail to image contrast ratio {structure_ratio:.3})"
            ),
            Self::UpsideDown { flip_gain } => write!(
                f,
                "upside down (flipped, it correlates {flip_gain:.3} better with the last accepted image)"
            ),
            Self::InconsistentFlow { valid_fraction } => write!(
                f,
                "inconsistent flow ({:.1} % of the pixels pass the forward-backward check)",
                100.0 * valid_fraction
            ),
            Self::NoRigidMotion { evidence } => {
                write!(
                    f,
                    "no rigid motion ({:.1} % of the correspondences fit the eight-point model",
                    100.0 * evidence.inlier_fraction()
                )?;
                match evidence.agreement {
                    Some(MotionAgreement {
                        rotation_change_deg: r,
                        translation_angle_deg: Some(t),
                    }) => write!(
                        f,
                        "; its motion turns {r:.1}° from the previous frame's and heads {t:.1}° away"
                    )?,
                    Some(a) => write!(
                        f,
                        "; its motion turns {:.1}° from the previous frame's",
                        a.rotation_change_deg
                    )?,
                    None => write!(f, "; no previous motion to compare with")?,
                }
                match evidence.valid_ratio() {
                    Some(r) => write!(
                        f,
                        "; its flow keeps {:.0} % of the recent frames' forward-backward share)",
                        100.0 * r
                    ),
                    None => write!(f, ")"),
                }
            }
            Self::InconsistentMotion {
                rotation_change_deg,
            } => write!(
                f,
                "inconsistent motion (rotation {rotation_change_deg:.2}° away from the previous frame's)"
            ),
        }
    }
}

/// The image tests' summary of a frame: its zero-mean thumbnail and standard deviation.
#[derive(Debug, Clone, PartialEq)]
pub struct Thumbnail {
    /// Thumbnail width, pixels.
    width: usize,
    /// Thumbnail intensities minus their mean, row-major.
    centred: Vec<f64>,
    /// Standard deviation of the thumbnail, grey levels.
    std: f64,
    /// Standard deviation of the full-resolution image, grey levels.
    image_std: f64,
}

impl Thumbnail {
    /// The box-downsampled thumbnail of `image` (`cfg.thumbnail_px` pixels a side).
    #[must_use]
    pub fn of(image: &GrayImage, cfg: &TrustConfig) -> Self {
        let small = visnav_flow::ops::downsample_box(image, cfg.thumbnail_px.max(1));
        let values: Vec<f64> = small.data().iter().map(|v| f64::from(*v)).collect();
        let n = values.len().max(1) as f64;
        let mean = values.iter().sum::<f64>() / n;
        let centred: Vec<f64> = values.iter().map(|v| v - mean).collect();
        let std = (centred.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        Self {
            width: small.width(),
            centred,
            std,
            image_std: std_of(image.data()),
        }
    }

    /// The thumbnail upside down (rows reversed).
    #[must_use]
    pub fn flipped(&self) -> Self {
        let w = self.width.max(1);
        let centred = self
            .centred
            .chunks(w)
            .rev()
            .flat_map(|row| row.iter().copied())
            .collect();
        Self {
            width: self.width,
            centred,
            std: self.std,
            image_std: self.image_std,
        }
    }

    /// Standard deviation of the thumbnail, grey levels (the no-texture test's measure).
    #[must_use]
    pub fn std(&self) -> f64 {
        self.std
    }

    /// The thumbnail's standard deviation over the full-resolution image's (the noise-like
    /// test's measure; 0 for a flat image).
    #[must_use]
    pub fn structure_ratio(&self) -> f64 {
        if self.image_std > 0.0 {
            self.std / self.image_std
        } else {
            0.0
        }
    }

    /// Normalised cross-correlation with `other` (0 when either is flat or the sizes differ).
    #[must_use]
    pub fn correlation(&self, other: &Self) -> f64 {
        if self.centred.len() != other.centred.len()
            || self.width != other.width
            || self.std <= 0.0
            || other.std <= 0.0
        {
            return 0.0;
        }
        let n = self.centred.len() as f64;
        let cov: f64 = self
            .centred
            .iter()
            .zip(&other.centred)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / n;
        cov / (self.std * other.std)
    }
}

/// Standard deviation of `values`.
fn std_of(values: &[f32]) -> f64 {
    let n = values.len().max(1) as f64;
    let mean = values.iter().map(|v| f64::from(*v)).sum::<f64>() / n;
    (values
        .iter()
        .map(|v| (f64::from(*v) - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Image tests: texture, noise-like structure, then (with a last accepted image) the
/// orientation.
pub(crate) fn check_image(
    thumbnail: &Thumbnail,
    last_accepted: Option<&Thumbnail>,
    cfg: &TrustConfig,
) -> Result<(), UntrustedReason> {
    if !cfg.enabled {
        return Ok(());
    }
    if thumbnail.std.is_nan() || thumbnail.std < cfg.min_intensity_std {
        return Err(UntrustedReason::NoTexture {
            intensity_std: thumbnail.std,
        });
    }
    let structure_ratio = thumbnail.structure_ratio();
    if structure_ratio.is_nan() || structure_ratio < cfg.min_structure_ratio {
        return Err(UntrustedReason::NoiseLike { structure_ratio });
    }
    if let Some(last) = last_accepted {
        let flipped = thumbnail.flipped().correlation(last);
        let flip_gain = flipped - thumbnail.correlation(last);
        if flipped >= cfg.min_flipped_correlation && flip_gain > cfg.max_flip_gain {
            return Err(UntrustedReason::UpsideDown { flip_gain });
        }
    }
    Ok(())
}

/// Flow test: the share of forward–backward consistent pixels.
pub(crate) fn check_flow(flow: &DenseFlow, cfg: &TrustConfig) -> Result<(), UntrustedReason> {
    let valid_fraction = flow.valid_fraction();
    if cfg.enabled && valid_fraction < cfg.min_valid_fraction {
        return Err(UntrustedReason::InconsistentFlow { valid_fraction });
    }
    Ok(())
}

/// Motion test: the rotation of the frame's `motion` against the previous frame's.
pub(crate) fn check_motion(
    motion: &RelativeMotion,
    last_motion: Option<&RelativeMotion>,
    cfg: &TrustConfig,
) -> Result<(), UntrustedReason> {
    let (Some(last), Some(max), true) = (last_motion, cfg.max_rotation_change_rad, cfg.enabled)
    else {
        return Ok(());
    };
    let change =
        (last.cur_from_prev().rotation.inverse() * motion.cur_from_prev().rotation).angle();
    if change.is_nan() || change > max {
        return Err(UntrustedReason::InconsistentMotion {
            rotation_change_deg: change.to_degrees(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use visnav_core::Pose;

    use super::*;

    fn textured(w: usize, h: usize, flip: bool) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let y = if flip { h - 1 - y } else { y };
            // a gradient from sky to road plus texture
            (40.0 + 150.0 * y as f64 / h as f64 + 30.0 * ((x as f64 * 0.05).sin())) as f32
        })
    }

    #[test]
    fn flat_noise_and_upside_down_frames_fail_the_image_tests() {
        let cfg = TrustConfig::default();
        let a = Thumbnail::of(&textured(320, 96, false), &cfg);
        assert_eq!(check_image(&a, None, &cfg), Ok(()));
        assert_eq!(check_image(&a, Some(&a), &cfg), Ok(()));
        for v in [0.0, 255.0] {
            let flat = Thumbnail::of(&GrayImage::from_fn(320, 96, |_, _| v), &cfg);
            assert!(matches!(
                check_image(&flat, Some(&a), &cfg),
                Err(UntrustedReason::NoTexture { .. })
            ));
        }
        let flipped = Thumbnail::of(&textured(320, 96, true), &cfg);
        match check_image(&flipped, Some(&a), &cfg) {
            Err(UntrustedReason::UpsideDown { flip_gain }) => assert!(flip_gain > 1.0),
            other => panic!("{other:?}"),
        }
        // without a last accepted image there is nothing to be upside down against
        assert_eq!(check_image(&flipped, None, &cfg), Ok(()));
        // uniform i.i.d. noise: contrast at the pixel scale only (1/8 of it left in 8-px cells)
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let noise = Thumbnail::of(
            &GrayImage::from_fn(320, 96, |_, _| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state % 256) as f32
            }),
            &cfg,
        );
        match check_image(&noise, Some(&a), &cfg) {
            Err(UntrustedReason::NoiseLike { structure_ratio }) => {
                assert!((0.08..0.2).contains(&structure_ratio), "{structure_ratio}");
            }
            other => panic!("{other:?}"),
        }
        let off = TrustConfig {
            enabled: false,
            ..cfg
        };
        assert_eq!(check_image(&flipped, Some(&a), &off), Ok(()));
    }

    #[test]
    fn a_rotation_jump_is_an_inconsistent_motion() {
        let cfg = TrustConfig {
            max_rotation_change_rad: Some(0.1),
            ..TrustConfig::default()
        };
        let step = RelativeMotion::from_cur_from_prev(Pose::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, 1.0),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.01, 0.0),
        ));
        assert_eq!(check_motion(&step, None, &cfg), Ok(()));
        assert_eq!(check_motion(&step, Some(&step), &cfg), Ok(()));
        let jump = RelativeMotion::from_cur_from_prev(Pose::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, 1.0),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.2, 0.0),
        ));
        match check_motion(&jump, Some(&step), &cfg) {
            Err(UntrustedReason::InconsistentMotion {
                rotation_change_deg,
            }) => assert!((rotation_change_deg - 0.19_f64.to_degrees()).abs() < 1e-6),
            other => panic!("{other:?}"),
        }
        // off by default
        assert_eq!(
            check_motion(&jump, Some(&step), &TrustConfig::default()),
            Ok(())
        );
    }

    #[test]
    fn a_flow_the_forward_backward_check_removed_is_inconsistent() {
        let cfg = TrustConfig::default();
        let flow = |valid_every: usize| DenseFlow {
            width: 10,
            height: 10,
            flow: vec![[1.0, 0.0]; 100],
            information: vec![[1.0, 0.0, 1.0]; 100],
            valid: (0..100).map(|i| i % valid_every == 0).collect(),
        };
        // 2 % valid: refused; 50 %: kept
        match check_flow(&flow(50), &cfg) {
            Err(UntrustedReason::InconsistentFlow { valid_fraction }) => {
                assert!((valid_fraction - 0.02).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(check_flow(&flow(2), &cfg), Ok(()));
        let off = TrustConfig {
            enabled: false,
            ..cfg
        };
        assert_eq!(check_flow(&flow(50), &off), Ok(()));
    }
}
