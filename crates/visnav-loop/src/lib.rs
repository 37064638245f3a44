//! Loop closure of visnav: candidate search by position and SSIM (§5 of Ng, Li and Kim 2021).
//!
//! [`CandidateSearch`] keeps, for every keyframe, a thumbnail and the estimated camera position.
//! Every `every_n_frames` frames it proposes loop-closure candidates for the current frame: earlier
//! keyframes within `max_distance_m` of the current position estimate and at least
//! `min_index_gap` frames older, whose SSIM (Wang et al. 2004, [`visnav_image::ssim`]) with the
//! current thumbnail is at least `min_ssim` (0.38 in the paper), keeping at most `max_candidates`
//! (three) with the highest SSIM.
//!
//! [`LoopCloser`] ([`closer`]) is the whole stage of the monocular pipeline: candidate search,
//! verification by dense flow with uncertainty (more than 20 % reliable pixels), relative pose by
//! the monocular motion estimation, and the pose graph ([`graph`]) optimised with a robust kernel.

pub mod closer;
pub mod graph;

pub use closer::{
    ClosurePose, ClosureReport, LoopCloser, LoopConfig, LoopStep, flow_is_reliable,
    reliable_fraction,
};
pub use graph::{LoopGraph, OdometryNoise};

use nalgebra::Vector3;
use visnav_core::GrayImage;

/// Errors of the loop-closure stage.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum LoopError {
    /// A configuration field is out of range.
    #[error("invalid config field `{field}`: {message}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A thumbnail's size differs from the first one's.
    #[error("thumbnail of frame {frame} is {got_w}x{got_h}, expected {expected_w}x{expected_h}")]
    ThumbnailSize {
        /// Frame index.
        frame: usize,
        /// Expected width.
        expected_w: usize,
        /// Expected height.
        expected_h: usize,
        /// Actual width.
        got_w: usize,
        /// Actual height.
        got_h: usize,
    },
}

/// Configuration of the candidate search; defaults from §5 of the paper where it gives them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CandidateConfig {
    /// Search every this many frames. Paper: 10.
    pub every_n_frames: usize,
    /// Earlier keyframes must lie within this distance of the current position, metres.
    /// Not given numerically in the paper; default 20 m.
    pub max_distance_m: f64,
    /// Earlier keyframes must be at least this many frames older. Default 50 frames.
    pub min_index_gap: usize,
    /// Minimum SSIM between thumbnails. Paper: 0.38.
    pub min_ssim: f64,
    /// At most this many candidates, best SSIM first. Paper: 3.
    pub max_candidates: usize,
}

impl Default for CandidateConfig {
    fn default() -> Self {
        Self {
            every_n_frames: 10,
            max_distance_m: 20.0,
            min_index_gap: 50,
            min_ssim: 0.38,
            max_candidates: 3,
        }
    }
}

impl CandidateConfig {
    /// Checks the fields.
    ///
    /// # Errors
    /// [`LoopError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), LoopError> {
        let invalid = |field, message: String| Err(LoopError::InvalidConfig { field, message });
        if self.every_n_frames == 0 {
            return invalid("every_n_frames", "must be >= 1".into());
        }
        if self.max_distance_m.is_nan() || self.max_distance_m < 0.0 {
            return invalid(
                "max_distance_m",
                format!("must be >= 0, got {}", self.max_distance_m),
            );
        }
        if self.min_ssim.is_nan() || !(-1.0..=1.0).contains(&self.min_ssim) {
            return invalid(
                "min_ssim",
                format!("must be in [-1, 1], got {}", self.min_ssim),
            );
        }
        Ok(())
    }
}

/// One proposed loop closure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Frame index of the earlier keyframe.
    pub frame: usize,
    /// SSIM between the two thumbnails.
    pub ssim: f64,
    /// Distance between the two position estimates, metres.
    pub distance_m: f64,
}

/// A stored keyframe.
#[derive(Debug, Clone)]
struct Keyframe {
    frame: usize,
    thumbnail: GrayImage,
    position_in_world_m: Vector3<f64>,
}

/// Keeps keyframe thumbnails and positions and proposes loop-closure candidates.
#[derive(Debug, Clone)]
pub struct CandidateSearch {
    config: CandidateConfig,
    keyframes: Vec<Keyframe>,
}

impl CandidateSearch {
    /// A search with no keyframe yet.
    ///
    /// # Errors
    /// [`LoopError::InvalidConfig`] for an invalid configuration.
    pub fn new(config: CandidateConfig) -> Result<Self, LoopError> {
        config.validate()?;
        Ok(Self {
            config,
            keyframes: Vec::new(),
        })
    }

    /// Number of stored keyframes.
    #[must_use]
    pub fn len(&self) -> usize {
        self.keyframes.len()
    }

