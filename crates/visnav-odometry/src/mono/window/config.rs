//! The monocular window adjustment's parameters ([`MonoWindowConfig`]): when it runs
//! ([`WindowMode`]) and what sets its scale ([`WindowScale`]); the module above says how the
//! window works.

use serde::{Deserialize, Serialize};

use super::StepChange;
use crate::ba::BaConfig;

/// What sets the scale of the window adjustment's poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WindowScale {
    /// The adjusted window (its two oldest frames hold the scale), pulled towards the ground
    /// plane's candidate by [`MonoWindowConfig::ground_pull`].
    Window,
    /// The odometry's scale stage: the adjusted step's rotation and direction, the scale
    /// stage's length.
    Stage,
    /// `stage` for a level flight (a ground normal given, `homography.ground_normal`: the
    /// scale stage measures each frame's scale on the floor along that normal), `window`
    /// otherwise. On the rendered indoor flight at 640x360 (seed 0) the window's own scale,
    /// held by its two oldest frames — after a hover and a turn on the spot, steps of
    /// millimetres — came out 1.30x on the second and third legs (path 1.21x); with the stage's
    /// it is 1.01–1.04x on every leg (path 1.037x) (docs/notes/2026-12-02-indoor-keyframes.md,
    /// "2026-12-03 (fourth session)").
    Auto,
}

/// When the window adjustment runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WindowMode {
    /// Never (the paper's frame-to-frame odometry).
    Off,
    /// Every frame.
    On,
    /// In aerial mode: a flight's window holds its own scale with its tracks refined
    /// ([`MonoWindowConfig::refine_tracks`]), forward or downward (until 2026-11-29 only
    /// forward-looking flights ran it: with tracks chained through the flow the window made
    /// downward flights worse); a car keeps the paper's frame-to-frame odometry. The default
    /// since 2026-11-29 (round 10), when [`MonoWindowConfig::min_points`] kept the window off
    /// small images: on the 320x96 flights of the `mono_aerial` tests (exact flow, 50–250
    /// points) it had cost a forward flight 100 m up 7 % of its first scale and a downward one
    /// its precision (Sim(3) ATE 0.8 % of the path against 0.04 %)
    /// (docs/notes/2026-12-02-aerial-history.md, rounds 9 and 10).
    Auto,
}

/// Parameters of the monocular window adjustment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonoWindowConfig {
    /// When to adjust a window of the last frames. Default `auto`: flights (aerial mode) do, a
    /// car keeps the paper's frame-to-frame odometry.
    pub mode: WindowMode,
    /// Frames in the window, the newest included (at least 3: two are held fixed). Default 10.
    pub window_frames: usize,
    /// Observations a track needs in the window to be adjusted (at least 2). Default 3.
    pub min_observations: usize,
    /// Points the window needs to adjust a frame: with fewer the frame keeps its fused pose
    /// (the window keeps its tracks). Default 300: a window of 50–250 points (the 320x96
    /// flights of the `mono_aerial` tests, exact flow) moves its steps by 5–10 % from frame to
    /// frame, one of 800–1,000 (620x188) holds them within 1–2 %
    /// (docs/notes/2026-12-02-aerial-history.md, round 10).
    pub min_points: usize,
    /// Standard deviation of a track's pixel, pixels. Default 0.1 (refined tracks; tracks
    /// chained through the flow alone, `refine_tracks = false`, want about 0.5).
    pub sigma_px: f64,
    /// Smallest angle between the rays of a track's first and last observations for its point
    /// to be adjusted, radians (a point without parallax constrains nothing but the rotation,
    /// and its depth is ill-conditioned). Default 0.002 (0.11°).
    pub min_ray_angle_rad: f64,
    /// Huber threshold on the whitened residual norm. Default 2.0.
    pub huber_px: f64,
    /// Tracks end, and are not seeded, within this distance of the image border, pixels (the
    /// dense flow's magnitude is biased low near the border:
    /// docs/notes/2026-12-02-aerial-history.md, rounds 2 and 6).
    /// Default 40.
    pub border_px: f64,
    /// Largest rotation, radians, by which the adjusted step may differ from the frame's fused
    /// step; beyond it (and beyond `max_direction_change_rad` for the translation's direction)
    /// the window is taken to have failed: the fused step stands and the window restarts at
    /// it. Default 0.02 (1.1°).
    pub max_rotation_change_rad: f64,
    /// Largest angle, radians, between the adjusted and the fused step's translation. Default
    /// 0.5 (the eight-point's direction is what the window corrects: up to 22° off in a forward
    /// flight's climbs).
    pub max_direction_change_rad: f64,
    /// What sets the scale. Default `auto` (`stage` for a level flight, `window` otherwise).
    pub scale: WindowScale,
    /// With [`WindowScale::Window`], not in aerial mode: the share by which the newest step's
    /// length moves towards the ground plane's scale candidate at the configured camera height
    /// (module docs) each frame (in logarithm; 0 = the window alone), when the candidate is
    /// within a factor 1.5 of the window's length. Default 0.2.
    pub ground_pull: f64,
    /// Align every track's patch in the previous image into the new one by Lucas–Kanade (a
    /// window of [`Self::refine_radius_px`] at full resolution, [`visnav_image::track_warped`],
    /// the template warped by the flow's Jacobian, the flow's pixel the guess) instead of taking
    /// the dense flow's pixel: the flow's magnitude is biased by its matching, smoothness and the image border,
    /// a patch's alignment is not. A track whose patch is lost, or lands more than a pixel from
    /// the flow's pixel, ends. Default true.
    pub refine_tracks: bool,
    /// Half-size of [`Self::refine_tracks`]' Lucas–Kanade window, pixels (the window is
    /// `2r+1` square, 1..=31). Default 7 (15x15).
    pub refine_radius_px: usize,
    /// Forward–backward check of [`Self::refine_tracks`]: a track's aligned pixel is aligned
    /// back into the previous image (the new patch the template, the inverse warp), and the
    /// track ends when it comes back farther than this from where it started, pixels. A patch
    /// whose alignment depends on the direction — a tree's crown over the ground behind it,
    /// an occluding edge — is not one surface point. 0 = no check. Default 0.1 (the paper's
    /// flight is over a forest): a held-out forest's palindrome ends 0.40 % from its start
    /// against 5.37 % without; over a city 0 is better (a held-out city's 2.41 % against
    /// 1.07 %) (docs/notes/2026-12-02-aerial-history.md, round 10).
    pub max_round_trip_px: f64,
}

