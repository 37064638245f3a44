//! The scale keeper (§5 step 4): the metric length of the eight-point's unit translation from
//! the ground plane `s = −(b·h)/d` and the median depth ratio against the previous depth map,
//! chosen by the rules of a ground vehicle or, with `scale.aerial`, of a flight ([`aerial`]),
//! and the state those rules keep from frame to frame.

mod aerial;
mod candidates;

use std::collections::VecDeque;

use self::aerial::AerialScale;
pub(super) use self::candidates::CellPoint;
use self::candidates::scale_candidates;
use super::config::{MonoConfig, ScaleConfig};
use super::context::FrameContext;
use super::correspondence::median;
use super::depth::DepthMap;
use super::point_scale::PointScale;
use super::result::ScaleSource;

/// The outcome of the scale stage.
pub(super) struct ScaleEstimate {
    /// The chosen translation length, metres.
    pub(super) scale_m: Option<f64>,
    /// Where it came from.
    pub(super) source: ScaleSource,
    /// The ground-plane candidate (before the motion-prior gate).
    pub(super) ground_m: Option<f64>,
    /// The depth-ratio candidate (before the motion-prior gate).
    pub(super) depth_ratio_m: Option<f64>,
}

impl ScaleEstimate {
    /// No eight-point pose to scale.
    pub(super) fn none() -> Self {
        Self {
            scale_m: None,
            source: ScaleSource::None,
            ground_m: None,
            depth_ratio_m: None,
        }
    }
}

/// The scale stage's state for the next frames: a frame works on a copy, which the odometry
/// keeps only when it accepts the frame.
#[derive(Debug, Clone)]
pub(super) struct ScaleKeeper {
    /// `ln(ground candidate / chosen scale)` of the recent frames with a ground candidate
    /// (the re-anchoring test).
    ground_log_ratios: VecDeque<f64>,
    /// The aerial rules and their state (`scale.aerial`); `None`: a ground vehicle's rules.
    aerial: Option<AerialScale>,
}

impl ScaleKeeper {
    /// The keeper of a new odometry with `config`'s rules.
    pub(super) fn new(config: &ScaleConfig) -> Self {
        Self {
            ground_log_ratios: VecDeque::new(),
            aerial: config
                .aerial
                .then(|| AerialScale::new(config.camera_height_m)),
        }
    }

    /// A new map: the next frame's scale comes from the ground plane again (aerial: with the
    /// last re-estimated camera height).
    pub(super) fn restart(&mut self) {
        if let Some(aerial) = &mut self.aerial {
            aerial.restart();
        }
        self.ground_log_ratios.clear();
    }

    /// After the accepted step `motion` (metres; `scaled`: the keeper is the frame's, which
    /// scaled an eight-point pose): the tracked ground follows the camera.
    pub(super) fn after_step(&mut self, motion: &crate::RelativeMotion, scaled: bool) {
        if let Some(aerial) = &mut self.aerial {
            aerial.after_step(motion, scaled);
        }
    }

    /// The translation bound, metres: `max_translation_m`, in aerial mode at least
    /// `aerial_max_step_heights` camera heights (the height the reconstruction last saw).
    pub(super) fn max_translation_m(&self, cfg: &MonoConfig) -> f64 {
        self.bound(cfg.max_translation_m, cfg.scale.aerial_max_step_heights)
    }

    /// The depth bound, metres: `max_depth_m`, in aerial mode at least
    /// `aerial_max_depth_heights` camera heights.
    pub(super) fn max_depth_m(&self, cfg: &MonoConfig) -> f64 {
        self.bound(cfg.max_depth_m, cfg.scale.aerial_max_depth_heights)
    }

    /// `vehicle_m`, in aerial mode at least `heights` camera heights.
    fn bound(&self, vehicle_m: f64, heights: f64) -> f64 {
        self.aerial
            .as_ref()
            .map_or(vehicle_m, |a| a.bound(vehicle_m, heights))
    }

