//! Windowed monocular bundle adjustment over tracks of the dense flow (issue 26; not in the
//! monocular paper, whose odometry is frame to frame).
//!
//! Every accepted frame chains the window's live tracks through its flow (`k−1 → k`, bilinear
//! in the flow, all four neighbours forward–backward consistent) and seeds new ones where a grid
//! cell of the new image has none, from the frame's own correspondences (the most certain pixel
//! of each cell, [`super::correspondences_from_flow`]). So a scene point is observed over up to
//! [`MonoWindowConfig::window_frames`] frames instead of two. With
//! [`MonoWindowConfig::refine_tracks`] (the default) the flow's pixel is only the guess: the
//! track's patch in the previous image is aligned into the new one by Lucas–Kanade, its
//! template warped by the flow's Jacobian there. The dense flow's magnitude is biased by its
//! matching, its smoothness and the image border by up to a few per cent; chained from frame
//! to frame that bias shrank a forward flight's window to 0.65 of its scale in 200 frames,
//! refined it holds 0.98 (docs/notes/2026-12-02-aerial-history.md, round 9).
//!
//! The window's poses (`cam_from_world`, the newest initialised with the frame's fused pose) and
//! the points of the tracks seen [`MonoWindowConfig::min_observations`] times are then refined
//! jointly on their reprojection errors by the stereo window's adjustment ([`crate::ba`], the
//! left-image residual only: `r = (u − fx·x/z − cx, v − fy·y/z − cy)`, divided by
//! [`MonoWindowConfig::sigma_px`], Huber kernel, outlier rounds). A monocular window has seven
//! gauge freedoms, the scale among them: its two oldest frames are held fixed, so the scale of
//! the window is the one its past steps were given, carried to the newest frame by the tracks.
//!
//! What sets the scale is [`WindowScale`]. With `window` (the default but for a level flight,
//! [`WindowScale::Auto`]) the adjusted window
//! does, and for a car the ground plane's scale candidate of the frame pulls it: the length
//! that puts the camera at the configured camera height (`scale.camera_height_m`) above the
//! ground fitted in the frame. In aerial mode nothing pulls it (the window's own scale): a
//! flight's height above the ground changes. The
//! whole window, poses and points, is scaled about its oldest camera by
//! `(ground / window)^ground_pull` — the scale is a gauge freedom the fixed frames hold, so a
//! change of the newest step alone would not last. In a climb the candidate is short by the
//! ratio of the heights (the 563-frame flight's climb from 30 to 60 m: the window's steps fall
//! to 0.59 of the truth, t_err 23 %, which is why aerial flights are not pulled); the aerial
//! mode's tracked ground (the height carried along by the steps) was tried in its place and
//! follows its own drift: one-way t_err 8.3 %, but palindromes ending 30–56 % from their start
//! (docs/notes/2026-12-02-aerial-history.md, round 7). With `stage`
//! the odometry's scale stage sets the newest step's length and the window corrects its
//! rotation and direction only — the eight-point's direction is what fails on a forward flight
//! whose focus of expansion leaves the image (docs/notes/2026-12-02-aerial-history.md,
//! round 4).
//!
//! [`WindowMode::Auto`], the default, runs it in aerial mode only (a car keeps the paper's
//! frame-to-frame odometry), and a frame whose window has fewer than
//! [`MonoWindowConfig::min_points`] points keeps its fused pose. With
//! the renderer's exact flow, or with zero-mean noise on it, the window
//! holds the scale where the frame-to-frame chain loses it (test
//! `mono_aerial::the_window_holds_the_scale_of_a_noisy_flow`); with the pipeline's own dense
//! flow it holds it when its tracks are refined (test
//! `mono_aerial::refined_tracks_hold_the_windows_scale_on_the_pipelines_flow`).

use std::collections::VecDeque;

use nalgebra::{Matrix2, Point2, Point3, UnitQuaternion, Vector3};
use visnav_core::{PinholeCamera, Pose, StereoCamera};
use visnav_flow::DenseFlow;
use visnav_geometry::Correspondence;
use visnav_image::{KltConfig, Pyramid, track_warped};

mod config;

pub use config::{MonoWindowConfig, WindowMode, WindowScale};

