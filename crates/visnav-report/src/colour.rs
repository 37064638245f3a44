//! Colour maps of the flow, its uncertainty and depth, and the legends that explain them.
//!
//! * Flow: the Middlebury colour wheel — hue is the direction of `(u, v)` (image x right, y
//!   down), saturation the magnitude relative to a scale `max_px` (white = no motion, full
//!   colour = `max_px` or more).
//! * Uncertainty: the 1-sigma radius `sqrt(trace(P) / 2)` in pixels of the flow covariance
//!   `P = Y⁻¹` (Ng, Li & Kim 2021, eq. 1: the bivariate Gaussian of each pixel), on a log scale
//!   from [`SIGMA_MIN_PX`] (blue) to [`SIGMA_MAX_PX`] (red).
//! * Depth: metres, linear between a near and a far limit, on the viridis map (yellow = near,
//!   dark blue = far); unknown depth is grey.
//!
//! Legends are small inline SVG documents (text in the page's font), so every image in the
//! report carries its scale.

use std::fmt::Write as _;

/// Smallest 1-sigma radius of the uncertainty colour scale, pixels (blue).
pub const SIGMA_MIN_PX: f32 = 0.1;
/// Largest 1-sigma radius of the uncertainty colour scale, pixels (red).
pub const SIGMA_MAX_PX: f32 = 10.0;
/// Colour of pixels without a value (unknown depth, singular information).
pub const UNKNOWN_RGB: [u8; 3] = [96, 96, 96];

