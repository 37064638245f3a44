//! The fundamental matrix of an image pair from tracked corners (for the epipolar cost of the
//! dense flow, §3.1 of the monocular paper): Shi–Tomasi corners in image 1 tracked into image 2
//! by pyramidal KLT (`visnav-image`), then the normalised eight-point algorithm (eq. 6) inside
//! RANSAC, seeded for repeatability.

use crate::{Correspondence, EightPointConfig, estimate_fundamental, seeded_rng};
use nalgebra::Matrix3;
use visnav_core::GrayImage;
use visnav_image::{CornerConfig, KltConfig, Pyramid, detect_corners, track};

/// The fundamental matrix (`x2ᵀ F x1 = 0`, full-resolution pixels) from corners tracked between
/// the two images; `None` when too few tracks survive or RANSAC finds no model.
#[must_use]
pub fn fundamental_from_tracks(
    img1: &GrayImage,
    img2: &GrayImage,
    seed: u64,
) -> Option<Matrix3<f64>> {
    let corners = detect_corners(img1, &CornerConfig::default());
    if corners.len() < 16 {
        return None;
    }
    let p1 = Pyramid::build(img1, 4);
    let p2 = Pyramid::build(img2, 4);
    let points: Vec<_> = corners.iter().map(|c| c.px).collect();
    let tracks = track(&p1, &p2, &points, None, &KltConfig::default()).ok()?;
    let data: Vec<Correspondence> = points
        .iter()
        .zip(&tracks)
        .filter_map(|(a, t)| t.tracked().map(|b| Correspondence::isotropic(*a, b, 1.0)))
        .collect();
    if data.len() < 16 {
        return None;
    }
    let mut rng = seeded_rng(seed);
    estimate_fundamental(&data, &EightPointConfig::default(), &mut rng).map(|r| r.model)
}