use super::point_scale::flow_at_subpixel;
use crate::RelativeMotion;
use crate::ba::{BaReport, Observation, WindowBa};

/// A point followed through the window: its pixel in each frame that saw it.
#[derive(Debug, Clone)]
struct Track {
    /// `(frame id, pixel)`, oldest first, consecutive frames.
    observations: Vec<(u64, Point2<f64>)>,
    /// World position from the last adjustment, metres.
    point_w: Option<Point3<f64>>,
}

/// A track's (or a seed's) step into the new frame.
#[derive(Debug, Clone, Copy)]
struct Move {
    /// Its pixel in the previous image.
    from_px: Point2<f64>,
    /// Its pixel in the new image by the flow.
    guess: Point2<f64>,
}

/// The window's state: its frames' poses and the tracks they observe.
#[derive(Debug, Clone)]
pub(crate) struct MonoWindow {
    /// `(frame id, cam_from_world)`, oldest first.
    frames: VecDeque<(u64, Pose)>,
    tracks: Vec<Track>,
}

/// The window after a frame: the new state and the newest frame's adjusted pose.
#[derive(Debug, Clone)]
pub(crate) struct WindowStep {
    /// The window to commit.
    pub(crate) window: MonoWindow,
    /// The newest frame's motion from the window's previous frame, both adjusted (its length
    /// the scale stage's where that sets it, [`WindowScale`]); `None` when the window could not
    /// adjust it (too few frames or observations, a failed solve): the fused pose stands.
    pub(crate) motion: Option<RelativeMotion>,
    /// Points adjusted.
    pub(crate) points: usize,
    /// The solve, when one ran.
    pub(crate) report: Option<BaReport>,
}

/// How far the window's adjusted step lies from the frame's fused step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StepChange {
    /// Angle of the rotation between the two steps' rotations, radians.
    pub(crate) rotation_rad: f64,
    /// Angle between the two translations, radians (0 when either is zero).
    pub(crate) direction_rad: f64,
}

impl StepChange {
    /// The change from `fused` to `adjusted` (both `cur_from_prev`).
    pub(crate) fn between(adjusted: &Pose, fused: &Pose) -> Self {
        let (a, f) = (adjusted.translation.vector, fused.translation.vector);
        Self {
            rotation_rad: adjusted.rotation.angle_to(&fused.rotation),
            direction_rad: if a.norm() > 0.0 && f.norm() > 0.0 {
                a.angle(&f)
            } else {
                0.0
            },
        }
    }
}

impl WindowStep {
    /// The newest frame's adjusted `world_from_cam` (as the window holds it), `None` as
    /// `motion`.
    pub(crate) fn world_from_cam(&self) -> Option<Pose> {
        self.motion
            .and(self.window.frames.back())
            .map(|f| f.1.inverse())
    }

    /// A new window of one frame at `world_from_cam`, nothing adjusted.
    pub(crate) fn restart(world_from_cam: Pose) -> Self {
        Self {
            window: MonoWindow::start(world_from_cam),
            motion: None,
            points: 0,
            report: None,
        }
    }
}

impl MonoWindow {
    /// A window of one frame at `world_from_cam` (the first image, or a restart).
    pub(crate) fn start(world_from_cam: Pose) -> Self {
        Self {
            frames: VecDeque::from([(0, world_from_cam.inverse())]),
            tracks: Vec::new(),
        }
    }

