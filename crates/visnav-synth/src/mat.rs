//! An indoor floor mat ([`MatConfig`]): a near-uniform grey with a weak band-limited texture and
//! sparse round markers of other grey levels (a real small drone's test floor: a grey mat with a
//! few per cent of coloured blobs, which a grey camera sees as darker or lighter discs).
//!
//! Coordinates are the ground's `(x, z)` in metres; markers are discs, at most one per cell of
//! a `marker_cell_m` grid, their edges filtered analytically over the pixel footprint (no
//! supersampling needed: the mat is one smooth surface to the renderer).

use serde::{Deserialize, Serialize};

use crate::SynthError;
use crate::noise::{Fbm, cell_random, smoothstep};

/// The floor mat of an indoor flight (see the module docs). Albedos are in 0..1 (the renderer
/// lights the floor to about 242 grey levels per unit albedo).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatConfig {
    /// The mat's mean albedo. Default 0.5 (about 121 grey levels).
    pub albedo: f64,
    /// Amplitude of the mat's own texture, albedo (a band-limited fractal noise of roughly unit
    /// amplitude times this). Default 0.08: a standard deviation of about 3 grey levels.
    pub texture_amplitude: f64,
    /// Coarsest wavelength of the mat's texture, metres. Default 0.5.
    pub texture_wavelength_m: f64,
    /// Finest wavelength of the mat's texture (its grain), metres. Default 0.0005.
    pub texture_finest_m: f64,
    /// Fraction of the floor covered by markers. Default 0.03.
    pub marker_fraction: f64,
    /// Side of the grid cells that hold at most one marker each, metres. Default 0.6.
    pub marker_cell_m: f64,
    /// Smallest and largest marker radius, metres. Default 0.04..0.12.
    pub marker_radius_m: [f64; 2],
    /// Albedo range of the dark markers; half the markers are dark. Default 0.1..0.3.
    pub dark_marker_albedo: [f64; 2],
    /// Albedo range of the light markers. Default 0.75..0.95.
    pub light_marker_albedo: [f64; 2],
}

impl Default for MatConfig {
    fn default() -> Self {
        Self {
            albedo: 0.5,
            texture_amplitude: 0.08,
            texture_wavelength_m: 0.5,
            texture_finest_m: 0.0005,
            marker_fraction: 0.03,
            marker_cell_m: 0.6,
            marker_radius_m: [0.04, 0.12],
            dark_marker_albedo: [0.1, 0.3],
            light_marker_albedo: [0.75, 0.95],
        }
    }
}

