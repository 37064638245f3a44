//! What a hit looks like: the intensity of a [`Scene`]'s surface point seen with a given pixel
//! footprint. Textures are band-limited by the footprint ([`crate::noise`]); the structured
//! patterns (lane markings, joints, windows, planks) are box-filtered analytically
//! (`pulse_box`), so the image is anti-aliased before supersampling.

use nalgebra::Vector3;

use super::{Hit, Material, Object, Scene, Surface};
use crate::noise::{Fbm, cell_random, smoothstep};

impl Scene {
    /// Intensity (0..255) of a hit seen with a pixel footprint `pixel_m` (metres) and a
    /// subsample footprint `sub_m` used by the box-filtered patterns.
    pub(crate) fn shade(&self, hit: &Hit, pixel_m: f64, sub_m: f64) -> f32 {
        let albedo = match hit.surface {
            Surface::Ground { x, z } => self.ground_albedo(x, z, pixel_m, sub_m),
            Surface::Object {
                index, u, v, top, ..
            } => object_albedo(&self.objects[index as usize], u, v, top, pixel_m, sub_m),
        };
        let lambert = hit.normal.dot(&self.sun).max(0.0) as f32;
        (255.0 * albedo * (0.4 + 0.72 * lambert)).clamp(3.0, 252.0)
    }

    /// An identifier of the smooth piece of surface a hit lies on (object face, or ground zone:
    /// asphalt, kerb, sidewalk, verge, per side); pixels whose subsamples all share one key are
    /// shaded once with the analytically filtered texture.
    pub(crate) fn surface_key(&self, hit: &Hit) -> u64 {
        match hit.surface {
            // a mat's markers are filtered analytically: one smooth surface
            Surface::Ground { .. } if self.config.mat.is_some() => 0,
            Surface::Ground { x, z } => {
                let cfg = &self.config;
                match self.road_coords(x, z) {
                    None => 0,
                    Some((_, lat)) => {
                        let d = lat.abs();
                        let zone = if d < cfg.road_half_width_m {
                            1
                        } else if d < cfg.road_half_width_m + cfg.kerb_width_m {
                            2
                        } else if d < cfg.road_half_width_m
                            + cfg.kerb_width_m
                            + cfg.sidewalk_width_m
                        {
                            3
                        } else {
                            0
                        };
                        if zone == 0 || zone == 1 {
                            zone
                        } else {
                            zone + if lat < 0.0 { 8 } else { 0 }
                        }
                    }
                }
            }
            Surface::Object { index, face, .. } => (u64::from(index) + 1) << 8 | u64::from(face),
        }
    }

    /// Intensity of the sky in world direction `dir` (not normalised): a gradient with clouds.
    pub(crate) fn sky(&self, dir: &Vector3<f64>) -> f32 {
        let d = dir / dir.norm();
        let up = (-d.y).max(0.0);
        let k = 1.0 / (up + 0.25);
        let clouds = Fbm {
            base_m: 1.5,
            finest_m: 0.05,
            persistence: 0.55,
        }
        .eval(d.x * k, d.z * k, 0.0, self.seed as u32 ^ 0x5c1e);
        (218.0 + 30.0 * up as f32 + 14.0 * clouds).clamp(3.0, 252.0)
    }

    fn ground_albedo(&self, x: f64, z: f64, pixel_m: f64, sub_m: f64) -> f32 {
        let cfg = &self.config;
        if let Some(mat) = &cfg.mat {
            return mat.albedo(x, z, pixel_m, self.seed as u32);
        }
        let seed = self.seed as u32;
        let k = cfg.ground_texture_scale;
        let fine = Fbm {
            base_m: 4.0 * k,
            finest_m: 0.008 * k,
            persistence: 0.82,
        }
        .eval(x, z, pixel_m, seed ^ 0x0a5f);
        let Some((s, lat)) = self.road_coords(x, z) else {
            return verge(x, z, pixel_m, seed, k);
        };
        let d = lat.abs();
        let hw = cfg.road_half_width_m;
        if d < hw {
            let patches = Fbm {
                base_m: 12.0 * k,
                finest_m: k,
                persistence: 0.5,
            }
            .eval(x + 100.0, z, pixel_m, seed ^ 0x9a7c);
            let mut a = 0.36 + 0.09 * fine + 0.05 * smoothstep(0.1, 0.4, patches);
            // dashed centre line (3 m on, 3 m off) and solid edge lines, box-filtered
            let centre = pulse_box(lat + 0.07, 1e4, 0.14, sub_m) * pulse_box(s, 6.0, 3.0, sub_m);
            let edge_line = pulse_box(d - (hw - 0.45), 1e4, 0.12, sub_m);
            let paint = (centre + edge_line).min(1.0);
            a += paint * (0.78 + 0.05 * fine - a);
            a
        } else if d < hw + cfg.kerb_width_m {
            let joint = pulse_box(s + 0.01, 1.0, 0.02, sub_m);
            0.6 + 0.06 * fine - 0.3 * joint
        } else if d < hw + cfg.kerb_width_m + cfg.sidewalk_width_m {
            let slab = 0.6;
            let su = s;
            let sd = d - hw - cfg.kerb_width_m;
            let joint_u = pulse_box(su + 0.01, slab, 0.02, sub_m);
            let joint_d = pulse_box(sd + 0.01, slab, 0.02, sub_m);
            let joint = (joint_u + joint_d - joint_u * joint_d).min(1.0);
            let tone = cell_random(
                (su / slab).floor() as i64,
                (sd / slab).floor() as i64 + if lat < 0.0 { 1_000 } else { 0 },
                seed ^ 0x51ab,
            );
            // per-slab tone fades to its mean when slabs are smaller than a pixel
            let slab_weight = smoothstep(1.0, 2.0, (slab / pixel_m) as f32);
            let a = 0.5 + slab_weight * 0.14 * (tone - 0.5) + 0.07 * fine;
            a - 0.22 * joint
        } else {
            verge(x, z, pixel_m, seed, k)
        }
    }
}