    /// Adds the frame whose flow from the window's newest frame is `flow` (its grid
    /// correspondences `corrs`), initialised at `world_from_cur`, and adjusts the window.
    /// `(stage, ground)`: the scale stage's step length where it sets the window's
    /// ([`MonoWindowConfig::stage_sets_length`]; `None`: the window holds its own scale) and
    /// the ground plane's candidate, metres (see [`WindowScale`],
    /// [`MonoWindowConfig::ground_pull`]).
    pub(crate) fn advance(
        &self,
        cfg: &MonoWindowConfig,
        camera: &PinholeCamera,
        (flow, corrs, cell_px): (&DenseFlow, &[Correspondence], usize),
        images: Option<(&Pyramid, &Pyramid)>,
        world_from_cur: Pose,
        (stage_m, ground_m): (Option<f64>, Option<f64>),
    ) -> WindowStep {
        let mut window = self.clone();
        let prev_id = window.frames.back().map_or(0, |f| f.0);
        let cur_id = prev_id + 1;
        // at most a quarter of the image's smaller side: a small image keeps its middle half
        let border_px = cfg.border_px.min(0.25 * flow.width.min(flow.height) as f64);
        let images = images.filter(|_| cfg.refine_tracks);
        window.extend_tracks(
            (flow, images, cfg),
            corrs,
            (cell_px.max(1), border_px),
            (prev_id, cur_id),
        );
        window.frames.push_back((cur_id, world_from_cur.inverse()));
        while window.frames.len() > cfg.window_frames {
            window.frames.pop_front();
        }
        let oldest = window.frames.front().map_or(cur_id, |f| f.0);
        for t in &mut window.tracks {
            t.observations.retain(|o| o.0 >= oldest);
        }
        window.tracks.retain(|t| t.observations.len() >= 2);
        let (points, report) = window.adjust(cfg, camera);
        let motion = report.is_some().then(|| {
            if stage_m.is_none()
                && let Some(g) = ground_m
            {
                window.pull_scale(g, cfg.ground_pull);
            }
            let step = window.newest_step(stage_m);
            let n = window.frames.len();
            window.frames[n - 1].1 = step * window.frames[n - 2].1;
            RelativeMotion::from_cur_from_prev(step)
        });
        WindowStep {
            window,
            motion,
            points,
            report,
        }
    }

