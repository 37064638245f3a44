//! Persistent tracks and the sliding-window bundle adjustment on top of RotROCC (issue #25; not
//! in the stereo paper, whose estimate is frame-to-frame).
//!
//! * **Tracks.** Every stereo feature carries an id. A feature of t-1 that RotROCC keeps as an
//!   inlier of its final phase at t is carried to t with its tracked left and right pixels (the
//!   predicted Lucas–Kanade and circular check of [`super`]) and the same id; its 3-D point is
//!   triangulated from the tracked pair. Shi–Tomasi corners detected at t (bucketed, stereo
//!   matched as before) only fill the gaps: a corner closer than
//!   [`WindowConfig::min_track_distance_px`] to a carried track, or in a bucket already holding
//!   `corners.max_per_bucket` tracks, is not added. A 3-D point is thus observed over many
//!   frames.
//! * **Window.** [`TrackWindow`] keeps the last [`WindowConfig::window_frames`] frames with their
//!   `world_from_cam` and their features. After each estimated frame the window is adjusted by
//!   [`crate::ba::WindowBa`] (poses and points, Huber kernel, χ² rounds, Levenberg–Marquardt on
//!   the Schur-reduced camera system; see [`crate::ba`]): RotROCC's frame-to-frame estimate is
//!   the initial guess of the newest pose, the earlier poses and the points start from the
//!   previous adjustment. The oldest `ba.fixed_frames` frames are held fixed (gauge and link to
//!   the trajectory before the window): a **fixed-window approximation** — the frames that leave
//!   the window are dropped, not marginalised, so their information is not carried as a prior;
//!   the adjusted world points of tracks that stay in view are kept and start the next window.
//! * **Output.** The newest adjusted pose is the frame's pose (an online estimate: poses of
//!   frames already reported are refined inside the window but not reported again). Tracks
//!   whose newest observation is a χ² outlier after the adjustment are ended; the next frame's
//!   tracking starts from the adjusted points ([`WindowConfig::use_window_points`]).
//! * **Residual weighting.** Every observation is whitened by one [`WindowConfig::sigma_px`];
//!   a DNRE-style normalisation (eq. 24) is not applied in the window: it divides by the
//!   translation-induced flow of one frame pair, which is not defined for a point seen in many
//!   frames.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};

use nalgebra::{Matrix6, Point2, Point3, UnitQuaternion, Vector3};
use visnav_core::{Pose, StereoCamera};

use crate::ba::{
    BaReport, CovarianceScale, Observation as BaObservation, StereoResidual, WindowBa,
};
use crate::stereo::config::WindowConfig;
use crate::stereo::matching::StereoFeature;

/// One frame of the window.
#[derive(Debug, Clone)]
struct WindowFrame {
    world_from_cam: Pose,
    ids: Vec<u64>,
    features: Vec<StereoFeature>,
}

/// The last frames with their tracks, and the adjusted world points of the tracks.
#[derive(Debug, Clone, Default)]
pub struct TrackWindow {
    frames: VecDeque<WindowFrame>,
    points_w: HashMap<u64, Point3<f64>>,
}

/// The result of one adjustment.
#[derive(Debug, Clone)]
pub struct Adjusted {
    /// The newest frame's adjusted pose.
    pub world_from_cam: Pose,
    /// The second newest frame's adjusted pose.
    pub prev_world_from_cam: Pose,
    /// Tracks whose newest observation is a χ² outlier after the adjustment.
    pub outlier_ids: HashSet<u64>,
    /// Points in the adjustment.
    pub points: usize,
    /// The solver's report.
    pub report: BaReport,
    /// The rig's disparity offset the adjustment measured, pixels (with
    /// `ba.estimate_right_cx_offset`).
    pub right_cx_offset_px: Option<f64>,
    /// The covariance of the step between the two newest adjusted frames (`prev_from_cur`,
    /// [`crate::ba::WindowBa::relative_covariance`]), when asked for and the information is
    /// regular.
    pub step_covariance: Option<Matrix6<f64>>,
}

impl TrackWindow {
    /// Whether the window holds no frame.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Forgets every frame and point (after a frame that could not be estimated).
    pub fn reset(&mut self) {
        self.frames.clear();
        self.points_w.clear();
    }