impl Default for MonoWindowConfig {
    fn default() -> Self {
        Self {
            mode: WindowMode::Auto,
            window_frames: 10,
            min_observations: 3,
            min_points: 300,
            sigma_px: 0.1,
            min_ray_angle_rad: 0.002,
            huber_px: 2.0,
            border_px: 40.0,
            max_rotation_change_rad: 0.02,
            max_direction_change_rad: 0.5,
            scale: WindowScale::Auto,
            ground_pull: 0.2,
            refine_tracks: true,
            refine_radius_px: 7,
            max_round_trip_px: 0.1,
        }
    }
}

impl MonoWindowConfig {
    /// Whether the window runs on a camera in aerial mode (`aerial`) or not: `on` always,
    /// `auto` in aerial mode, `off` never.
    #[must_use]
    pub fn runs(&self, aerial: bool) -> bool {
        match self.mode {
            WindowMode::Off => false,
            WindowMode::On => true,
            WindowMode::Auto => aerial,
        }
    }

    /// Whether the scale stage sets the window's step lengths ([`WindowScale::Stage`], or
    /// [`WindowScale::Auto`] on a level flight, `level`: a ground normal is given); else the
    /// window holds its own scale.
    #[must_use]
    pub fn stage_sets_length(&self, level: bool) -> bool {
        match self.scale {
            WindowScale::Window => false,
            WindowScale::Stage => true,
            WindowScale::Auto => level,
        }
    }

    /// `None` when valid, else the offending field, its value and what was expected.
    #[must_use]
    pub fn invalid_field(&self) -> Option<(&'static str, f64, &'static str)> {
        if self.window_frames < 3 {
            return Some(("window.window_frames", self.window_frames as f64, ">= 3"));
        }
        if !(1..=31).contains(&self.refine_radius_px) {
            return Some((
                "window.refine_radius_px",
                self.refine_radius_px as f64,
                "in 1..=31",
            ));
        }
        if self.min_observations < 2 {
            return Some((
                "window.min_observations",
                self.min_observations as f64,
                ">= 2",
            ));
        }
        for (field, v) in [
            ("window.sigma_px", self.sigma_px),
            ("window.huber_px", self.huber_px),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Some((field, v, "finite and > 0"));
            }
        }
        if !(0.0..=1.0).contains(&self.ground_pull) {
            return Some(("window.ground_pull", self.ground_pull, "in [0, 1]"));
        }
        for (field, v) in [
            ("window.border_px", self.border_px),
            ("window.max_round_trip_px", self.max_round_trip_px),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((field, v, "finite and >= 0"));
            }
        }
        for (field, v) in [
            (
                "window.max_rotation_change_rad",
                self.max_rotation_change_rad,
            ),
            (
                "window.max_direction_change_rad",
                self.max_direction_change_rad,
            ),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Some((field, v, "finite and > 0"));
            }
        }
        if !(self.min_ray_angle_rad.is_finite() && self.min_ray_angle_rad >= 0.0) {
            return Some((
                "window.min_ray_angle_rad",
                self.min_ray_angle_rad,
                "finite and >= 0",
            ));
        }
        None
    }

    /// The adjustment's settings for this window (two frames held fixed).
    pub(super) fn ba(&self) -> BaConfig {
        BaConfig {
            fixed_frames: 2,
            huber_px: self.huber_px,
            // χ² with 2 degrees of freedom at 95 %: the residual has the left pixel only
            outlier_chi2: 5.991,
            ..BaConfig::default()
        }
    }
}

impl MonoWindowConfig {
    /// Whether a step change stays within the allowed one.
    pub(crate) fn accepts(&self, change: &StepChange) -> bool {
        change.rotation_rad <= self.max_rotation_change_rad
            && change.direction_rad <= self.max_direction_change_rad
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_scale_is_the_stages_for_a_level_flight_only() {
        let auto = MonoWindowConfig::default();
        assert_eq!(auto.scale, WindowScale::Auto);
        assert!(auto.stage_sets_length(true));
        assert!(!auto.stage_sets_length(false));
        // a scale the user chose stands, level or not
        for (fixed, stage) in [(WindowScale::Window, false), (WindowScale::Stage, true)] {
            let cfg = MonoWindowConfig {
                scale: fixed,
                ..auto
            };
            assert_eq!(cfg.stage_sets_length(true), stage);
            assert_eq!(cfg.stage_sets_length(false), stage);
        }
    }

    #[test]
    fn the_scale_reads_and_writes_in_kebab_case() {
        for (text, scale) in [
            ("auto", WindowScale::Auto),
            ("stage", WindowScale::Stage),
            ("window", WindowScale::Window),
        ] {
            let json = format!("{{\"scale\": \"{text}\"}}");
            let cfg: MonoWindowConfig = serde_json::from_str(&json).unwrap();
            assert_eq!(cfg.scale, scale);
            let back = serde_json::to_value(cfg).unwrap();
            assert_eq!(back["scale"], text);
        }
    }
}