    /// Chains the tracks seen in `prev` through the flow into `cur` (refined by Lucas–Kanade
    /// when `images` are given, [`MonoWindowConfig::refine_tracks`]); seeds new tracks from the
    /// correspondences in the grid cells of `cur` no track reached.
    fn extend_tracks(
        &mut self,
        (flow, images, cfg): (&DenseFlow, Option<(&Pyramid, &Pyramid)>, &MonoWindowConfig),
        corrs: &[Correspondence],
        (cell_px, border_px): (usize, f64),
        (prev, cur): (u64, u64),
    ) {
        let (w, h) = (flow.width as f64, flow.height as f64);
        let inside = |p: &Point2<f64>| {
            p.x >= border_px
                && p.y >= border_px
                && p.x <= w - 1.0 - border_px
                && p.y <= h - 1.0 - border_px
        };
        let cols = flow.width.div_ceil(cell_px);
        let rows = flow.height.div_ceil(cell_px);
        let mut occupied = vec![false; cols * rows];
        let cell_of = |p: &Point2<f64>| {
            let (x, y) = (
                p.x.max(0.0) as usize / cell_px,
                p.y.max(0.0) as usize / cell_px,
            );
            (x < cols && y < rows).then_some(y * cols + x)
        };
        let align = |moves: &[Move]| match images {
            Some(images) => refine_by_klt(flow, images, cfg, moves),
            None => moves.iter().map(|m| Some(m.guess)).collect(),
        };
        let (carried, moves): (Vec<usize>, Vec<Move>) = self
            .tracks
            .iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let &(id, px) = t.observations.last()?;
                if id != prev {
                    return None;
                }
                let guess = follow_flow(flow, &px)?;
                Some((i, Move { from_px: px, guess }))
            })
            .unzip();
        for (i, target) in carried.into_iter().zip(align(&moves)) {
            if let Some(q) = target.filter(|q| inside(q))
                && let Some(cell) = cell_of(&q)
            {
                self.tracks[i].observations.push((cur, q));
                occupied[cell] = true;
            }
        }
        let seeds: Vec<Move> = corrs
            .iter()
            .filter(|c| inside(&c.p1_px))
            .map(|c| Move {
                from_px: c.p1_px,
                guess: c.p2_px,
            })
            .collect();
        for (m, target) in seeds.iter().zip(align(&seeds)) {
            if let Some(q) = target.filter(|q| inside(q))
                && let Some(cell) = cell_of(&q)
                && !occupied[cell]
            {
                occupied[cell] = true;
                self.tracks.push(Track {
                    observations: vec![(prev, m.from_px), (cur, q)],
                    point_w: None,
                });
            }
        }
    }

    /// Bundle adjustment of the window; the points adjusted and the solve's report (`None`
    /// when nothing could be adjusted).
    fn adjust(
        &mut self,
        cfg: &MonoWindowConfig,
        camera: &PinholeCamera,
    ) -> (usize, Option<BaReport>) {
        if self.frames.len() < 3 {
            return (0, None);
        }
        let oldest = self.frames[0].0;
        let Ok(rig) = StereoCamera::new(*camera, 1.0) else {
            return (0, None);
        };
        let mut ba = WindowBa {
            rig,
            cam_from_world: self.frames.iter().map(|f| f.1).collect(),
            points_w: Vec::new(),
            observations: Vec::new(),
        };
        let mut adjusted = Vec::new();
        for (i, t) in self.tracks.iter().enumerate() {
            if t.observations.len() < cfg.min_observations {
                continue;
            }
            let pose = |id: u64| self.frames[(id - oldest) as usize].1;
            let in_front = |p: &Point3<f64>| t.observations.iter().all(|o| (pose(o.0) * p).z > 0.0);
            let Some(point) = t.point_w.filter(in_front).or_else(|| {
                let (a, b) = (t.observations[0], t.observations[t.observations.len() - 1]);
                triangulate_midpoint(camera, (&pose(a.0), &a.1), (&pose(b.0), &b.1), cfg)
                    .filter(in_front)
            }) else {
                continue;
            };
            let index = ba.points_w.len();
            ba.points_w.push(point);
            adjusted.push(i);
            for &(id, px) in &t.observations {
                ba.observations.push(Observation {
                    frame: (id - oldest) as usize,
                    point: index,
                    left_px: px,
                    right_u_px: None,
                    sigma_px: cfg.sigma_px,
                    right_sigma_px: cfg.sigma_px,
                });
            }
        }
        if adjusted.len() < cfg.min_points {
            return (adjusted.len(), None);
        }
        let Ok(report) = ba.solve(&cfg.ba()) else {
            return (adjusted.len(), None);
        };
        let poses_ok = ba
            .cam_from_world
            .iter()
            .all(|p| p.translation.vector.iter().all(|v| v.is_finite()));
        // the residual of a point behind a camera is not defined (the adjustment costs it as an
        // outlier, so it may still end there): a solve that moved many points there went wrong
        let mut in_front = vec![true; ba.points_w.len()];
        for o in &ba.observations {
            if (ba.cam_from_world[o.frame] * ba.points_w[o.point]).z <= 0.0 {
                in_front[o.point] = false;
            }
        }
        let behind = in_front.iter().filter(|f| !**f).count();
        if !poses_ok || behind * 50 > ba.points_w.len() {
            return (adjusted.len(), None);
        }
        for (f, pose) in self.frames.iter_mut().zip(&ba.cam_from_world) {
            f.1 = *pose;
        }
        for ((&i, p), front) in adjusted.iter().zip(&ba.points_w).zip(in_front) {
            // a point the solve left behind a camera is triangulated again next frame
            self.tracks[i].point_w = front.then_some(*p);
        }
        (adjusted.len(), Some(report))
    }

    /// The newest frame's motion from the previous window frame after the adjustment, its
    /// translation's length `stage_m` where the scale stage sets it, else the window's.
    fn newest_step(&self, stage_m: Option<f64>) -> Pose {
        let n = self.frames.len();
        let mut cur_from_prev = self.frames[n - 1].1 * self.frames[n - 2].1.inverse();
        cur_from_prev.rotation = UnitQuaternion::new_normalize(cur_from_prev.rotation.into_inner());
        let length = cur_from_prev.translation.vector.norm();
        let target = stage_m.unwrap_or(length);
        if target.is_finite() && target > 0.0 && length > 0.0 {
            cur_from_prev.translation.vector *= target / length;
        }
        cur_from_prev
    }

    /// Scales the window about its oldest camera by `(ground / window)^pull`, `window` the
    /// length of its newest step and `ground` the ground plane's candidate for it (metres),
    /// when the two are within a factor 1.5: the window's scale is a gauge freedom its fixed
    /// frames hold, so only a change of the whole window (poses and points) lasts.
    fn pull_scale(&mut self, ground_m: f64, pull: f64) {
        let n = self.frames.len();
        let centre = |k: usize| self.frames[k].1.inverse().translation.vector;
        let length = (centre(n - 1) - centre(n - 2)).norm();
        let ratio = ground_m / length;
        if !(ratio.is_finite() && ratio > 0.0 && ratio.ln().abs() < 1.5f64.ln()) || pull == 0.0 {
            return;
        }
        let c = ratio.powf(pull);
        let origin = centre(0);
        for f in &mut self.frames {
            let mut world_from_cam = f.1.inverse();
            world_from_cam.translation.vector =
                origin + c * (world_from_cam.translation.vector - origin);
            f.1 = world_from_cam.inverse();
        }
        for t in &mut self.tracks {
            if let Some(p) = t.point_w.as_mut() {
                *p = Point3::from(origin + c * (p.coords - origin));
            }
        }
    }
}