/// Grass and gravel beside the road, its wavelengths multiplied by `scale`
/// ([`SceneConfig::ground_texture_scale`]).
fn verge(x: f64, z: f64, pixel_m: f64, seed: u32, scale: f64) -> f32 {
    let n = Fbm {
        base_m: 6.0 * scale,
        finest_m: 0.01 * scale,
        persistence: 0.8,
    }
    .eval(x, z, pixel_m, seed ^ 0x7e4a);
    0.34 + 0.16 * n
}

/// Coverage of `x` by pulses `[k period, k period + width)` under a box filter of width
/// `footprint` (the analytic integral of the pulse train), in 0..1.
#[inline]
pub(super) fn pulse_box(x: f64, period: f64, width: f64, footprint: f64) -> f32 {
    let integral = |x: f64| {
        let k = (x / period).floor();
        let r = x - k * period;
        k * width + r.min(width)
    };
    let f = footprint.max(1e-6);
    (((integral(x + 0.5 * f) - integral(x - 0.5 * f)) / f) as f32).clamp(0.0, 1.0)
}

fn object_albedo(obj: &Object, u: f64, v: f64, top: bool, pixel_m: f64, sub_m: f64) -> f32 {
    let noise = |base_m: f64, persistence: f32, salt: u32| {
        Fbm {
            base_m,
            finest_m: 0.008,
            persistence,
        }
        .eval(u, v, pixel_m, obj.seed ^ salt)
    };
    if top {
        if matches!(obj.material, Material::Foliage) {
            return obj.tone + 0.22 * noise(0.9, 0.85, 7);
        }
        return obj.tone * 0.8 + 0.08 * noise(3.0, 0.7, 1);
    }
    match obj.material {
        Material::Facade {
            bay_m,
            floor_m,
            window_w_m,
            window_h_m,
        } => {
            let wall = obj.tone + 0.08 * noise(3.0, 0.8, 2);
            // mortar courses every 0.3 m
            let mortar = pulse_box(v, 0.3, 0.015, sub_m);
            let wall = wall - 0.05 * mortar;
            let sill_m = 0.9;
            let u0 = 0.5 * (bay_m - window_w_m);
            let frame_m = 0.12;
            let win = pulse_box(u - u0, bay_m, window_w_m, sub_m)
                * pulse_box(v - sill_m, floor_m, window_h_m, sub_m);
            let frame = pulse_box(u - u0 + frame_m, bay_m, window_w_m + 2.0 * frame_m, sub_m)
                * pulse_box(
                    v - sill_m + frame_m,
                    floor_m,
                    window_h_m + 2.0 * frame_m,
                    sub_m,
                );
            let pane_tone = 0.07
                + 0.2
                    * cell_random(
                        (u / bay_m).floor() as i64,
                        ((v - sill_m) / floor_m).floor() as i64,
                        obj.seed,
                    );
            let pane_weight = smoothstep(1.0, 2.0, (window_w_m / pixel_m) as f32);
            let pane = 0.22 + pane_weight * (pane_tone - 0.22) + 0.06 * noise(1.0, 0.6, 3);
            let frame_tone = (obj.tone + 0.2).min(0.85);
            let a = wall + (frame - win).max(0.0) * (frame_tone - wall);
            a + win * (pane - a)
        }
        Material::Crate => {
            let plank = pulse_box(v + 0.01, 0.25, 0.02, sub_m);
            obj.tone + 0.1 * noise(1.0, 0.8, 4) - 0.15 * plank
        }
        Material::Pole => {
            let band = pulse_box(v, 1.0, 0.15, sub_m);
            obj.tone + 0.08 * noise(0.5, 0.7, 5) + 0.15 * band
        }
        Material::Foliage => obj.tone + 0.22 * noise(0.9, 0.85, 6),
    }
}
