//! A depth map with per-cell variance on a regular pixel grid, its uncertainty-weighted fusion
//! and its propagation to the next frame (§5).

use nalgebra::Point2;
use visnav_core::{PinholeCamera, Pose};

/// Depth (metres, along the optical axis) and its variance (m²) at the pixels
/// `(cx · stride, cy · stride)` of a grid over the image; `NaN` where unknown.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Grid stride, pixels.
    pub stride: usize,
    /// Grid columns.
    pub cols: usize,
    /// Grid rows.
    pub rows: usize,
    /// Row-major depth per cell, metres (`NaN` = unknown).
    pub depth_m: Vec<f32>,
    /// Row-major depth variance per cell, m².
    pub variance_m2: Vec<f32>,
}

impl DepthMap {
    /// An empty map covering a `width` x `height` image.
    #[must_use]
    pub fn empty(width: usize, height: usize, stride: usize) -> Self {
        let stride = stride.max(1);
        let cols = width.div_ceil(stride);
        let rows = height.div_ceil(stride);
        Self {
            stride,
            cols,
            rows,
            depth_m: vec![f32::NAN; cols * rows],
            variance_m2: vec![f32::NAN; cols * rows],
        }
    }

    /// The pixel at the centre of cell `i`.
    #[must_use]
    pub fn pixel_of(&self, i: usize) -> Point2<f64> {
        Point2::new(
            ((i % self.cols) * self.stride) as f64,
            ((i / self.cols) * self.stride) as f64,
        )
    }

    /// The cell whose pixel is nearest to `px`, if inside the grid.
    #[must_use]
    pub fn cell_of(&self, px: &Point2<f64>) -> Option<usize> {
        let cx = (px.x / self.stride as f64).round();
        let cy = (px.y / self.stride as f64).round();
        if cx < 0.0 || cy < 0.0 || !cx.is_finite() || !cy.is_finite() {
            return None;
        }
        let (cx, cy) = (cx as usize, cy as usize);
        (cx < self.cols && cy < self.rows).then_some(cy * self.cols + cx)
    }

    /// `(depth_m, variance_m2)` of cell `i` when known.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<(f64, f64)> {
        let d = self.depth_m[i];
        d.is_finite()
            .then(|| (f64::from(d), f64::from(self.variance_m2[i])))
    }

    /// Number of known cells.
    #[must_use]
    pub fn known(&self) -> usize {
        self.depth_m.iter().filter(|d| d.is_finite()).count()
    }

    /// Sets cell `i`.
    pub fn set(&mut self, i: usize, depth_m: f64, variance_m2: f64) {
        self.depth_m[i] = depth_m as f32;
        self.variance_m2[i] = variance_m2 as f32;
    }

    /// Fuses a new measurement into cell `i` by inverse-variance weighting when it agrees with the
    /// stored depth within `gate_sigma` combined standard deviations; otherwise the measurement
    /// replaces it (the newer triangulation wins on disagreement).
    pub fn fuse(&mut self, i: usize, depth_m: f64, variance_m2: f64, gate_sigma: f64) {
        match self.get(i) {
            Some((d0, v0)) if (d0 - depth_m).abs() <= gate_sigma * (v0 + variance_m2).sqrt() => {
                let w0 = 1.0 / v0.max(1e-12);
                let w1 = 1.0 / variance_m2.max(1e-12);
                self.set(i, (w0 * d0 + w1 * depth_m) / (w0 + w1), 1.0 / (w0 + w1));
            }
            _ => self.set(i, depth_m, variance_m2),
        }
    }

    /// The map seen from the next camera: every known cell is lifted to 3-D, moved by
    /// `cur_from_prev`, projected and splatted into the nearest cell of the new grid (nearest depth
    /// wins). The depth standard deviation is scaled with the depth and its variance inflated by
    /// `1 + process_noise`.
    #[must_use]
    pub fn propagate(
        &self,
        camera: &PinholeCamera,
        cur_from_prev: &Pose,
        process_noise: f64,
    ) -> Self {
        let mut out = Self {
            depth_m: vec![f32::NAN; self.depth_m.len()],
            variance_m2: vec![f32::NAN; self.depth_m.len()],
            ..*self
        };
        for i in 0..self.depth_m.len() {
            let Some((d, v)) = self.get(i) else {
                continue;
            };
            let p_prev = camera.unproject(&self.pixel_of(i), d);
            let p_cur = cur_from_prev * p_prev;
            let Some(px) = camera.project(&p_cur) else {
                continue;
            };
            let Some(j) = out.cell_of(&px) else {
                continue;
            };
            let z = p_cur.z;
            let old = out.depth_m[j];
            if old.is_finite() && f64::from(old) <= z {
                continue;
            }
            let ratio = z / d;
            out.set(j, z, v * ratio * ratio * (1.0 + process_noise));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn propagation_of_a_wall_and_fusion() {
        let cam = PinholeCamera::new(100.0, 100.0, 40.0, 30.0, 81, 61).unwrap();
        let mut map = DepthMap::empty(81, 61, 2);
        for i in 0..map.depth_m.len() {
            map.set(i, 10.0, 0.04);
        }
        // move 1 m forward: the wall at 10 m is at 9 m
        let cur_from_prev = Pose::from_parts(
            Translation3::new(0.0, 0.0, -1.0),
            UnitQuaternion::identity(),
        );
        let next = map.propagate(&cam, &cur_from_prev, 0.0);
        let centre = next.cell_of(&Point2::new(40.0, 30.0)).unwrap();
        let (d, v) = next.get(centre).unwrap();
        assert!((d - 9.0).abs() < 1e-5);
        assert!((v - 0.04 * 0.81).abs() < 1e-6);
        // edge cells expand outside the view: the border becomes unknown
        assert!(next.known() < map.known());
        let mut fused = next.clone();
        fused.fuse(centre, 9.2, v, 3.0);
        assert!((fused.get(centre).unwrap().0 - 9.1).abs() < 1e-5);
        fused.fuse(centre, 20.0, v, 3.0);
        assert!((fused.get(centre).unwrap().0 - 20.0).abs() < 1e-5);
    }
}
