//! A stereo baseline that no camera rig has: the translation of a stereo calibration written in
//! millimetres (or centimetres) where metres are expected. KITTI's 0.537 m rig written in
//! millimetres reads as a 537 m baseline: the run goes on, its depths and trajectory 1000× too
//! large. Such a calibration is read (the numbers may be what the user means) with a warning
//! that names the file, the field, the value and the likely unit.
//!
//! The evidence for "impossible": a rigid stereo rig spans at most a few metres (the public
//! driving rigs: KITTI 0.54 m, EuRoC 0.11 m), and the images say the same: two parallel cameras
//! of focal length `fx` pixels and `width` pixels share no point nearer than
//! `fx · b / width` metres (the disparity `fx · b / Z` of a point seen by both is below the image
//! width). KITTI's 1241-pixel images with fx = 718.9 px share every point beyond 0.31 m at the
//! real baseline, but nothing nearer than 311 m at 537 m: no scene a camera rig moves through.
//! Above [`MAX_PLAUSIBLE_BASELINE_M`] the warning is given; a millimetre error of any rig wider
//! than 1 cm and a centimetre error of any rig wider than 10 cm exceed it, and no real rig does.
//!
//! The stereo constants of a rectified pair's projection matrices live here too (the baseline
//! `rectified_baseline`, the principal-point offset `right_cx_offset`), shared by the layouts that
//! read such matrices (KITTI's `calib.txt`, a bag's `CameraInfo`).

use std::path::Path;

use nalgebra::Matrix3x4;
use visnav_core::PinholeCamera;

use crate::error::{IoError, Result};

/// Widest stereo baseline taken without a warning, metres.
pub const MAX_PLAUSIBLE_BASELINE_M: f64 = 10.0;

/// Plausible baselines of real stereo rigs, metres (phones to cars), for the "likely unit"
/// guess.
const RIG_RANGE_M: std::ops::RangeInclusive<f64> = 0.005..=3.0;

/// Why `baseline_m` is impossible for a rig whose (left) camera is `camera`, or `None` when it
/// is plausible (see the module docs).
#[must_use]
pub fn implausible_baseline(baseline_m: f64, camera: &PinholeCamera) -> Option<String> {
    if !(baseline_m.is_finite() && baseline_m > MAX_PLAUSIBLE_BASELINE_M) {
        return None;
    }
    let nearest_shared_m = camera.fx * baseline_m / f64::from(camera.width.max(1));
    let units: Vec<String> = [(1000.0, "millimetres"), (100.0, "centimetres")]
        .into_iter()
        .filter(|(per_m, _)| RIG_RANGE_M.contains(&(baseline_m / per_m)))
        .map(|(per_m, unit)| format!("{unit} ({:.4} m)", baseline_m / per_m))
        .collect();
    let unit = if units.is_empty() {
        "the translation in another unit than metres?".to_owned()
    } else {
        format!("the translation written in {}?", units.join(" or "))
    };
    let shown = format!("{baseline_m:.4}");
    let shown = shown.trim_end_matches('0').trim_end_matches('.');
    Some(format!(
        "stereo baseline {shown} m is impossible for a camera rig (over {MAX_PLAUSIBLE_BASELINE_M} m: \
         its two {}-pixel-wide images with fx {:.1} px would share no point nearer than {nearest_shared_m:.0} m); \
         {unit}",
        camera.width, camera.fx
    ))
}

/// Logs a warning naming `path` and `field` when `baseline_m` is impossible (see
/// [`implausible_baseline`]); returns the message.
pub fn warn_if_implausible(
    path: &Path,
    field: &str,
    baseline_m: f64,
    camera: &PinholeCamera,
) -> Option<String> {
    let why = implausible_baseline(baseline_m, camera)?;
    let message = format!("{}: {field}: {why}", path.display());
    log::warn!("{message}");
    Some(message)
}