    /// The eight-point scale (§5): ground plane and/or depth ratio of the unit-scale
    /// triangulation `cells` against `prior`, per the vehicle or the aerial rules, with the
    /// keeper the frame leaves for the next ones (committed only when it is accepted).
    pub(super) fn choose(
        &self,
        ctx: &FrameContext<'_>,
        (prior, cells): (Option<&DepthMap>, &[CellPoint]),
        pnp_scale: Option<f64>,
        at_points: Option<PointScale>,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> (ScaleEstimate, ScaleKeeper) {
        let cfg = ctx.config.scale;
        let initialising = self.aerial.as_ref().is_some_and(AerialScale::initialising);
        let candidates = scale_candidates(ctx, (prior, cells), at_points, initialising, rng);
        let mut state = self.clone();
        let s_ground_raw = candidates.ground_m;
        let s_depth_raw = candidates.depth_m;
        let previous = ctx.last_motion.map(|m| m.length_m()).filter(|s| *s > 0.0);
        // motion prior: a candidate changing the speed by more than `max_scale_change` (ratio)
        // in one frame is implausible and dropped; the PnP translation then stands in. Aerial:
        // the previous scale the keeper chose, not PnP's length ([`AerialScale::prior_anchor_m`])
        let anchor = match &self.aerial {
            Some(a) => a.prior_anchor_m(),
            None => previous,
        };
        let plausible = |s: &f64| {
            anchor.is_none_or(|p| *s <= p * cfg.max_scale_change && *s * cfg.max_scale_change >= p)
        };
        let s_ground = s_ground_raw.filter(plausible);
        let s_depth = s_depth_raw.filter(plausible);
        let fallback = match pnp_scale {
            Some(p) if p > 0.0 => (Some(p), ScaleSource::Pnp),
            _ => (previous, ScaleSource::Previous),
        };
        let (scale, source) = match (&self.aerial, &mut state.aerial) {
            (Some(before), Some(next)) => before.choose(
                ctx,
                next,
                aerial::Candidates {
                    ground: candidates.ground.as_ref(),
                    known_m: candidates.known_m,
                    s_ground,
                    s_depth: s_depth.filter(|_| candidates.overlap >= cfg.min_overlap_fraction),
                    cells,
                    plausible: &plausible,
                    fallback,
                },
                rng,
            ),
            _ => vehicle_scale(&cfg, s_ground, s_depth, pnp_scale, fallback),
        };
        let (scale, source) = self.reanchor(ctx, (scale, source), s_ground_raw, &mut state);
        if let Some(next) = &mut state.aerial {
            next.chose(scale);
        }
        // the camera height seen by the reconstruction at the chosen scale (aerial re-init)
        if let (Some(s), Some(g), Some(before), Some(next)) =
            (scale, &candidates.ground, &self.aerial, &mut state.aerial)
        {
            let normal_in_cam = aerial::level_normal(ctx).unwrap_or(g.plane.normal);
            before.measured_height(next, s * g.camera_height, normal_in_cam);
        }
        let source = if scale.is_none() {
            ScaleSource::None
        } else {
            source
        };
        let estimate = ScaleEstimate {
            scale_m: scale,
            source,
            ground_m: s_ground_raw,
            depth_ratio_m: s_depth_raw,
        };
        (estimate, state)
    }

    /// Ground vehicles: a persistent disagreement between the ground and the chosen scale (the
    /// depth-ratio chain, which the motion prior protects) re-anchors on the ground. Aerial: the
    /// same median ratio once, when the first `reanchor_frames` ground candidates after the
    /// initialisation are in (a single frame's dominant plane can be a roof or a facade).
    fn reanchor(
        &self,
        ctx: &FrameContext<'_>,
        (scale, source): (Option<f64>, ScaleSource),
        s_ground_raw: Option<f64>,
        state: &mut ScaleKeeper,
    ) -> (Option<f64>, ScaleSource) {
        let cfg = ctx.config.scale;
        // aerial: once, over the first frames after initialisation, whatever the ratio; the
        // ground at the height the camera has climbed to since then (a takeoff from the given
        // height doubles it in these frames), not at the given one
        let aerial_window = state.aerial.as_ref().is_some_and(AerialScale::reanchors);
        let s_ground_raw = match self.aerial.as_ref().and_then(AerialScale::tracked_height_m) {
            Some(h) if aerial_window => s_ground_raw.map(|g| g * h / cfg.camera_height_m),
            _ => s_ground_raw,
        };
        match (scale, s_ground_raw) {
            (Some(s), Some(g))
                if g <= self.max_translation_m(ctx.config)
                    && (state.aerial.is_none() || aerial_window) =>
            {
                let ratios = &mut state.ground_log_ratios;
                ratios.push_back((g / s).ln());
                while ratios.len() > cfg.reanchor_frames {
                    ratios.pop_front();
                }
                let mut window: Vec<f64> = ratios.iter().copied().collect();
                match median(&mut window) {
                    Some(m)
                        if window.len() >= cfg.reanchor_frames
                            && (aerial_window || m.abs() > cfg.reanchor_ratio.ln()) =>
                    {
                        log::info!(
                            "mono frame {}: scale re-anchored on the ground (x{:.3})",
                            ctx.frame,
                            m.exp()
                        );
                        ratios.clear();
                        if let Some(aerial) = &mut state.aerial {
                            aerial.anchored();
                        }
                        (Some(s * m.exp()), ScaleSource::GroundReanchor)
                    }
                    _ => (Some(s), source),
                }
            }
            other => (other.0, source),
        }
    }
}

/// The ground vehicles' rule (§5): the mean of the ground-plane and depth-ratio scales when
/// they agree within `max_disagreement`, else the one nearer the PnP translation (else the
/// depth ratio); either alone; neither: `fallback`.
fn vehicle_scale(
    cfg: &ScaleConfig,
    s_ground: Option<f64>,
    s_depth: Option<f64>,
    pnp_scale: Option<f64>,
    fallback: (Option<f64>, ScaleSource),
) -> (Option<f64>, ScaleSource) {
    match (s_ground, s_depth) {
        (Some(g), Some(d)) if (g - d).abs() <= cfg.max_disagreement * g.max(d) => {
            (Some(0.5 * (g + d)), ScaleSource::GroundAndDepth)
        }
        // disagreement (e.g. rotation on the spot, where the ground fit is ill-posed):
        // the candidate closer to the PnP translation, else the depth ratio
        (Some(g), Some(d)) => match pnp_scale {
            Some(p) if (g - p).abs() < (d - p).abs() => (Some(g), ScaleSource::Ground),
            _ => (Some(d), ScaleSource::DepthRatio),
        },
        (Some(g), None) => (Some(g), ScaleSource::Ground),
        (None, Some(d)) => (Some(d), ScaleSource::DepthRatio),
        (None, None) => fallback,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_aerial_strategy_bounds_in_camera_heights_and_survives_a_restart() {
        let mut cfg = MonoConfig::default();
        cfg.scale.camera_height_m = 30.0;
        let vehicle = ScaleKeeper::new(&cfg.scale);
        assert!(vehicle.aerial.is_none());
        assert_eq!(vehicle.max_translation_m(&cfg), cfg.max_translation_m);
        cfg.scale.aerial = true;
        let mut aerial = ScaleKeeper::new(&cfg.scale);
        let heights = cfg.scale.aerial_max_step_heights * 30.0;
        assert!(heights > cfg.max_translation_m);
        assert_eq!(aerial.max_translation_m(&cfg), heights);
        // a restart initialises the scale again, from the height last seen
        aerial.ground_log_ratios.push_back(0.1);
        let before = aerial.aerial;
        aerial.restart();
        assert!(aerial.ground_log_ratios.is_empty());
        assert_eq!(aerial.max_translation_m(&cfg), heights);
        let expected = before.map(|mut a| {
            a.restart();
            a
        });
        assert_eq!(aerial.aerial, expected);
    }

    #[test]
    fn the_vehicle_rule_averages_agreeing_candidates_and_else_follows_pnp() {
        let cfg = ScaleConfig::default();
        let fallback = (Some(9.0), ScaleSource::Pnp);
        let agree = vehicle_scale(&cfg, Some(1.0), Some(1.2), None, fallback);
        assert_eq!(agree.1, ScaleSource::GroundAndDepth);
        assert!((agree.0.unwrap() - 1.1).abs() < 1e-12);
        // far apart (beyond `max_disagreement`): the one nearer PnP, else the depth ratio
        let near_ground = vehicle_scale(&cfg, Some(1.0), Some(3.0), Some(1.1), fallback);
        assert_eq!(near_ground, (Some(1.0), ScaleSource::Ground));
        let no_pnp = vehicle_scale(&cfg, Some(1.0), Some(3.0), None, fallback);
        assert_eq!(no_pnp, (Some(3.0), ScaleSource::DepthRatio));
        assert_eq!(vehicle_scale(&cfg, None, None, None, fallback), fallback);
    }
}