    /// Whether no keyframe is stored.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.keyframes.is_empty()
    }

    /// Updates the position estimate of a stored frame (after a pose-graph correction).
    pub fn update_position(&mut self, frame: usize, position_in_world_m: Vector3<f64>) {
        if let Some(k) = self.keyframes.iter_mut().find(|k| k.frame == frame) {
            k.position_in_world_m = position_in_world_m;
        }
    }

    /// Stores frame `frame` and, on every `every_n_frames`-th frame, returns its candidates
    /// (best SSIM first; empty on other frames).
    ///
    /// # Errors
    /// [`LoopError::ThumbnailSize`] when the thumbnail's size differs from the first one's.
    pub fn process(
        &mut self,
        frame: usize,
        thumbnail: GrayImage,
        position_in_world_m: Vector3<f64>,
    ) -> Result<Vec<Candidate>, LoopError> {
        if let Some(first) = self.keyframes.first() {
            let (w, h) = (first.thumbnail.width(), first.thumbnail.height());
            if thumbnail.width() != w || thumbnail.height() != h {
                return Err(LoopError::ThumbnailSize {
                    frame,
                    expected_w: w,
                    expected_h: h,
                    got_w: thumbnail.width(),
                    got_h: thumbnail.height(),
                });
            }
        }
        let mut candidates = Vec::new();
        if frame.checked_rem(self.config.every_n_frames) == Some(0) {
            for k in &self.keyframes {
                if k.frame + self.config.min_index_gap > frame {
                    continue;
                }
                let distance_m = (k.position_in_world_m - position_in_world_m).norm();
                if distance_m > self.config.max_distance_m {
                    continue;
                }
                let Some(score) = visnav_image::ssim::ssim(&thumbnail, &k.thumbnail) else {
                    continue;
                };
                if score >= self.config.min_ssim {
                    candidates.push(Candidate {
                        frame: k.frame,
                        ssim: score,
                        distance_m,
                    });
                }
            }
            candidates.sort_by(|a, b| b.ssim.total_cmp(&a.ssim));
            candidates.truncate(self.config.max_candidates);
        }
        self.keyframes.push(Keyframe {
            frame,
            thumbnail,
            position_in_world_m,
        });
        Ok(candidates)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured thumbnail that depends on `place` (distinct places look different).
    fn place_image(place: usize, shift: f64) -> GrayImage {
        let p = place as f64;
        GrayImage::from_fn(40, 30, |x, y| {
            let (x, y) = (x as f64 + shift, y as f64);
            let v = 127.5
                + 60.0 * ((x * (0.3 + 0.07 * p)) + p).sin() * ((y * (0.25 + 0.05 * p)) - p).cos()
                + 40.0 * ((x + y) * (0.11 + 0.03 * p)).sin();
            #[allow(clippy::cast_possible_truncation)]
            let v = v as f32;
            v
        })
    }

    /// A drive around a loop of 100 frames, revisited from frame 100 on: frame k shows place
    /// k / 10 (mod 10) at position on a circle. Candidates appear only on revisits, only every 10
    /// frames, only for frames at least 50 older, best first, at most three.
    #[test]
    fn proposes_revisits_only() {
        let mut search = CandidateSearch::new(CandidateConfig::default()).unwrap();
        let mut found = Vec::new();
        for frame in 0..160 {
            let phi = std::f64::consts::TAU * (frame % 100) as f64 / 100.0;
            let position = Vector3::new(30.0 * phi.cos(), 30.0 * phi.sin(), 0.0);
            let place = (frame % 100) / 10;
            let shift = (frame % 10) as f64 * 0.3;
            let c = search
                .process(frame, place_image(place, shift), position)
                .unwrap();
            if frame % 10 != 0 {
                assert!(c.is_empty());
            }
            if frame < 100 {
                assert!(c.is_empty(), "frame {frame}: {c:?}");
            }
            if !c.is_empty() {
                assert!(c.len() <= 3);
                assert!(c.windows(2).all(|w| w[0].ssim >= w[1].ssim));
                for cand in &c {
                    assert!(cand.frame + 50 <= frame);
                    assert!(cand.distance_m <= 20.0);
                    assert!(cand.ssim >= 0.38);
                    // SSIM keeps out nearby keyframes of a different place.
                    assert_eq!((cand.frame % 100) / 10, place, "frame {frame}: {c:?}");
                }
                found.push((frame, c[0].frame));
            }
        }
        // Every revisit frame (100, 110, ..., 150) finds the same place one lap earlier.
        assert_eq!(found.len(), 6, "{found:?}");
        for (frame, best) in found {
            assert_eq!(best, frame - 100);
        }
        assert_eq!(search.len(), 160);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(
            CandidateSearch::new(CandidateConfig {
                every_n_frames: 0,
                ..CandidateConfig::default()
            })
            .is_err()
        );
        let mut s = CandidateSearch::new(CandidateConfig::default()).unwrap();
        s.process(0, place_image(0, 0.0), Vector3::zeros()).unwrap();
        let err = s
            .process(1, GrayImage::new(10, 10, 0.0), Vector3::zeros())
            .unwrap_err();
        assert!(matches!(err, LoopError::ThumbnailSize { frame: 1, .. }));
    }
}