/// The baseline of a KITTI rectified pair, `−P1[0][3] / P1[0][0]` metres (`field` names the
/// matrix: `P1`, or `P_rect_01` of a raw drive), with the warning of [`warn_if_implausible`]
/// naming the field.
///
/// # Errors
/// A baseline that is not positive (the right camera is not on the right), naming the file.
pub(crate) fn rectified_baseline(
    p1: &Matrix3x4<f64>,
    calib_path: &Path,
    field: &str,
    camera: &PinholeCamera,
) -> Result<f64> {
    let b = -p1[(0, 3)] / p1[(0, 0)];
    if !(b.is_finite() && b > 0.0) {
        return Err(IoError::Format {
            path: calib_path.to_path_buf(),
            message: format!("stereo baseline -{field}[0][3]/{field}[0][0] = {b} is not positive"),
        });
    }
    warn_if_implausible(
        calib_path,
        &format!("{field} (baseline -{field}[0][3]/{field}[0][0])"),
        b,
        camera,
    );
    Ok(b)
}

/// The right projection's principal-point column minus the left one's (`P1` and `P0` of a KITTI
/// `calib.txt`, or the right and left `CameraInfo` `P` of a bag), after checking that the two
/// describe one rectified pair: the same focal lengths and principal-point row (a pair whose rows
/// differ is not rectified, and its disparities would be wrong silently).
pub(crate) fn right_cx_offset(
    p0: &Matrix3x4<f64>,
    p1: &Matrix3x4<f64>,
    calib_path: &Path,
) -> Result<f64> {
    // a NaN differs too
    let differs =
        |a: f64, b: f64, tolerance: f64| (a - b).abs().is_nan() || (a - b).abs() > tolerance;
    let (fx, fy, cy) = (p0[(0, 0)], p0[(1, 1)], p0[(1, 2)]);
    let problem = if differs(p1[(0, 0)], fx, 1e-6 * fx.abs())
        || differs(p1[(1, 1)], fy, 1e-6 * fy.abs())
    {
        Some(format!(
            "P1's focal lengths ({}, {}) differ from P0's ({fx}, {fy}): not a rectified pair",
            p1[(0, 0)],
            p1[(1, 1)]
        ))
    } else if differs(p1[(1, 2)], cy, 1e-6 * cy.abs().max(1.0)) {
        Some(format!(
            "P1's principal point row {} differs from P0's {cy}: the rows of the pair are not aligned (not rectified)",
            p1[(1, 2)]
        ))
    } else {
        None
    };
    match problem {
        Some(message) => Err(IoError::Format {
            path: calib_path.to_path_buf(),
            message,
        }),
        None => Ok(p1[(0, 2)] - p0[(0, 2)]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kitti00() -> PinholeCamera {
        PinholeCamera::new(718.856, 718.856, 607.1928, 185.2157, 1241, 376).unwrap()
    }

    #[test]
    fn a_millimetre_baseline_is_named_with_its_likely_unit() {
        let why = implausible_baseline(537.165_7, &kitti00()).unwrap();
        assert!(why.contains("537.1657 m"), "{why}");
        assert!(why.contains("written in millimetres (0.5372 m)?"), "{why}");
        // fx b / width = 718.856 · 537.17 / 1241 = 311 m
        assert!(why.contains("nearer than 311 m"), "{why}");
        let why = implausible_baseline(53.7, &kitti00()).unwrap();
        assert!(
            why.contains("millimetres (0.0537 m) or centimetres (0.5370 m)?"),
            "{why}"
        );
        let why = implausible_baseline(5000.0, &kitti00()).unwrap();
        assert!(why.contains("another unit than metres?"), "{why}");
    }

    #[test]
    fn real_rigs_are_plausible() {
        for b in [0.011, 0.11, 0.537, 1.5, 3.0, MAX_PLAUSIBLE_BASELINE_M] {
            assert_eq!(implausible_baseline(b, &kitti00()), None, "{b}");
        }
        assert_eq!(implausible_baseline(f64::NAN, &kitti00()), None);
        let path = Path::new("camera.yaml");
        assert!(warn_if_implausible(path, "cam1.T_cn_cnm1", 0.11, &kitti00()).is_none());
        let w = warn_if_implausible(path, "cam1.T_cn_cnm1", 110.0, &kitti00()).unwrap();
        assert!(w.starts_with("camera.yaml: cam1.T_cn_cnm1: "), "{w}");
    }
}
