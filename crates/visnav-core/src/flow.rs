//! A dense optical flow field without uncertainty (ground truth, `.flo` files, renderings).

/// A dense flow field: `uv[2 * (y * width + x)]` is u (pixels, +x), the next entry v (+y).
#[derive(Debug, Clone, PartialEq)]
pub struct FlowField {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Interleaved `(u, v)` per pixel, row-major.
    pub uv: Vec<f32>,
}

impl FlowField {
    /// A zero flow field.
    #[must_use]
    pub fn zeros(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            uv: vec![0.0; 2 * width * height],
        }
    }

    /// Flow `(u, v)` at a pixel.
    #[must_use]
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> (f32, f32) {
        let i = 2 * (y * self.width + x);
        (self.uv[i], self.uv[i + 1])
    }

    /// Sets the flow at a pixel.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, u: f32, v: f32) {
        let i = 2 * (y * self.width + x);
        self.uv[i] = u;
        self.uv[i + 1] = v;
    }

    /// Whether the flow at a pixel is known (both components finite and below 1e9).
    #[must_use]
    pub fn is_known(&self, x: usize, y: usize) -> bool {
        let (u, v) = self.get(x, y);
        u.is_finite() && v.is_finite() && u.abs() < 1e9 && v.abs() < 1e9
    }
}