    /// Appends the newest frame, dropping the oldest beyond `window_frames`.
    pub fn push(
        &mut self,
        world_from_cam: Pose,
        ids: &[u64],
        features: &[StereoFeature],
        window_frames: usize,
    ) {
        self.frames.push_back(WindowFrame {
            world_from_cam,
            ids: ids.to_vec(),
            features: features.to_vec(),
        });
        while self.frames.len() > window_frames {
            self.frames.pop_front();
        }
        let alive: HashSet<u64> = self
            .frames
            .iter()
            .flat_map(|f| f.ids.iter().copied())
            .collect();
        self.points_w.retain(|id, _| alive.contains(id));
    }

    /// Appends tracks to the newest frame (the new corners of a frame adjusted before they
    /// joined it: a track seen once is not in an adjustment with `min_observations` ≥ 2).
    pub fn extend_newest(&mut self, ids: &[u64], features: &[StereoFeature]) {
        if let Some(newest) = self.frames.back_mut() {
            newest.ids.extend_from_slice(ids);
            newest.features.extend_from_slice(features);
        }
    }

    /// The adjusted point of track `id` in the newest camera, when it has one.
    pub fn point_in_newest(&self, id: u64) -> Option<Vector3<f64>> {
        let newest = self.frames.back()?;
        let x = self.points_w.get(&id)?;
        Some((newest.world_from_cam.inverse() * x).coords)
    }

    /// Bundle-adjusts the window; `None` when it has fewer than two frames, no point seen
    /// twice, or the solver refuses it (the window is then left as it was). With `covariance`,
    /// the step between the two newest frames gets its covariance at the solution.
    pub fn adjust(
        &mut self,
        rig: &StereoCamera,
        cfg: &WindowConfig,
        covariance: Option<CovarianceScale>,
    ) -> Option<Adjusted> {
        let n = self.frames.len();
        if n < 2 {
            return None;
        }
        // observations of every track, in id order (deterministic)
        let mut seen: BTreeMap<u64, Vec<(usize, usize)>> = BTreeMap::new();
        for (k, f) in self.frames.iter().enumerate() {
            for (i, &id) in f.ids.iter().enumerate() {
                seen.entry(id).or_default().push((k, i));
            }
        }
        let mut ids = Vec::new();
        let mut points_w = Vec::new();
        let mut observations = Vec::new();
        for (id, obs) in &seen {
            if obs.len() < cfg.min_observations {
                continue;
            }
            let (k0, i0) = obs[0];
            let first = &self.frames[k0];
            let x = self.points_w.get(id).copied().unwrap_or_else(|| {
                first.world_from_cam * Point3::from(first.features[i0].p_in_cam)
            });
            let point = points_w.len();
            for &(frame, i) in obs {
                let f = &self.frames[frame].features[i];
                observations.push(BaObservation {
                    frame,
                    point,
                    left_px: f.left_px,
                    right_u_px: Some(f.right_px.x),
                    sigma_px: cfg.sigma_px,
                    right_sigma_px: cfg.right_sigma_px,
                });
            }
            ids.push(*id);
            points_w.push(x);
        }
        let fixed = cfg.ba.fixed_frames.min(n - 1);
        let mut ba = WindowBa {
            rig: *rig,
            cam_from_world: self
                .frames
                .iter()
                .map(|f| f.world_from_cam.inverse())
                .collect(),
            points_w,
            observations,
        };
        let ba_cfg = crate::ba::BaConfig {
            fixed_frames: fixed,
            ..cfg.ba
        };
        let report = ba.solve(&ba_cfg).ok()?;
        let finite = ba.cam_from_world.iter().all(|t| {
            t.translation.vector.iter().all(|v| v.is_finite())
                && t.rotation.coords.iter().all(|v| v.is_finite())
        });
        if !finite || !report.final_cost.is_finite() {
            return None;
        }
        for (f, t) in self.frames.iter_mut().zip(&ba.cam_from_world) {
            // products of many unit quaternions drift off the unit sphere: renormalise
            let rotation = UnitQuaternion::new_normalize(t.rotation.into_inner());
            f.world_from_cam = Pose::from_parts(t.translation, rotation).inverse();
        }
        for (id, x) in ids.iter().zip(&ba.points_w) {
            if x.iter().all(|v| v.is_finite()) {
                self.points_w.insert(*id, *x);
            }
        }
        let outlier_ids = ba
            .observations
            .iter()
            .filter(|o| o.frame == n - 1)
            .filter(|o| {
                StereoResidual::new(rig, o)
                    .value(&ba.cam_from_world[o.frame], &ba.points_w[o.point])
                    .is_none_or(|r| r.norm_squared() > cfg.ba.outlier_chi2)
            })
            .map(|o| ids[o.point])
            .collect();
        let step_covariance =
            covariance.and_then(|scale| ba.relative_covariance(&ba_cfg, (n - 2, n - 1), scale));
        Some(Adjusted {
            step_covariance,
            world_from_cam: self.frames[n - 1].world_from_cam,
            prev_world_from_cam: self.frames[n - 2].world_from_cam,
            outlier_ids,
            points: ids.len(),
            report,
            right_cx_offset_px: cfg
                .ba
                .estimate_right_cx_offset
                .then_some(ba.rig.right_cx_offset_px),
        })
    }
}