impl MatConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`SynthError::InvalidConfig`] naming the offending field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |field: &str, message: &str| {
            Err(SynthError::InvalidConfig {
                field: format!("mat.{field}"),
                message: message.into(),
            })
        };
        let unit = |v: f64| v.is_finite() && (0.0..=1.0).contains(&v);
        let unit_range = |r: [f64; 2]| unit(r[0]) && unit(r[1]) && r[0] <= r[1];
        if !unit(self.albedo) {
            return bad("albedo", "must be within 0..=1");
        }
        if !(self.texture_amplitude.is_finite() && (0.0..=0.5).contains(&self.texture_amplitude)) {
            return bad("texture_amplitude", "must be within 0..=0.5");
        }
        if !(self.texture_finest_m.is_finite()
            && self.texture_finest_m > 0.0
            && self.texture_wavelength_m.is_finite()
            && self.texture_wavelength_m >= self.texture_finest_m
            && self.texture_wavelength_m <= 1e3)
        {
            return bad(
                "texture_wavelength_m",
                "need 0 < texture_finest_m <= texture_wavelength_m <= 1000",
            );
        }
        if !unit(self.marker_fraction) {
            return bad("marker_fraction", "must be within 0..=1");
        }
        let [r_min, r_max] = self.marker_radius_m;
        if !(r_min.is_finite() && r_min > 0.0 && r_max >= r_min && r_max.is_finite()) {
            return bad("marker_radius_m", "need 0 < smallest <= largest");
        }
        if !(self.marker_cell_m.is_finite()
            && self.marker_cell_m > 2.0 * r_max
            && self.marker_cell_m <= 1e3)
        {
            return bad(
                "marker_cell_m",
                "must exceed the largest marker's diameter and be at most 1000 m",
            );
        }
        if !unit_range(self.dark_marker_albedo) {
            return bad("dark_marker_albedo", "need 0 <= low <= high <= 1");
        }
        if !unit_range(self.light_marker_albedo) {
            return bad("light_marker_albedo", "need 0 <= low <= high <= 1");
        }
        Ok(())
    }

    /// The probability that a cell holds a marker: the marker fraction over the mean disc's
    /// share of a cell (at most 1).
    fn marker_probability(&self) -> f64 {
        let [r_min, r_max] = self.marker_radius_m;
        // mean of r² for r uniform in [r_min, r_max]
        let mean_r2 = (r_min * r_min + r_min * r_max + r_max * r_max) / 3.0;
        let disc_share = std::f64::consts::PI * mean_r2 / (self.marker_cell_m * self.marker_cell_m);
        (self.marker_fraction / disc_share).min(1.0)
    }

    /// The mat's albedo at `(x, z)` (metres) seen with a pixel footprint of `pixel_m` metres.
    #[must_use]
    pub fn albedo(&self, x: f64, z: f64, pixel_m: f64, seed: u32) -> f32 {
        let texture = Fbm {
            base_m: self.texture_wavelength_m,
            finest_m: self.texture_finest_m,
            persistence: 0.8,
        }
        .eval(x, z, pixel_m, seed ^ 0x3a71);
        let base = (self.albedo + self.texture_amplitude * f64::from(texture)) as f32;
        let cell = self.marker_cell_m;
        let (ix, iz) = ((x / cell).floor() as i64, (z / cell).floor() as i64);
        let pick = |salt: u32| f64::from(cell_random(ix, iz, seed ^ salt));
        if pick(0x6d61) >= self.marker_probability() {
            return base;
        }
        let [r_min, r_max] = self.marker_radius_m;
        let radius = r_min + (r_max - r_min) * pick(0x7261);
        // the centre keeps the whole disc inside its cell
        let free = cell - 2.0 * radius;
        let cx = (ix as f64) * cell + radius + free * pick(0x6378);
        let cz = (iz as f64) * cell + radius + free * pick(0x637a);
        let range = if pick(0x6c64) < 0.5 {
            self.dark_marker_albedo
        } else {
            self.light_marker_albedo
        };
        let marker = (range[0] + (range[1] - range[0]) * pick(0x616c)) as f32;
        let d = ((x - cx).powi(2) + (z - cz).powi(2)).sqrt();
        let half = 0.5 * pixel_m.max(1e-6);
        // coverage of the pixel by the disc: 1 inside, 0 outside, a ramp over the footprint
        let cover = 1.0 - smoothstep((radius - half) as f32, (radius + half) as f32, d as f32);
        base + cover * (marker - base)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The markers cover about the configured fraction of the floor and the mat between them
    /// is a weak texture around its albedo.
    #[test]
    fn markers_cover_their_fraction_and_the_mat_is_weak() {
        let mat = MatConfig::default();
        let (mut markers, mut n) = (0usize, 0usize);
        let mut plain = Vec::new();
        for i in 0..400 {
            for j in 0..400 {
                let (x, z) = (f64::from(i) * 0.0301, f64::from(j) * 0.0299);
                let a = f64::from(mat.albedo(x, z, 0.004, 5));
                n += 1;
                if (a - mat.albedo).abs() > 0.18 {
                    markers += 1;
                } else {
                    plain.push(a);
                }
            }
        }
        let fraction = markers as f64 / n as f64;
        assert!(
            (0.01..0.06).contains(&fraction),
            "marker fraction {fraction}"
        );
        let mean = plain.iter().sum::<f64>() / plain.len() as f64;
        let sd =
            (plain.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / plain.len() as f64).sqrt();
        assert!(
            (mean - mat.albedo).abs() < 0.02 && sd > 0.003 && sd < 0.04,
            "{mean} {sd}"
        );
    }

    #[test]
    fn invalid_mats_are_errors() {
        for mat in [
            MatConfig {
                albedo: 1.5,
                ..MatConfig::default()
            },
            MatConfig {
                marker_cell_m: 0.1,
                ..MatConfig::default()
            },
            MatConfig {
                marker_radius_m: [0.1, 0.05],
                ..MatConfig::default()
            },
            MatConfig {
                texture_finest_m: 0.0,
                ..MatConfig::default()
            },
        ] {
            assert!(matches!(
                mat.validate(),
                Err(SynthError::InvalidConfig { .. })
            ));
        }
    }
}