/// The pixel `p + flow(p)`, the flow interpolated bilinearly; `None` when a neighbour is not
/// forward–backward consistent or the target leaves the image (how the window follows a track).
#[must_use]
pub fn follow_flow(flow: &DenseFlow, p: &Point2<f64>) -> Option<Point2<f64>> {
    let q = flow_at_subpixel(flow, p)?.target_px;
    let (w, h) = (flow.width as f64, flow.height as f64);
    let inside = q.x >= 0.0 && q.y >= 0.0 && q.x <= w - 1.0 && q.y <= h - 1.0;
    inside.then_some(q)
}

/// The Lucas–Kanade window of [`MonoWindowConfig::refine_tracks`], `radius_px` its half-size:
/// at full resolution only (the flow's pixel is the guess, within a pixel of the patch's own).
fn refine_klt_config(radius_px: usize) -> KltConfig {
    KltConfig {
        window_radius: radius_px,
        levels: 1,
        ..KltConfig::default()
    }
}

/// Each move's pixel in the new image `cur` aligned by Lucas–Kanade from its pixel in the
/// previous image `prev`, the template warped by the flow's Jacobian there and the flow's pixel
/// the guess: `None` where the patch is lost (out of the image, untextured, a large residual),
/// lands more than a pixel from the flow's pixel or fails the round trip
/// ([`MonoWindowConfig::max_round_trip_px`]).
fn refine_by_klt(
    flow: &DenseFlow,
    (prev, cur): (&Pyramid, &Pyramid),
    cfg: &MonoWindowConfig,
    moves: &[Move],
) -> Vec<Option<Point2<f64>>> {
    let klt = refine_klt_config(cfg.refine_radius_px);
    let points: Vec<Point2<f64>> = moves.iter().map(|m| m.from_px).collect();
    let guesses: Vec<Point2<f64>> = moves.iter().map(|m| m.guess).collect();
    let warps: Vec<Matrix2<f64>> = points.iter().map(|p| flow_jacobian(flow, p)).collect();
    let Ok(tracked) = track_warped(prev, cur, &points, Some(&guesses), &warps, &klt) else {
        return vec![None; moves.len()];
    };
    let aligned: Vec<Option<Point2<f64>>> = tracked
        .iter()
        .zip(&guesses)
        .map(|(t, g)| t.tracked().filter(|q| (q - g).norm() <= 1.0))
        .collect();
    if cfg.max_round_trip_px <= 0.0 {
        return aligned;
    }
    // back from where each patch landed (the flow's pixel for a lost one, not looked at)
    let landed: Vec<Point2<f64>> = aligned
        .iter()
        .zip(&guesses)
        .map(|(q, g)| q.unwrap_or(*g))
        .collect();
    let inverse: Vec<Matrix2<f64>> = warps
        .iter()
        .map(|m| m.try_inverse().unwrap_or_else(Matrix2::identity))
        .collect();
    let Ok(back) = track_warped(cur, prev, &landed, Some(&points), &inverse, &klt) else {
        return vec![None; moves.len()];
    };
    aligned
        .into_iter()
        .zip(back.iter().zip(&points))
        .map(|(q, (b, p))| {
            q.filter(|_| {
                b.tracked()
                    .is_some_and(|b| (b - p).norm() <= cfg.max_round_trip_px)
            })
        })
        .collect()
}