/// Where new features may go: the buckets (`bucket_cols` x `bucket_rows` over the image) that
/// hold fewer than `max_per_bucket` features, away from every feature by `min_distance_px`.
#[derive(Debug)]
pub struct Gaps {
    size: (f64, f64),
    cols: usize,
    rows: usize,
    max_per_bucket: usize,
    count: Vec<usize>,
    min_distance_px: f64,
    /// occupancy grid with cells of `min_distance_px`: a point checks its 3x3 neighbourhood
    grid: HashMap<(i64, i64), Vec<Point2<f64>>>,
}

impl Gaps {
    /// The gaps left by features at `left_px` in an image of `size` pixels; `buckets` is
    /// `(bucket_cols, bucket_rows, max_per_bucket)`.
    #[must_use]
    pub fn new<'a>(
        left_px: impl IntoIterator<Item = &'a Point2<f64>>,
        size: (usize, usize),
        buckets: (usize, usize, usize),
        min_distance_px: f64,
    ) -> Self {
        let (cols, rows, max_per_bucket) = buckets;
        let (cols, rows) = (cols.max(1), rows.max(1));
        let mut gaps = Self {
            size: (size.0.max(1) as f64, size.1.max(1) as f64),
            cols,
            rows,
            max_per_bucket,
            count: vec![0; cols * rows],
            min_distance_px,
            grid: HashMap::new(),
        };
        for p in left_px {
            gaps.add(p);
        }
        gaps
    }

    fn bucket(&self, p: &Point2<f64>) -> usize {
        let c = ((p.x / self.size.0 * self.cols as f64).max(0.0) as usize).min(self.cols - 1);
        let r = ((p.y / self.size.1 * self.rows as f64).max(0.0) as usize).min(self.rows - 1);
        r * self.cols + c
    }

    fn cell(&self, p: &Point2<f64>) -> (i64, i64) {
        let cell = self.min_distance_px.max(1.0);
        ((p.x / cell).floor() as i64, (p.y / cell).floor() as i64)
    }

    /// Whether a feature at `p` fills a gap. Adding features only closes gaps, so a point
    /// refused now is refused later too.
    #[must_use]
    pub fn admits(&self, p: &Point2<f64>) -> bool {
        if self.count[self.bucket(p)] >= self.max_per_bucket {
            return false;
        }
        let (cx, cy) = self.cell(p);
        !(-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                self.grid
                    .get(&(cx + dx, cy + dy))
                    .is_some_and(|v| v.iter().any(|q| (q - p).norm() < self.min_distance_px))
            })
        })
    }

    /// Records a feature at `p`.
    pub fn add(&mut self, p: &Point2<f64>) {
        let b = self.bucket(p);
        self.count[b] += 1;
        let cell = self.cell(p);
        self.grid.entry(cell).or_default().push(*p);
    }
}

