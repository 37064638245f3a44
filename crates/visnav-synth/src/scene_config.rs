//! The parameters of a [`crate::Scene`]: the city's layout, the renderer's supersampling, and the
//! ground's texture (the street's, or an indoor floor mat, [`crate::MatConfig`]).

use serde::{Deserialize, Serialize};

use crate::SynthError;
use crate::mat::MatConfig;

/// Layout and rendering parameters of a [`crate::Scene`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// Height of the camera path above the ground, metres (KITTI 1.65): the ground plane lies
    /// this far below the plane fitted to the camera positions.
    pub ground_depth_m: f64,
    /// Half the width of the carriageway, metres.
    pub road_half_width_m: f64,
    /// Width of the kerb stones, metres.
    pub kerb_width_m: f64,
    /// Width of the paved sidewalk beyond the kerb, metres.
    pub sidewalk_width_m: f64,
    /// Smallest distance from the road centre line to a facade, metres.
    pub setback_min_m: f64,
    /// Largest distance from the road centre line to a facade, metres.
    pub setback_max_m: f64,
    /// Lowest building, metres.
    pub building_min_height_m: f64,
    /// Highest building, metres.
    pub building_max_height_m: f64,
    /// Rays travelling further see the sky, metres.
    pub max_distance_m: f64,
    /// Samples per pixel along each axis (3 = 3x3 supersampling).
    pub supersampling: u32,
    /// Road length generated before the first pose, metres.
    pub lead_in_m: f64,
    /// Road length generated after the last pose, metres.
    pub lead_out_m: f64,
    /// A forest instead of the buildings: tree crowns (upright cylinders 8–25 m high, 1.5–3.5 m
    /// in radius, leaf-textured) on a jittered 7 m grid from `setback_min_m` to this distance
    /// from the road on both sides, metres; 0 (the default) for the street of buildings.
    pub forest_depth_m: f64,
    /// Every wavelength of the ground's texture (asphalt, verge) multiplied by this: a flight
    /// kilometres up sees fields and tracks tens of metres across, where a street's gravel
    /// (centimetres to metres) averages to one grey. Default 1 (the street's).
    pub ground_texture_scale: f64,
    /// An indoor floor mat instead of the street's ground (a near-uniform grey with sparse
    /// markers, [`MatConfig`]); `None` (the default) for the street.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mat: Option<MatConfig>,
}

/// The allowed [`SceneConfig::ground_texture_scale`] (and a flight's `texture_scale`).
pub(crate) const GROUND_TEXTURE_SCALE: std::ops::RangeInclusive<f64> = 1e-3..=1e4;

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            ground_depth_m: 1.65,
            road_half_width_m: 4.0,
            kerb_width_m: 0.25,
            sidewalk_width_m: 3.0,
            setback_min_m: 9.0,
            setback_max_m: 13.0,
            building_min_height_m: 6.0,
            building_max_height_m: 22.0,
            max_distance_m: 400.0,
            supersampling: 3,
            lead_in_m: 60.0,
            lead_out_m: 250.0,
            forest_depth_m: 0.0,
            ground_texture_scale: 1.0,
            mat: None,
        }
    }
}

impl SceneConfig {
    /// A motorway: a 15 m carriageway (half width 7.5 m), facades 16–20 m from the centre line
    /// and 8–14 m high — long rows of similar windowed blocks, the repetitive roadside of a
    /// highway drive ([`crate::highway_trajectory`]); the other fields as [`Self::default`].
    #[must_use]
    pub fn highway() -> Self {
        Self {
            road_half_width_m: 7.5,
            setback_min_m: 16.0,
            setback_max_m: 20.0,
            building_min_height_m: 8.0,
            building_max_height_m: 14.0,
            ..Self::default()
        }
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`SynthError::InvalidConfig`] naming the offending field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |field: &str, message: &str| {
            Err(SynthError::InvalidConfig {
                field: field.into(),
                message: message.into(),
            })
        };
        let positive = [
            ("ground_depth_m", self.ground_depth_m),
            ("road_half_width_m", self.road_half_width_m),
            ("kerb_width_m", self.kerb_width_m),
            ("sidewalk_width_m", self.sidewalk_width_m),
            ("building_min_height_m", self.building_min_height_m),
            ("max_distance_m", self.max_distance_m),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, "must be finite and positive");
            }
        }
        for (name, v) in [
            ("lead_in_m", self.lead_in_m),
            ("lead_out_m", self.lead_out_m),
        ] {
            if !(v.is_finite() && (0.0..1e5).contains(&v)) {
                return bad(name, "must be within 0..100000 m");
            }
        }
        if !(self.setback_min_m
            > self.road_half_width_m + self.kerb_width_m + self.sidewalk_width_m
            && self.setback_max_m >= self.setback_min_m
            && self.setback_max_m < 1e3)
        {
            return bad(
                "setback_min_m",
                "need road + kerb + sidewalk < setback_min_m <= setback_max_m < 1000",
            );
        }
        if !(self.building_max_height_m >= self.building_min_height_m
            && self.building_max_height_m < 1e3)
        {
            return bad(
                "building_max_height_m",
                "need building_min_height_m <= building_max_height_m < 1000",
            );
        }
        if !(self.forest_depth_m.is_finite() && (0.0..1e3).contains(&self.forest_depth_m)) {
            return bad("forest_depth_m", "must be within 0..1000 m");
        }
        if !(1..=8).contains(&self.supersampling) {
            return bad("supersampling", "must be within 1..=8");
        }
        if !GROUND_TEXTURE_SCALE.contains(&self.ground_texture_scale) {
            return bad("ground_texture_scale", "must be within 0.001..=10000");
        }
        if let Some(mat) = &self.mat {
            mat.validate()?;
        }
        Ok(())
    }
}