/// `I + ∂flow/∂x` at `p` (central differences over ±1 px of the bilinear flow): the map of a
/// small patch's offsets from the first image to the second; the identity where a neighbour
/// is not forward–backward consistent (the window's template warp for a track).
#[must_use]
pub fn flow_jacobian(flow: &DenseFlow, p: &Point2<f64>) -> Matrix2<f64> {
    let at = |dx: f64, dy: f64| {
        let q = Point2::new(p.x + dx, p.y + dy);
        flow_at_subpixel(flow, &q).map(|s| s.target_px - q)
    };
    match (at(1.0, 0.0), at(-1.0, 0.0), at(0.0, 1.0), at(0.0, -1.0)) {
        (Some(xp), Some(xm), Some(yp), Some(ym)) => {
            let (dx, dy) = (0.5 * (xp - xm), 0.5 * (yp - ym));
            Matrix2::new(1.0 + dx.x, dy.x, dx.y, 1.0 + dy.y)
        }
        _ => Matrix2::identity(),
    }
}

/// The midpoint of the closest approach of two viewing rays (`cam_from_world`, pixel), when
/// both depths are positive and the rays differ by at least `min_ray_angle_rad`.
fn triangulate_midpoint(
    camera: &PinholeCamera,
    (a_from_world, a_px): (&Pose, &Point2<f64>),
    (b_from_world, b_px): (&Pose, &Point2<f64>),
    cfg: &MonoWindowConfig,
) -> Option<Point3<f64>> {
    let ray = |pose: &Pose, px: &Point2<f64>| -> (Vector3<f64>, Vector3<f64>) {
        let world_from_cam = pose.inverse();
        let d = Vector3::new(
            (px.x - camera.cx) / camera.fx,
            (px.y - camera.cy) / camera.fy,
            1.0,
        );
        (
            world_from_cam.translation.vector,
            (world_from_cam.rotation * d).normalize(),
        )
    };
    let (ca, da) = ray(a_from_world, a_px);
    let (cb, db) = ray(b_from_world, b_px);
    let cos = da.dot(&db).clamp(-1.0, 1.0);
    if cos.acos() < cfg.min_ray_angle_rad {
        return None;
    }
    // minimise |ca + s da − cb − t db|²
    let w0 = ca - cb;
    let (b, d, e) = (da.dot(&db), da.dot(&w0), db.dot(&w0));
    let denom = 1.0 - b * b;
    if denom <= 1e-12 {
        return None;
    }
    let s = (b * e - d) / denom;
    let t = (e - b * d) / denom;
    if !(s > 0.0 && t > 0.0) {
        return None;
    }
    Some(Point3::from(0.5 * (ca + s * da + cb + t * db)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn camera() -> PinholeCamera {
        PinholeCamera::new(300.0, 300.0, 160.0, 120.0, 320, 240).unwrap()
    }

    #[test]
    fn midpoint_recovers_a_point_seen_from_two_poses() {
        let cam = camera();
        let x_w = Point3::new(1.0, -0.5, 12.0);
        let a = Pose::identity();
        let b = Pose::from_parts(
            Translation3::new(-0.8, 0.1, -1.0),
            UnitQuaternion::from_euler_angles(0.01, 0.03, -0.02),
        );
        let px = |p: &Pose| cam.project(&(p * x_w)).unwrap();
        let got = triangulate_midpoint(
            &cam,
            (&a, &px(&a)),
            (&b, &px(&b)),
            &MonoWindowConfig::default(),
        )
        .unwrap();
        assert!((got - x_w).norm() < 1e-9, "{got:?}");
    }

    #[test]
    fn flow_is_followed_bilinearly_and_refused_where_inconsistent() {
        let (w, h) = (8, 6);
        let mut flow = DenseFlow {
            width: w,
            height: h,
            flow: (0..w * h).map(|i| [(i % w) as f32 * 0.5, 1.0]).collect(),
            information: vec![[1.0, 0.0, 1.0]; w * h],
            valid: vec![true; w * h],
        };
        let q = follow_flow(&flow, &Point2::new(2.5, 1.0)).unwrap();
        assert!((q.x - (2.5 + 1.25)).abs() < 1e-12 && (q.y - 2.0).abs() < 1e-12);
        flow.valid[w + 3] = false;
        assert!(follow_flow(&flow, &Point2::new(2.5, 1.0)).is_none());
        assert!(
            follow_flow(&flow, &Point2::new(6.5, 4.5)).is_none(),
            "leaves the image"
        );
    }

    /// A window of three cameras 1 m apart along z, one point per track.
    fn three_frame_window() -> MonoWindow {
        let frames = (0..3u64)
            .map(|k| {
                let world_from_cam = Pose::translation(0.0, 0.0, k as f64);
                (k, world_from_cam.inverse())
            })
            .collect();
        MonoWindow {
            frames,
            tracks: vec![Track {
                observations: vec![(0, Point2::new(10.0, 10.0)), (1, Point2::new(11.0, 11.0))],
                point_w: Some(Point3::new(1.0, 2.0, 10.0)),
            }],
        }
    }

    #[test]
    fn pulling_the_scale_scales_the_whole_window_about_its_oldest_camera() {
        let mut w = three_frame_window();
        // the ground says 1.44 m a step, the window 1 m: half of the way in logarithm
        w.pull_scale(1.44, 0.5);
        let c = 1.2;
        let centre = |k: usize| w.frames[k].1.inverse().translation.vector;
        assert!((centre(0) - Vector3::zeros()).norm() < 1e-12);
        assert!((centre(2) - Vector3::new(0.0, 0.0, 2.0 * c)).norm() < 1e-12);
        let p = w.tracks[0].point_w.unwrap();
        assert!((p - Point3::new(c, 2.0 * c, 10.0 * c)).norm() < 1e-12);
        // a candidate beyond a factor 1.5 of the window's step is not trusted
        let before = w.frames.clone();
        w.pull_scale(100.0, 0.5);
        assert_eq!(w.frames, before);
    }

    #[test]
    fn the_adjusted_step_must_stay_near_the_fused_one() {
        let cfg = MonoWindowConfig::default();
        let fused = Pose::translation(0.0, 0.0, -1.0);
        let turned = |deg: f64| {
            Pose::from_parts(
                Translation3::new(0.0, 0.0, -1.0),
                UnitQuaternion::from_euler_angles(0.0, deg.to_radians(), 0.0),
            )
        };
        let accepts = |adjusted: &Pose| cfg.accepts(&StepChange::between(adjusted, &fused));
        assert!(accepts(&turned(0.5)));
        assert!(!accepts(&turned(2.0)), "1.1° at most");
        let climbing = Pose::translation(0.0, -0.3, -1.0);
        assert!(accepts(&climbing), "17° of direction is a correction");
        assert!(!accepts(&Pose::translation(1.0, 0.0, 0.0)));
    }

    #[test]
    fn the_flows_jacobian_is_the_patchs_linear_map() {
        // flow(x, y) = (0.02 x − 0.01 y + 3, 0.005 x + 0.03 y − 1): an affine motion
        let (w, h) = (40, 30);
        let mut flow = DenseFlow {
            width: w,
            height: h,
            flow: (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    [0.02 * x - 0.01 * y + 3.0, 0.005 * x + 0.03 * y - 1.0]
                })
                .collect(),
            information: vec![[1.0, 0.0, 1.0]; w * h],
            valid: vec![true; w * h],
        };
        let a = flow_jacobian(&flow, &Point2::new(20.3, 14.6));
        let expected = Matrix2::new(1.02, -0.01, 0.005, 1.03);
        assert!((a - expected).amax() < 1e-5, "{a}");
        flow.valid[15 * w + 21] = false;
        assert_eq!(
            flow_jacobian(&flow, &Point2::new(20.3, 14.6)),
            Matrix2::identity()
        );
    }

    /// A patch on one surface comes back where it started; one over a depth edge (a near
    /// surface moving 3 px, the one behind it 1 px) is aligned forward but fails the round trip.
    #[test]
    fn the_round_trip_ends_a_track_across_a_depth_edge() {
        let (w, h) = (96usize, 64usize);
        let texture = |x: f64, y: f64, k: f64| {
            100.0
                + 40.0 * (0.31 * k * x + 0.17 * y).sin() * (0.23 * y - 0.11 * k * x).cos()
                + 25.0 * (0.53 * x + 0.29 * k * y).sin()
        };
        // the near surface covers x < edge; it moves 3 px right, the ground 1 px
        let image = |near_shift: f64, far_shift: f64| {
            let edge = 48.0 + near_shift;
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    if x < edge {
                        texture(x - near_shift, y, 1.7) as f32
                    } else {
                        texture(x - far_shift, y, 1.0) as f32
                    }
                })
                .collect();
            visnav_core::GrayImage::from_vec(w, h, data).unwrap()
        };
        let (prev, cur) = (image(0.0, 0.0), image(3.0, 1.0));
        let pyramids = (Pyramid::build(&prev, 1), Pyramid::build(&cur, 1));
        let flow = DenseFlow {
            width: w,
            height: h,
            flow: vec![[1.0, 0.0]; w * h],
            information: vec![[1.0, 0.0, 1.0]; w * h],
            valid: vec![true; w * h],
        };
        let moves: Vec<Move> = [(70.0, 32.0), (50.0, 32.0)]
            .iter()
            .map(|&(x, y)| Move {
                from_px: Point2::new(x, y),
                guess: Point2::new(x + 1.0, y),
            })
            .collect();
        let refine = |max_round_trip_px| {
            let cfg = MonoWindowConfig {
                refine_radius_px: 7,
                max_round_trip_px,
                ..MonoWindowConfig::default()
            };
            refine_by_klt(&flow, (&pyramids.0, &pyramids.1), &cfg, &moves)
        };
        let (one_way, checked) = (refine(0.0), refine(0.1));
        let ground = one_way[0].expect("the ground's patch is aligned");
        assert!((ground - Point2::new(71.0, 32.0)).norm() < 0.05, "{ground}");
        assert_eq!(checked[0], one_way[0], "one surface comes back");
        assert!(one_way[1].is_some(), "the edge's patch is aligned one way");
        assert!(checked[1].is_none(), "but does not come back");
    }

    /// A window adjusts only with [`MonoWindowConfig::min_points`] points; below, nothing moves.
    #[test]
    fn a_window_of_too_few_points_does_not_adjust() {
        let cam = camera();
        let mut window = three_frame_window();
        window.tracks = (0..40)
            .map(|i| {
                let p = Point3::new(
                    f64::from(i % 8) - 3.5,
                    f64::from(i / 8) - 2.0,
                    12.0 + f64::from(i % 5),
                );
                let observations = window
                    .frames
                    .iter()
                    .map(|&(id, cam_from_world)| (id, cam.project(&(cam_from_world * p)).unwrap()))
                    .collect();
                Track {
                    observations,
                    point_w: None,
                }
            })
            .collect();
        let before: Vec<Pose> = window.frames.iter().map(|f| f.1).collect();
        let mut cfg = MonoWindowConfig {
            min_points: 41,
            ..MonoWindowConfig::default()
        };
        let (points, report) = window.clone().adjust(&cfg, &cam);
        assert_eq!((points, report.is_some()), (40, false));
        cfg.min_points = 40;
        let (points, report) = window.adjust(&cfg, &cam);
        assert_eq!((points, report.is_some()), (40, true));
        for (f, b) in window.frames.iter().zip(&before) {
            assert!((f.1.translation.vector - b.translation.vector).norm() < 1e-6);
        }
    }

    #[test]
    fn config_validation_names_the_field() {
        assert!(MonoWindowConfig::default().invalid_field().is_none());
        let bad = MonoWindowConfig {
            window_frames: 2,
            ..MonoWindowConfig::default()
        };
        assert_eq!(bad.invalid_field().unwrap().0, "window.window_frames");
        let bad = MonoWindowConfig {
            refine_radius_px: 0,
            ..MonoWindowConfig::default()
        };
        assert_eq!(bad.invalid_field().unwrap().0, "window.refine_radius_px");
        let bad = MonoWindowConfig {
            max_round_trip_px: -0.1,
            ..MonoWindowConfig::default()
        };
        assert_eq!(bad.invalid_field().unwrap().0, "window.max_round_trip_px");
    }
}
