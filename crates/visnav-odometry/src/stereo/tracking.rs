//! Stereo tracking t-1 → t (step 2 of [`super`]) and the motion estimated from it (step 3):
//! each feature of t-1 predicted in both images at t by a motion guess, refined by pyramidal
//! Lucas–Kanade (its window warped as the feature's patch is predicted to look at t) and kept
//! through the circular check; up to four passes from different guesses, the best consistent
//! motion kept.

use std::time::Instant;

use nalgebra::{Matrix2, Point2, Vector3};
use visnav_core::Pose;
use visnav_image::Pyramid;
use visnav_image::klt::{fronto_parallel_warp, track, track_warped};

use super::estimate::{self, MotionEstimate, Observation, estimate_motion};
use super::{Estimated, FailReason, FrameCounts, FrameState, StereoOdometry, ms};
use crate::RelativeMotion;

/// The best pass of [`StereoOdometry::track_and_estimate`]: (estimate, tracked in both images,
/// observations, their features' indices at t-1, consistent observations).
type Best = (MotionEstimate, usize, Vec<Observation>, Vec<usize>, usize);

impl StereoOdometry {
    /// The predicted warps of the features' windows t-1 → t in the left and the right image
    /// ([`visnav_image::fronto_parallel_warp`] at each feature's point; the identity where it
    /// has none or where it changes the window's area by more than `max_warp_area_change`).
    pub(super) fn track_warps(
        &self,
        prev: &FrameState,
        cur_from_prev: &Pose,
    ) -> (Vec<Matrix2<f64>>, Vec<Matrix2<f64>>) {
        let cam = &self.rig.left;
        let to_right = Vector3::new(self.rig.baseline_m, 0.0, 0.0);
        // the right camera's motion is the left one's seen from the right camera
        let right_from_left = Pose::translation(-to_right.x, 0.0, 0.0);
        let cur_from_prev_right = right_from_left * cur_from_prev * right_from_left.inverse();
        let max_change = self.config.max_warp_area_change;
        let warp = |p: &Vector3<f64>, motion: &Pose| {
            fronto_parallel_warp(p, motion, cam.fx, cam.fy)
                .filter(|a| (a.determinant() - 1.0).abs() <= max_change)
                .unwrap_or_else(Matrix2::identity)
        };
        prev.features
            .iter()
            .map(|f| {
                (
                    warp(&f.p_in_cam, cur_from_prev),
                    warp(&(f.p_in_cam - to_right), &cur_from_prev_right),
                )
            })
            .unzip()
    }

    /// Tracks the features of t-1 into both images at t, predicting them with `cur_from_prev`,
    /// and keeps those passing the circular check: (observations, tracked in both images), or
    /// `None` when Lucas–Kanade refuses its input.
    pub(super) fn track_with(
        &self,
        prev: &FrameState,
        pl: &Pyramid,
        pr: &Pyramid,
        cur_from_prev: &Pose,
    ) -> Option<(Vec<Observation>, Vec<usize>, usize)> {
        let cfg = &self.config;
        // reproject every 3-D point of t-1 with the motion guess
        let (guess_l, guess_r): (Vec<Point2<f64>>, Vec<Point2<f64>>) = prev
            .features
            .iter()
            .map(|f| {
                let q = cur_from_prev * nalgebra::Point3::from(f.p_in_cam);
                let gl = self.rig.left.project(&q).unwrap_or(f.left_px);
                let gr = self.rig.project_right(&q).unwrap_or(f.right_px);
                (gl, gr)
            })
            .unzip();
        let pts_l: Vec<Point2<f64>> = prev.features.iter().map(|f| f.left_px).collect();
        let pts_r: Vec<Point2<f64>> = prev.features.iter().map(|f| f.right_px).collect();
        let (tl, tr) = if cfg.warps_tracks() {
            let (warp_l, warp_r) = self.track_warps(prev, cur_from_prev);
            rayon::join(
                || track_warped(&prev.left, pl, &pts_l, Some(&guess_l), &warp_l, &cfg.klt),
                || track_warped(&prev.right, pr, &pts_r, Some(&guess_r), &warp_r, &cfg.klt),
            )
        } else {
            rayon::join(
                || track(&prev.left, pl, &pts_l, Some(&guess_l), &cfg.klt),
                || track(&prev.right, pr, &pts_r, Some(&guess_r), &cfg.klt),
            )
        };
        let (Ok(tl), Ok(tr)) = (tl, tr) else {
            return None;
        };
        let both: Vec<usize> = (0..pts_l.len())
            .filter(|&i| tl[i].tracked().is_some() && tr[i].tracked().is_some())
            .filter(|&i| {
                let (l, r) = (tl[i].position, tr[i].position);
                l.x - r.x > 0.0 && (l.y - r.y).abs() < cfg.circular_tolerance_px
            })
            .collect();
        // circular check: left t → right t must land where the right track did
        let from: Vec<Point2<f64>> = both.iter().map(|&i| tl[i].position).collect();
        let to: Vec<Point2<f64>> = both.iter().map(|&i| tr[i].position).collect();
        let stereo_klt = visnav_image::KltConfig {
            levels: 1,
            ..cfg.klt.clone()
        };
        let closure = track(pl, pr, &from, Some(&to), &stereo_klt).ok()?;
        let (obs, idx): (Vec<Observation>, Vec<usize>) = both
            .iter()
            .zip(&closure)
            .filter(|(_, c)| c.tracked().is_some())
            .filter(|(i, c)| (c.position - tr[**i].position).norm() < cfg.circular_tolerance_px)
            .map(|(&i, _)| {
                let o = Observation {
                    p_in_prev: prev.features[i].p_in_cam,
                    left_px: tl[i].position,
                    right_px: tr[i].position,
                    right_row_offset_px: prev.features[i].right_px.y - prev.features[i].left_px.y,
                };
                (o, i)
            })
            .unzip();
        Some((obs, idx, both.len()))
    }

