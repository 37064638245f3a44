//! Procedural texture primitives: a hashed lattice, 2-D value noise with a quintic fade, and a
//! band-limited fractal sum (fBm) whose octaves fade out below the pixel footprint so textures
//! carry detail at every scale the camera can resolve without aliasing.
//!
//! All coordinates are surface coordinates in metres; the result depends only on the position
//! on the surface (and on the footprint through the band limit), never on the view otherwise.

/// A 32-bit integer hash of a lattice point and a seed (avalanche mix of three products).
#[inline]
#[must_use]
pub fn hash2(ix: i64, iy: i64, seed: u32) -> u32 {
    let mut h = (ix as u32).wrapping_mul(0x8da6_b343)
        ^ (iy as u32).wrapping_mul(0xd816_3841)
        ^ seed.wrapping_mul(0xcb1a_b31f)
        ^ ((ix >> 32) as u32).wrapping_mul(0x2545_f491)
        ^ ((iy >> 32) as u32).wrapping_mul(0x9e37_79b9);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297a_2d39);
    h ^= h >> 15;
    h
}

/// A hashed value in `[0, 1]` for an integer cell (per-tile tones, random choices).
#[inline]
#[must_use]
pub fn cell_random(ix: i64, iy: i64, seed: u32) -> f32 {
    hash2(ix, iy, seed) as f32 * (1.0 / u32::MAX as f32)
}

#[inline]
fn lattice(ix: i64, iy: i64, seed: u32) -> f32 {
    cell_random(ix, iy, seed) * 2.0 - 1.0
}

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// 2-D value noise in `[-1, 1]` with unit lattice spacing and C2 quintic interpolation.
#[inline]
#[must_use]
pub fn value_noise(x: f64, y: f64, seed: u32) -> f32 {
    let fx = x.floor();
    let fy = y.floor();
    let ix = fx as i64;
    let iy = fy as i64;
    let sx = fade((x - fx) as f32);
    let sy = fade((y - fy) as f32);
    let a = lattice(ix, iy, seed);
    let b = lattice(ix + 1, iy, seed);
    let c = lattice(ix, iy + 1, seed);
    let d = lattice(ix + 1, iy + 1, seed);
    // smooth-step interpolation of an unbounded lattice, not a sampled grid (not
    // `visnav_core::bilinear`)
    let top = a + (b - a) * sx;
    let bottom = c + (d - c) * sx;
    top + (bottom - top) * sy
}

/// Smooth step from 0 at `e0` to 1 at `e1`.
#[inline]
#[must_use]
pub fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Weight of an octave of wavelength `lambda_m` seen with a pixel footprint `footprint_m`:
/// 1 when the wavelength spans at least 3 pixels, 0 below 1.5 pixels (band limit below the
/// Nyquist rate of the pixel grid).
#[inline]
#[must_use]
pub fn band_weight(lambda_m: f64, footprint_m: f64) -> f32 {
    smoothstep(1.5, 3.0, (lambda_m / footprint_m.max(1e-9)) as f32)
}

/// Parameters of a fractal noise sum.
#[derive(Debug, Clone, Copy)]
pub struct Fbm {
    /// Wavelength of the coarsest octave, metres.
    pub base_m: f64,
    /// Wavelength below which no octave is added, metres (finest physical detail).
    pub finest_m: f64,
    /// Amplitude ratio between successive octaves (each octave halves the wavelength).
    pub persistence: f32,
}

impl Fbm {
    /// Band-limited fractal value noise at `(x, y)` (metres), roughly in `[-1, 1]`; octaves
    /// finer than the pixel footprint are replaced by their mean (zero), so distant surfaces
    /// become smoother instead of aliasing.
    #[inline]
    #[must_use]
    pub fn eval(&self, x: f64, y: f64, footprint_m: f64, seed: u32) -> f32 {
        let mut lambda = self.base_m;
        let mut amp = 1.0f32;
        let mut sum = 0.0f32;
        let mut norm = 0.0f32;
        let mut octave = 0u32;
        while lambda >= self.finest_m && octave < 20 {
            let w = band_weight(lambda, footprint_m);
            if w > 0.0 {
                // shift each octave so that lattice points of different octaves do not line up
                let off = f64::from(octave) * 7.31;
                sum += amp
                    * w
                    * value_noise(
                        x / lambda + off,
                        y / lambda - off,
                        seed.wrapping_add(octave),
                    );
            }
            norm += amp;
            lambda *= 0.5;
            amp *= self.persistence;
            octave += 1;
        }
        if norm > 0.0 { 1.6 * sum / norm } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_noise_is_continuous_and_bounded() {
        let mut max_jump = 0.0f32;
        let mut prev = value_noise(-3.0, 2.5, 7);
        for i in 1..20_000 {
            let x = -3.0 + f64::from(i) * 1e-4;
            let v = value_noise(x, 2.5, 7);
            assert!((-1.0..=1.0).contains(&v));
            max_jump = max_jump.max((v - prev).abs());
            prev = v;
        }
        assert!(max_jump < 1e-3, "jump {max_jump}");
        // lattice values are reproduced exactly
        assert!((value_noise(4.0, -2.0, 3) - lattice(4, -2, 3)).abs() < 1e-7);
        assert_ne!(value_noise(0.3, 0.7, 1), value_noise(0.3, 0.7, 2));
    }

    #[test]
    fn fbm_fades_octaves_below_footprint() {
        let f = Fbm {
            base_m: 1.0,
            finest_m: 0.01,
            persistence: 0.7,
        };
        // a huge footprint removes every octave
        assert_eq!(f.eval(0.37, 0.11, 100.0, 1), 0.0);
        // a fine footprint keeps fine detail: neighbouring points 1 cm apart differ
        let a = f.eval(0.37, 0.11, 0.001, 1);
        let b = f.eval(0.38, 0.11, 0.001, 1);
        assert!((a - b).abs() > 1e-4);
        // a coarse footprint makes the same neighbours nearly equal
        let c = f.eval(0.37, 0.11, 0.5, 1);
        let d = f.eval(0.38, 0.11, 0.5, 1);
        assert!((c - d).abs() < (a - b).abs());
    }
}