/// HSV (all in 0..1) to 8-bit RGB.
#[must_use]
pub fn hsv(h: f32, s: f32, v: f32) -> [u8; 3] {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let p = v * (1.0 - s);
    let q = v * (1.0 - f * s);
    let t = v * (1.0 - (1.0 - f) * s);
    let (r, g, b) = match (i as i32).rem_euclid(6) {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// Colour of a flow vector `(u, v)` in pixels: hue = direction, saturation = `|(u, v)| / max_px`
/// (clamped to 1).
#[must_use]
pub fn flow_rgb(uv: [f32; 2], max_px: f32) -> [u8; 3] {
    if !(uv[0].is_finite() && uv[1].is_finite()) {
        return UNKNOWN_RGB;
    }
    let mag = (uv[0].hypot(uv[1]) / max_px.max(1e-6)).min(1.0);
    let hue = (uv[1].atan2(uv[0]) / std::f32::consts::TAU + 1.0) % 1.0;
    hsv(hue, mag, 1.0)
}

/// The largest finite flow magnitude of a field, pixels (at least 1e-6).
#[must_use]
pub fn max_magnitude_px(uv: impl Iterator<Item = [f32; 2]>) -> f32 {
    uv.map(|f| f[0].hypot(f[1]))
        .filter(|m| m.is_finite())
        .fold(1e-6_f32, f32::max)
}

/// The 1-sigma radius `sqrt(trace(P) / 2)` of the covariance `P` of an information matrix
/// `(Yxx, Yxy, Yyy)` in 1/px², pixels; infinite for a singular information.
#[must_use]
pub fn sigma_px(information: [f32; 3]) -> f32 {
    visnav_core::Information2::from_array(information)
        .covariance_px2()
        .map_or(f32::INFINITY, |c| (0.5 * (c[0] + c[2])).max(1e-12).sqrt())
}

/// Position of a 1-sigma radius on the log scale `[SIGMA_MIN_PX, SIGMA_MAX_PX]`, 0..1.
fn sigma_t(sigma_px: f32) -> f32 {
    let (lo, hi) = (SIGMA_MIN_PX.log10(), SIGMA_MAX_PX.log10());
    ((sigma_px.max(1e-12).log10() - lo) / (hi - lo)).clamp(0.0, 1.0)
}

/// Colour of a 1-sigma radius in pixels: blue (certain, ≤ 0.1 px) to red (≥ 10 px), log scale.
#[must_use]
pub fn sigma_rgb(sigma_px: f32) -> [u8; 3] {
    if sigma_px.is_nan() {
        return UNKNOWN_RGB;
    }
    hsv(0.66 * (1.0 - sigma_t(sigma_px)), 1.0, 1.0)
}

/// Viridis at 9 control points (t = 0, 1/8, …, 1).
const VIRIDIS: [[f32; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

/// Viridis colour at `t` in 0..1 (dark blue to yellow), linear between the control points.
#[must_use]
pub fn viridis(t: f32) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * 8.0;
    let k = (x.floor() as usize).min(7);
    let f = x - k as f32;
    let (a, b) = (VIRIDIS[k], VIRIDIS[k + 1]);
    [0, 1, 2].map(|c| (a[c] + f * (b[c] - a[c])).round().clamp(0.0, 255.0) as u8)
}

/// Colour of a depth in metres between `near_m` (yellow) and `far_m` (dark blue); unknown
/// (non-finite or non-positive) depth is grey.
#[must_use]
pub fn depth_rgb(depth_m: f32, near_m: f32, far_m: f32) -> [u8; 3] {
    if !(depth_m.is_finite() && depth_m > 0.0) {
        return UNKNOWN_RGB;
    }
    let t = (depth_m - near_m) / (far_m - near_m).max(1e-6);
    viridis(1.0 - t)
}

/// The 2nd and 98th percentiles of the known depths, metres (`None` without known depth).
#[must_use]
pub fn depth_range_m(depth_m: &[f32]) -> Option<(f32, f32)> {
    let mut known: Vec<f32> = depth_m
        .iter()
        .copied()
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if known.is_empty() {
        return None;
    }
    known.sort_by(f32::total_cmp);
    let at = |q: f32| known[((known.len() - 1) as f32 * q).round() as usize];
    let (near, far) = (at(0.02), at(0.98));
    Some((near, if far > near { far } else { near + 1.0 }))
}

/// A horizontal colour bar with tick labels as an SVG document: `colour(t)` for t in 0..1 left
/// to right, `ticks` as `(t, label)`, `title` above (include the unit).
#[must_use]
pub fn colour_bar_svg(
    title: &str,
    colour: impl Fn(f32) -> [u8; 3],
    ticks: &[(f32, String)],
) -> String {
    const W: f32 = 280.0;
    const X0: f32 = 28.0;
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" class="legend" width="{w}" height="64" viewBox="0 0 {w} 64"><text x="{X0}" y="14" font-size="13">{title}</text><defs><linearGradient id="g{id}">"#,
        w = W + 2.0 * X0,
        title = super::html::escape(title),
        id = legend_id(title),
    );
    for k in 0..=16 {
        let t = k as f32 / 16.0;
        let [r, g, b] = colour(t);
        let _ = write!(
            svg,
            r#"<stop offset="{:.4}" stop-color="rgb({r},{g},{b})"/>"#,
            t
        );
    }
    let _ = write!(
        svg,
        r##"</linearGradient></defs><rect x="{X0}" y="20" width="{W}" height="16" fill="url(#g{id})" stroke="#333"/>"##,
        id = legend_id(title),
    );
    for (t, label) in ticks {
        let x = X0 + t.clamp(0.0, 1.0) * W;
        let _ = write!(
            svg,
            r##"<line x1="{x:.1}" y1="36" x2="{x:.1}" y2="41" stroke="#333"/><text x="{x:.1}" y="55" font-size="12" text-anchor="middle">{}</text>"##,
            super::html::escape(label)
        );
    }
    svg.push_str("</svg>");
    svg
}

/// A stable element id for a legend title (gradients need page-unique ids).
fn legend_id(title: &str) -> String {
    title
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// The legend of the uncertainty map: 1-sigma radius in pixels, log scale.
#[must_use]
pub fn sigma_legend_svg() -> String {
    let ticks = [0.1f32, 0.3, 1.0, 3.0, 10.0]
        .map(|s| (sigma_t(s), format!("{s} px")))
        .to_vec();
    colour_bar_svg(
        "flow uncertainty: 1-sigma radius [px], log scale",
        |t| hsv(0.66 * (1.0 - t), 1.0, 1.0),
        &ticks,
    )
}

/// The legend of a depth map between `near_m` and `far_m` metres.
#[must_use]
pub fn depth_legend_svg(near_m: f32, far_m: f32) -> String {
    let ticks = (0..=4)
        .map(|k| {
            let t = k as f32 / 4.0;
            (t, format!("{:.1} m", near_m + t * (far_m - near_m)))
        })
        .collect::<Vec<_>>();
    colour_bar_svg(
        &format!("depth [m], {near_m:.1} to {far_m:.1} m (grey: unknown)"),
        |t| viridis(1.0 - t),
        &ticks,
    )
}

/// RGB pixels of a colour-wheel disc of `size`×`size` pixels: the flow colour of the vector from
/// the centre, the rim being `max_px` (outside the disc: white).
#[must_use]
pub fn wheel_rgb(size: usize) -> Vec<u8> {
    let c = (size as f32 - 1.0) / 2.0;
    let mut rgb = Vec::with_capacity(size * size * 3);
    for y in 0..size {
        for x in 0..size {
            let (u, v) = ((x as f32 - c) / c, (y as f32 - c) / c);
            let px = if u.hypot(v) <= 1.0 {
                flow_rgb([u, v], 1.0)
            } else {
                [255, 255, 255]
            };
            rgb.extend_from_slice(&px);
        }
    }
    rgb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_colours_follow_direction_and_magnitude() {
        // no motion is white, full motion to the right is red, down (+y) is yellow-green
        assert_eq!(flow_rgb([0.0, 0.0], 5.0), [255, 255, 255]);
        assert_eq!(flow_rgb([5.0, 0.0], 5.0), [255, 0, 0]);
        assert_eq!(flow_rgb([50.0, 0.0], 5.0), [255, 0, 0]);
        let down = flow_rgb([0.0, 5.0], 5.0);
        assert!(down[1] > 200 && down[2] == 0, "{down:?}");
        let half = flow_rgb([2.5, 0.0], 5.0);
        assert!(half[0] == 255 && half[1] > 100 && half[1] < 160, "{half:?}");
        assert_eq!(flow_rgb([f32::NAN, 0.0], 5.0), UNKNOWN_RGB);
    }

    #[test]
    fn sigma_scale_is_log_blue_to_red() {
        // information 1/σ² on both axes gives σ
        assert!((sigma_px([4.0, 0.0, 4.0]) - 0.5).abs() < 1e-6);
        assert!(sigma_px([0.0, 0.0, 0.0]).is_infinite());
        assert_eq!(sigma_rgb(0.01), hsv(0.66, 1.0, 1.0));
        assert_eq!(sigma_rgb(100.0), [255, 0, 0]);
        assert_eq!(sigma_rgb(f32::INFINITY), [255, 0, 0]);
        assert!((sigma_t(1.0) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn depth_colours_and_range() {
        assert_eq!(depth_rgb(f32::NAN, 1.0, 10.0), UNKNOWN_RGB);
        assert_eq!(depth_rgb(1.0, 1.0, 10.0), [253, 231, 37]);
        assert_eq!(depth_rgb(10.0, 1.0, 10.0), [68, 1, 84]);
        let d: Vec<f32> = (1..=100).map(|i| i as f32).chain([f32::NAN]).collect();
        let (near, far) = depth_range_m(&d).unwrap();
        assert!(
            (near - 3.0).abs() < 1.01 && (far - 98.0).abs() < 1.01,
            "{near} {far}"
        );
        assert_eq!(depth_range_m(&[f32::NAN]), None);
    }

    #[test]
    fn legends_carry_units_and_ticks() {
        let s = sigma_legend_svg();
        assert!(s.contains("0.1 px") && s.contains("10 px") && s.contains("<linearGradient"));
        let d = depth_legend_svg(2.0, 40.0);
        assert!(d.contains("2.0 m") && d.contains("40.0 m"));
        let w = wheel_rgb(9);
        assert_eq!(w.len(), 9 * 9 * 3);
        // centre is white (no motion), the right rim red
        assert_eq!(&w[(4 * 9 + 4) * 3..(4 * 9 + 4) * 3 + 3], &[255, 255, 255]);
        assert_eq!(&w[(4 * 9 + 8) * 3..(4 * 9 + 8) * 3 + 3], &[255, 0, 0]);
    }
}