    /// The observations whose reprojection error (eq. 2) under `cur_from_prev` is below
    /// `consistency_limit_px`.
    pub(super) fn consistent_count(&self, obs: &[Observation], cur_from_prev: &Pose) -> usize {
        let cfg = &self.config;
        obs.iter()
            .filter(|o| {
                estimate::reprojection_error(
                    &self.rig,
                    o,
                    cur_from_prev,
                    cfg.use_right_reprojection,
                ) < cfg.consistency_limit_px
            })
            .count()
    }

    /// Whether `consistent` of `tracked` observations pass `min_consistent_fraction`.
    pub(super) fn is_consistent(&self, consistent: usize, tracked: usize) -> bool {
        consistent as f64 >= self.config.min_consistent_fraction * tracked as f64
    }

    /// The motion guess of the last tracking pass: the previous translation with the rotation
    /// that shifts the previous left image onto the current one at the pyramid's coarsest
    /// level at least 64 pixels high (`visnav_image::align::dominant_shift`, ±12 pixels
    /// there): yaw `atan(dx / f_x)`,
    /// pitch `−atan(dy / f_y)`; the previous translation is `prediction`'s. `None` when the
    /// images are too small for the search.
    pub(super) fn alignment_guess(
        &self,
        (prev, cur): (&Pyramid, &Pyramid),
        prediction: &RelativeMotion,
    ) -> Option<RelativeMotion> {
        const MAX_SHIFT_PX: usize = 12;
        // the coarsest level at least 64 pixels high (±12 there: ±48 px at level 2)
        let level = (0..prev.levels().len().min(cur.levels().len()))
            .rev()
            .find(|&l| prev.level(l).is_some_and(|p| p.image.height() >= 64))?;
        let (a, b) = (&prev.level(level)?.image, &cur.level(level)?.image);
        let (dx, dy) = visnav_image::align::dominant_shift(a, b, MAX_SHIFT_PX)?;
        let scale = f64::from(1u32 << level);
        let yaw = (f64::from(dx) * scale / self.rig.left.fx).atan();
        let pitch = -(f64::from(dy) * scale / self.rig.left.fy).atan();
        let rotation =
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), pitch)
                * nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), yaw);
        // (the rotation of `cur_from_prev`, the previous translation in the same direction)
        let cur_from_prev = Pose::from_parts(prediction.cur_from_prev().translation, rotation);
        Some(RelativeMotion::from_cur_from_prev(cur_from_prev))
    }

    /// Tracking t-1 → t and motion estimation: (motion or reason, counts, tracking ms, est. ms).
    ///
    /// The first pass predicts with `prediction`, the driver's previous motion (constant turn
    /// rate and velocity). When
    /// that prediction was poor — fewer than `retrack_fraction` of the features survive tracking,
    /// or of those fewer than `retrack_fraction` are rotation inliers, as when the turn rate
    /// changes by several degrees per frame, or the motion is inconsistent with most tracks
    /// (`min_consistent_fraction`) — the features are tracked again from the motion just
    /// estimated (from zero motion when the first pass has no consistent one; a third pass from
    /// zero motion when the second is inconsistent too, as when a stop follows a fast frame;
    /// a fourth from the rotation that aligns the two images, [`Self::alignment_guess`], when
    /// none was consistent, as at the onset of a turn in front of repeated facades).
    /// A consistent pass beats an inconsistent one; between two of the same kind the one with
    /// more rotation inliers is kept. An inconsistent best motion is refused
    /// ([`FailReason::InconsistentMotion`]): the rank-based phases always end with some subset,
    /// which on a wrong motion is a small minority of the tracks.
    pub(super) fn track_and_estimate(
        &self,
        prev: &FrameState,
        (pl, pr): (&Pyramid, &Pyramid),
        prediction: &RelativeMotion,
    ) -> (Estimated, FrameCounts, f64, f64) {
        let mut counts = FrameCounts::default();
        if prev.features.is_empty() {
            return (Err(FailReason::NoPreviousFeatures), counts, 0.0, 0.0);
        }
        let cfg = &self.config;
        let n_prev = prev.features.len() as f64;
        let mut tracking_ms = 0.0;
        let mut est_ms = 0.0;
        // (estimate, tracked in both images, observations, consistent observations)
        let mut best: Option<Best> = None;
        let mut last_found = 0;
        let mut implausible: Option<f64> = None;
        let mut guess = *prediction;
        for pass in 0..4 {
            if pass == 3 {
                // three passes without a consistent motion: a last one from the rotation that
                // aligns the two left images globally
                let best_ok = best
                    .as_ref()
                    .is_some_and(|(_, _, b_obs, _, c)| self.is_consistent(*c, b_obs.len()));
                match self
                    .alignment_guess((&prev.left, pl), prediction)
                    .filter(|_| !best_ok)
                {
                    Some(g) => guess = g,
                    None => break,
                }
            }
            let t = Instant::now();
            let tracked = self.track_with(prev, pl, pr, &guess.cur_from_prev());
            tracking_ms += ms(t);
            let Some((obs, idx, n_tracked)) = tracked else {
                if best.is_none() {
                    return (
                        Err(FailReason::EstimationFailed),
                        counts,
                        tracking_ms,
                        est_ms,
                    );
                }
                break;
            };
            last_found = obs.len();
            if pass == 0 {
                counts.tracked = n_tracked;
                counts.circular = obs.len();
            }
            let est = if obs.len() >= cfg.min_features {
                let t = Instant::now();
                let est = estimate_motion(&self.rig, &obs, &guess, cfg);
                est_ms += ms(t);
                est.filter(|e| {
                    let translation_m = e.motion.length_m();
                    let plausible =
                        translation_m.is_finite() && translation_m <= cfg.max_translation_m;
                    if !plausible {
                        implausible = Some(translation_m);
                    }
                    plausible
                })
            } else {
                None
            };
            let est = est.map(|e| {
                let consistent = self.consistent_count(&obs, &e.motion.cur_from_prev());
                (e, consistent)
            });
            let poor = match &est {
                None => true,
                Some((e, consistent)) => {
                    (obs.len() as f64) < cfg.retrack_fraction * n_prev
                        || (e.rotation_inliers as f64) < cfg.retrack_fraction * obs.len() as f64
                        || !self.is_consistent(*consistent, obs.len())
                }
            };
            if let Some((e, consistent)) = est {
                let ok = self.is_consistent(consistent, obs.len());
                let better = best.as_ref().is_none_or(|(b, _, b_obs, _, b_consistent)| {
                    let b_ok = self.is_consistent(*b_consistent, b_obs.len());
                    (ok && !b_ok) || (ok == b_ok && e.rotation_inliers > b.rotation_inliers)
                });
                // the next pass starts from a consistent motion, else from zero motion
                guess = if ok || pass == 0 {
                    e.motion
                } else {
                    RelativeMotion::identity()
                };
                if better {
                    best = Some((e, n_tracked, obs, idx, consistent));
                }
            } else if best.is_none() {
                guess = RelativeMotion::identity();
            }
            let best_ok = best
                .as_ref()
                .is_some_and(|(_, _, b_obs, _, c)| self.is_consistent(*c, b_obs.len()));
            if !poor || cfg.retrack_fraction <= 0.0 || (pass == 1 && best_ok) {
                break;
            }
        }
        let Some((est, n_tracked, best_obs, best_idx, consistent)) = best else {
            // report why the last attempt failed
            if last_found < cfg.min_features {
                return (
                    Err(FailReason::TooFewTracks {
                        found: last_found,
                        needed: cfg.min_features,
                    }),
                    counts,
                    tracking_ms,
                    est_ms,
                );
            }
            let reason = match implausible {
                Some(translation_m) => FailReason::ImplausibleMotion { translation_m },
                None => FailReason::EstimationFailed,
            };
            return (Err(reason), counts, tracking_ms, est_ms);
        };
        counts.tracked = n_tracked;
        counts.circular = best_obs.len();
        counts.consistent = consistent;
        counts.rotation_inliers = est.rotation_inliers;
        counts.rotation_iterations = est.rotation_iterations;
        counts.translation_inliers = est.translation_inliers;
        counts.translation_iterations = est.translation_iterations;
        if !self.is_consistent(consistent, best_obs.len()) {
            let reason = FailReason::InconsistentMotion {
                consistent,
                tracked: best_obs.len(),
            };
            return (Err(reason), counts, tracking_ms, est_ms);
        }
        (Ok((est, best_obs, best_idx)), counts, tracking_ms, est_ms)
    }
}