/// Merges the carried tracks with the corners detected at the current frame: a corner is added
/// (with a fresh id from `next_id`), in the order given, when it fills a gap the carried tracks
/// and the corners added before it leave (`gaps`: those of the carried tracks, [`Gaps::new`]).
pub fn fill_gaps(
    gaps: &mut Gaps,
    carried: &mut Vec<StereoFeature>,
    ids: &mut Vec<u64>,
    detected: &[StereoFeature],
    next_id: &mut u64,
) {
    for f in detected {
        if gaps.admits(&f.left_px) {
            gaps.add(&f.left_px);
            carried.push(*f);
            ids.push(*next_id);
            *next_id += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use visnav_core::PinholeCamera;
    use visnav_core::se3::se3_exp;

    /// Exact stereo features of `points_w` seen from `world_from_cam` (ids = point indices).
    fn observe(
        rig: &StereoCamera,
        world_from_cam: &Pose,
        points_w: &[Point3<f64>],
    ) -> (Vec<u64>, Vec<StereoFeature>) {
        let cam_from_world = world_from_cam.inverse();
        points_w
            .iter()
            .enumerate()
            .filter_map(|(j, x)| {
                let p = cam_from_world * x;
                let l = rig.left.project(&p)?;
                let r = rig.project_right(&p)?;
                Some((
                    j as u64,
                    StereoFeature {
                        left_px: l,
                        right_px: r,
                        disparity_px: l.x - r.x,
                        p_in_cam: p.coords,
                    },
                ))
            })
            .unzip()
    }

    /// `n` points scattered 10–40 m in front of the first camera.
    fn scattered_points(n: u32) -> Vec<Point3<f64>> {
        (0..n)
            .map(|j| {
                let j = f64::from(j);
                Point3::new(
                    (j * 0.37).sin() * 12.0,
                    (j * 0.91).cos() * 2.0 - 0.5,
                    10.0 + (j * 1.3).rem_euclid(30.0),
                )
            })
            .collect()
    }

    #[test]
    fn the_window_recovers_exact_poses_from_exact_tracks() {
        let rig = StereoCamera::new(PinholeCamera::kitti_default(), 0.54).unwrap();
        let points_w = scattered_points(300);
        let truth: Vec<Pose> = (0..5)
            .map(|k| se3_exp(&Vector6::new(0.02, 0.0, 1.1, 0.0, 0.01, 0.0).scale(f64::from(k))))
            .collect();
        let cfg = WindowConfig::default();
        let mut window = TrackWindow::default();
        let mut adjusted = None;
        for (k, t) in truth.iter().enumerate() {
            let (ids, features) = observe(&rig, t, &points_w);
            // the initial guess of the newest pose is off by 5 cm and 0.3°
            let guess = if k == 0 {
                *t
            } else {
                *t * se3_exp(&Vector6::new(0.05, -0.02, 0.03, 0.005, 0.0, 0.002))
            };
            window.push(guess, &ids, &features, cfg.window_frames);
            if k > 0 {
                adjusted = window.adjust(&rig, &cfg, None);
                let a = adjusted.as_ref().unwrap();
                let err = a.world_from_cam.inverse() * t;
                assert!(err.translation.vector.norm() < 1e-6, "frame {k}: {err}");
                assert!(err.rotation.angle() < 1e-8, "frame {k}: {err}");
                assert!(a.outlier_ids.is_empty());
            }
        }
        assert_eq!(adjusted.unwrap().points, 300);
        assert!(!window.is_empty());
        window.reset();
        assert!(window.is_empty() && window.adjust(&rig, &cfg, None).is_none());
    }

    /// What the odometry relies on to adjust the window beside the corner detection: adjusting
    /// with the carried tracks and appending the new ones afterwards leaves the same window,
    /// poses and outliers as pushing all of them first.
    #[test]
    fn new_tracks_appended_after_the_adjustment_change_nothing() {
        let rig = StereoCamera::new(PinholeCamera::kitti_default(), 0.54).unwrap();
        let points_w = scattered_points(200);
        let cfg = WindowConfig::default();
        let (mut early, mut late) = (TrackWindow::default(), TrackWindow::default());
        for k in 0..4 {
            let t = se3_exp(&Vector6::new(0.01, 0.0, 1.0, 0.0, 0.004, 0.0).scale(k as f64));
            let (mut ids, mut features) = observe(&rig, &t, &points_w);
            // noisy tracks, one gross outlier, and ids 1000+ seen for the first time
            for (i, f) in features.iter_mut().enumerate() {
                f.left_px.x += ((i * 7 + k * 3) % 11) as f64 * 0.05 - 0.25;
            }
            features[5].left_px.y += 9.0;
            let split = ids.len();
            let (fresh_ids, fresh): (Vec<u64>, Vec<StereoFeature>) = (0..20)
                .map(|i| {
                    let id = 1000 + 100 * k as u64 + i;
                    (id, feature(30.0 * i as f64 + 5.0, 50.0 + k as f64))
                })
                .unzip();
            let guess = t * se3_exp(&Vector6::new(0.03, 0.0, -0.02, 0.0, 0.001, 0.0));
            early.push(guess, &ids, &features, cfg.window_frames);
            let a = early.adjust(&rig, &cfg, None);
            early.extend_newest(&fresh_ids, &fresh);
            ids.extend(&fresh_ids);
            features.extend(&fresh);
            late.push(guess, &ids, &features, cfg.window_frames);
            let b = late.adjust(&rig, &cfg, None);
            assert_eq!(a.is_some(), b.is_some(), "frame {k}");
            if let (Some(a), Some(b)) = (a, b) {
                assert_eq!(a.world_from_cam, b.world_from_cam, "frame {k}");
                assert_eq!(a.outlier_ids, b.outlier_ids, "frame {k}");
                assert_eq!(a.points, b.points, "frame {k}");
            }
            for id in &ids[..split] {
                assert_eq!(early.point_in_newest(*id), late.point_in_newest(*id));
            }
        }
        assert_eq!(
            early.frames.back().unwrap().ids,
            late.frames.back().unwrap().ids
        );
    }

    fn feature(x: f64, y: f64) -> StereoFeature {
        StereoFeature {
            left_px: Point2::new(x, y),
            right_px: Point2::new(x - 10.0, y),
            disparity_px: 10.0,
            p_in_cam: Vector3::new(0.0, 0.0, 10.0),
        }
    }

    #[test]
    fn gaps_are_filled_away_from_tracks_and_within_bucket_limits() {
        let mut carried = vec![feature(10.0, 10.0)];
        let mut ids = vec![7];
        let detected = [
            feature(12.0, 11.0),  // near the track
            feature(40.0, 10.0),  // same bucket, second feature: allowed
            feature(45.0, 30.0),  // same bucket, third: over the limit
            feature(150.0, 10.0), // another bucket
        ];
        let mut next_id = 100;
        let left_px: Vec<Point2<f64>> = carried.iter().map(|f| f.left_px).collect();
        let mut gaps = Gaps::new(&left_px, (200, 100), (2, 1, 2), 5.0);
        fill_gaps(&mut gaps, &mut carried, &mut ids, &detected, &mut next_id);
        assert_eq!(ids, vec![7, 100, 101]);
        assert_eq!(carried[1].left_px.x, 40.0);
        assert_eq!(carried[2].left_px.x, 150.0);
        assert_eq!(next_id, 102);
    }

    #[test]
    fn corners_refused_by_the_carried_tracks_alone_change_nothing() {
        // what `StereoOdometry::match_corners` relies on: matching only the corners the carried
        // tracks leave room for gives the features of matching them all
        let carried: Vec<StereoFeature> = (0..40)
            .map(|i| feature(f64::from(i * 37 % 100), f64::from(i * 53 % 100)))
            .collect();
        let detected: Vec<StereoFeature> = (0..300)
            .map(|i| feature(f64::from(i * 71 % 199) + 0.5, f64::from(i * 29 % 97) + 0.25))
            .collect();
        // the carried tracks fill the buckets of the left half (10 each, 6 allowed)
        let left_px: Vec<Point2<f64>> = carried.iter().map(|f| f.left_px).collect();
        let gaps = || Gaps::new(&left_px, (200, 100), (4, 2, 6), 6.0);
        let fill = |candidates: &[StereoFeature]| {
            let (mut features, mut ids, mut next_id) = (carried.clone(), vec![0; 40], 100);
            fill_gaps(
                &mut gaps(),
                &mut features,
                &mut ids,
                candidates,
                &mut next_id,
            );
            features
        };
        let gaps = gaps();
        let admitted: Vec<StereoFeature> = detected
            .iter()
            .filter(|f| gaps.admits(&f.left_px))
            .copied()
            .collect();
        assert!(
            admitted.len() < detected.len() * 6 / 10,
            "{}",
            admitted.len()
        );
        let all = fill(&detected);
        assert!(all.len() > carried.len() + 10, "{}", all.len());
        assert_eq!(fill(&admitted), all);
    }
}
