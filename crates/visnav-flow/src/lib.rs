//! Dense optical flow with per-pixel bivariate Gaussian uncertainty (being built).
//! Spec: Ng, Li, Kim 2021, section 3; DCFlow (Xu, Ranftl, Koltun 2017).

/// Dense flow from image 1 to image 2 at full resolution, with its uncertainty.
///
/// Per pixel `i = y * width + x`: `flow[i] = (u, v)` in pixels (`x2 = x + u`, `y2 = y + v`);
/// `information[i] = (Yxx, Yxy, Yyy)` the information matrix (inverse covariance) of the flow,
/// in 1/px², always positive definite; `valid[i]` whether the pixel passed the forward–backward
/// check (invalid pixels carry interpolated flow and the maximum uncertainty).
#[derive(Debug, Clone, PartialEq)]
pub struct DenseFlow {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `(u, v)` per pixel, row-major.
    pub flow: Vec<[f32; 2]>,
    /// `(Yxx, Yxy, Yyy)` per pixel, 1/px².
    pub information: Vec<[f32; 3]>,
    /// Forward–backward consistency per pixel.
    pub valid: Vec<bool>,
}
