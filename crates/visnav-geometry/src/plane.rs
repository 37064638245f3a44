//! Ground-plane fit and the monocular translation scale (Ng, Li, Kim 2021, §5).
//!
//! Candidates are reconstructed points below the camera (`y > 0`, camera y axis down) seen within
//! the central half of the image width (`|u − cx| ≤ width / 4`). A RANSAC plane
//! `ax + by + cz + d = 0` (unit normal, `b > 0`) is fitted through them; minimal fits whose normal
//! is tilted more than `max_tilt_rad` from the camera y axis are rejected, and the inliers are
//! refitted by total least squares. The camera height in reconstruction units is `−d/b`, so with a
//! known height `h` (metres) the scale of a unit-translation reconstruction is `s = −(b·h)/d`.
//! Distances are measured relative to the candidates' median `y`, so the threshold is
//! scale-free.
//!
//! A plane through (or near) the camera centre is rejected: it contains the viewing rays of one
//! band of image rows, so it fits points on those rays *whatever their depth*, e.g. the far
//! points near the horizon; its camera height `−d/b ≈ 0` would make the scale absurd (≈ 1e15).
//! The ground lies below every point seen above it, so its height is at least about the
//! candidates' median `y`; planes lower than `min_relative_height` times that are refused.

use nalgebra::{Matrix3, Point2, Point3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use visnav_core::PinholeCamera;

use crate::ransac::{RansacConfig, RansacProblem, ransac};
use crate::{GeometryError, check};

/// A plane `normal · p + offset = 0` with a unit normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal `(a, b, c)`.
    pub normal: Vector3<f64>,
    /// Offset `d`.
    pub offset: f64,
}

impl Plane {
    /// Signed distance of a point.
    #[must_use]
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) + self.offset
    }

    /// Camera height above the plane, `−d/b` (units of the points); `None` if `b ≈ 0`.
    #[must_use]
    pub fn camera_height(&self) -> Option<f64> {
        (self.normal.y.abs() > 1e-9).then(|| -self.offset / self.normal.y)
    }

    /// Least-squares plane through points (centroid and smallest principal direction), with `b ≥ 0`.
    #[must_use]
    pub fn fit(points: &[&Point3<f64>]) -> Option<Self> {
        if points.len() < 3 {
            return None;
        }
        let n = points.len() as f64;
        let centroid = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
        let mut cov = Matrix3::zeros();
        for p in points {
            let d = p.coords - centroid;
            cov += d * d.transpose();
        }
        let mut normal = crate::smallest_eigenvector(&cov)?;
        if normal.y < 0.0 {
            normal = -normal;
        }
        let norm = normal.norm();
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        normal /= norm;
        Some(Self {
            normal,
            offset: -normal.dot(&centroid),
        })
    }
}

/// Ground-plane parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GroundPlaneConfig {
    /// RANSAC; threshold on the squared point–plane distance relative to the candidates' median
    /// height. Default 0.05² (5 % of the camera height).
    pub ransac: RansacConfig,
    /// Largest angle between the plane normal and the camera y axis, radians. Default 0.35 (20°).
    pub max_tilt_rad: f64,
    /// Fewest candidate points to attempt a fit. Default 20.
    pub min_points: usize,
    /// Smallest camera height above the plane as a fraction of the candidates' median `y`.
    /// Default 0.5. Rejects the degenerate planes through the camera centre (see the module
    /// docs).
    pub min_relative_height: f64,
    /// The aerial (dominant-plane) fit: largest angle between the plane's normal and the
    /// camera's y–z plane, radians, i.e. the largest roll of the camera about its optical axis
    /// from a level image. Default 0.785 (45°). The monocular odometry bounds the first ground
    /// of a flight (or of a new map) with it, not the later frames' planes (it passes π/2). The ground under a flying camera whose image
    /// rows are roughly level has its normal in the camera's y–z plane (a forward or a nadir
    /// view, banked by a turn); a facade along a street has its normal along x, supports
    /// everything behind it and, seen from a street at roof height, can hold more points than
    /// the ground (rendered city flight 12: the facade 8.6 m to the side taken for the ground
    /// 30 m below, the scale 3.8x).
    pub max_roll_rad: f64,
}

impl Default for GroundPlaneConfig {
    fn default() -> Self {
        Self {
            ransac: RansacConfig {
                inlier_threshold: 0.05 * 0.05,
                guided_sampling: false,
                ..RansacConfig::default()
            },
            max_tilt_rad: 0.35,
            min_points: 20,
            min_relative_height: 0.5,
            max_roll_rad: std::f64::consts::FRAC_PI_4,
        }
    }
}

impl GroundPlaneConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`GeometryError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check(
            self.max_tilt_rad > 0.0 && self.max_tilt_rad < std::f64::consts::FRAC_PI_2,
            "ground.max_tilt_rad",
            self.max_tilt_rad,
            "in (0, π/2)",
        )?;
        check(
            self.min_points >= 3,
            "ground.min_points",
            self.min_points as f64,
            ">= 3",
        )?;
        check(
            self.min_relative_height > 0.0 && self.min_relative_height.is_finite(),
            "ground.min_relative_height",
            self.min_relative_height,
            "finite and > 0",
        )?;
        check(
            self.max_roll_rad > 0.0 && self.max_roll_rad <= std::f64::consts::FRAC_PI_2,
            "ground.max_roll_rad",
            self.max_roll_rad,
            "in (0, π/2]",
        )?;
        self.ransac.validate()
    }
}

struct PlaneProblem {
    min_normal_y: f64,
    /// Smallest camera height `−d/b` (the points are in units of their median `y`).
    min_height: f64,
}

impl PlaneProblem {
    fn accepts(&self, p: &Plane) -> bool {
        p.normal.y >= self.min_normal_y && p.camera_height().is_some_and(|h| h >= self.min_height)
    }
}

impl RansacProblem for PlaneProblem {
    type Sample = Point3<f64>;
    type Model = Plane;
    const MIN_SAMPLES: usize = 3;

    fn fit_minimal(&self, s: &[&Point3<f64>]) -> Vec<Plane> {
        Plane::fit(s)
            .filter(|p| self.accepts(p))
            .into_iter()
            .collect()
    }

    fn residual_sq(&self, model: &Plane, sample: &Point3<f64>) -> f64 {
        let d = model.distance(sample);
        d * d
    }

    fn refit(&self, inliers: &[&Point3<f64>], _: &Plane) -> Option<Plane> {
        Plane::fit(inliers).filter(|p| self.accepts(p))
    }
}

/// A fitted ground plane.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundPlane {
    /// The plane in the points' frame and units.
    pub plane: Plane,
    /// Camera height above it in the points' units: `−d/b`, along the camera y axis
    /// ([`fit_ground_plane`]), or the camera's distance from it, `|d|`
    /// ([`fit_dominant_plane`]).
    pub camera_height: f64,
    /// Candidates (below the camera, central half of the width) considered.
    pub candidates: usize,
    /// Inliers of the plane.
    pub inliers: usize,
}

impl GroundPlane {
    /// The scale `s = −(b·h)/d` that makes the camera height `camera_height_m` metres.
    #[must_use]
    pub fn scale(&self, camera_height_m: f64) -> f64 {
        scale_from_plane(&self.plane, camera_height_m).unwrap_or(f64::NAN)
    }

    /// The scale `s = h / |d|` that makes the camera's distance from the plane
    /// `camera_height_m` metres, whatever the plane's orientation (the aerial ground; for a
    /// plane normal to the camera y axis it equals [`Self::scale`]).
    #[must_use]
    pub fn scale_by_distance(&self, camera_height_m: f64) -> f64 {
        let s = camera_height_m / self.plane.offset.abs();
        if s.is_finite() && s > 0.0 {
            s
        } else {
            f64::NAN
        }
    }
}

/// `s = −(b·h)/d`; `None` unless positive and finite.
#[must_use]
pub fn scale_from_plane(plane: &Plane, camera_height_m: f64) -> Option<f64> {
    let s = -(plane.normal.y * camera_height_m) / plane.offset;
    (s.is_finite() && s > 0.0).then_some(s)
}

/// Fits the ground plane through `points_in_cam` (camera frame) observed at `pixels` in camera 1
/// (same length); `None` with too few candidates or no roughly horizontal plane below the camera.
pub fn fit_ground_plane<R: Rng>(
    camera: &PinholeCamera,
    points_in_cam: &[Point3<f64>],
    pixels: &[Point2<f64>],
    config: &GroundPlaneConfig,
    rng: &mut R,
) -> Option<GroundPlane> {
    let half_band = f64::from(camera.width) / 4.0;
    let mut candidates: Vec<Point3<f64>> = points_in_cam
        .iter()
        .zip(pixels)
        .filter(|(p, px)| p.y > 0.0 && p.z > 0.0 && (px.x - camera.cx).abs() <= half_band)
        .map(|(p, _)| *p)
        .collect();
    if candidates.len() < config.min_points.max(3) {
        return None;
    }
    let unit = rescale_by_median(&mut candidates, |p| p.y)?;
    let problem = PlaneProblem {
        min_normal_y: config.max_tilt_rad.cos(),
        min_height: config.min_relative_height,
    };
    let res = ransac(&problem, &candidates, None, &config.ransac, rng)?;
    let mut plane = res.model;
    if !problem.accepts(&plane) {
        return None;
    }
    plane.offset *= unit;
    let camera_height = plane.camera_height()?;
    (camera_height > 0.0).then_some(GroundPlane {
        plane,
        camera_height,
        candidates: candidates.len(),
        inliers: res.inlier_count,
    })
}

/// Smallest distance of the dominant plane from the camera centre, as a fraction of the median
/// distance of the points: rejects the planes through the camera (see the module docs).
const MIN_RELATIVE_PLANE_DISTANCE: f64 = 0.1;

/// Divides `points` by the median of `measure` over them (the scale-free units of the plane
/// fits) and returns that median; `None` unless it is positive.
fn rescale_by_median(
    points: &mut [Point3<f64>],
    measure: impl Fn(&Point3<f64>) -> f64,
) -> Option<f64> {
    let mut values: Vec<f64> = points.iter().map(measure).collect();
    let mid = values.len() / 2;
    let unit = *values.select_nth_unstable_by(mid, f64::total_cmp).1;
    if unit.is_nan() || unit <= 0.0 {
        return None;
    }
    for p in points.iter_mut() {
        p.coords /= unit;
    }
    Some(unit)
}

/// A plane of any orientation, clear of the camera, whose normal points from the camera
/// towards it (`offset < 0`): the aerial ground. A point farther than the inlier threshold
/// beyond it contradicts it: everything a camera sees lies on its side of the ground, so the
/// ground is the plane that supports the scene, while a roof or a facade has the ground and the
/// roofs behind it beyond it.
struct SupportingPlaneProblem {
    /// Largest `|normal.x|`: the sine of the largest roll ([`GroundPlaneConfig::max_roll_rad`]).
    max_normal_x: f64,
}

impl SupportingPlaneProblem {
    /// A supporting plane within the largest roll.
    fn level(&self, points: &[&Point3<f64>]) -> Option<Plane> {
        Self::oriented(points).filter(|p| p.normal.x.abs() <= self.max_normal_x)
    }

    /// The least-squares plane oriented away from the camera, if it is at least
    /// `MIN_RELATIVE_PLANE_DISTANCE` from it (units of the median point distance).
    fn oriented(points: &[&Point3<f64>]) -> Option<Plane> {
        let p = Plane::fit(points)?;
        let p = if p.offset > 0.0 {
            Plane {
                normal: -p.normal,
                offset: -p.offset,
            }
        } else {
            p
        };
        (-p.offset >= MIN_RELATIVE_PLANE_DISTANCE).then_some(p)
    }
}

impl RansacProblem for SupportingPlaneProblem {
    type Sample = Point3<f64>;
    type Model = Plane;
    const MIN_SAMPLES: usize = 3;

    fn fit_minimal(&self, s: &[&Point3<f64>]) -> Vec<Plane> {
        self.level(s).into_iter().collect()
    }

    fn residual_sq(&self, model: &Plane, sample: &Point3<f64>) -> f64 {
        let d = model.distance(sample);
        d * d
    }

    fn refit(&self, inliers: &[&Point3<f64>], _: &Plane) -> Option<Plane> {
        self.level(inliers)
    }

    fn contradicts(&self, model: &Plane, sample: &Point3<f64>, threshold_sq: f64) -> bool {
        model.distance(sample) > threshold_sq.sqrt()
    }
}

/// Whether a point is finite and in front of the camera (the aerial fits' candidates).
fn in_front(p: &Point3<f64>) -> bool {
    p.z > 0.0 && p.coords.iter().all(|v| v.is_finite())
}

/// The supporting-plane problem without the roll bound (its residuals and contradictions).
const ANY_PLANE: SupportingPlaneProblem = SupportingPlaneProblem { max_normal_x: 1.0 };

/// A supporting plane ([`SupportingPlaneProblem`]) near a predicted one: its normal within
/// `cos_tilt` of `normal`, its distance from the camera within `[min_distance, max_distance]`.
struct PredictedPlaneProblem {
    normal: Vector3<f64>,
    cos_tilt: f64,
    min_distance: f64,
    max_distance: f64,
}

impl PredictedPlaneProblem {
    fn near(&self, p: Plane) -> Option<Plane> {
        let distance = -p.offset;
        (p.normal.dot(&self.normal) >= self.cos_tilt
            && distance >= self.min_distance
            && distance <= self.max_distance)
            .then_some(p)
    }
}

impl RansacProblem for PredictedPlaneProblem {
    type Sample = Point3<f64>;
    type Model = Plane;
    const MIN_SAMPLES: usize = 3;

    fn fit_minimal(&self, s: &[&Point3<f64>]) -> Vec<Plane> {
        SupportingPlaneProblem::oriented(s)
            .and_then(|p| self.near(p))
            .into_iter()
            .collect()
    }

    fn residual_sq(&self, model: &Plane, sample: &Point3<f64>) -> f64 {
        ANY_PLANE.residual_sq(model, sample)
    }

    fn refit(&self, inliers: &[&Point3<f64>], _: &Plane) -> Option<Plane> {
        SupportingPlaneProblem::oriented(inliers).and_then(|p| self.near(p))
    }

    fn contradicts(&self, model: &Plane, sample: &Point3<f64>, threshold_sq: f64) -> bool {
        ANY_PLANE.contradicts(model, sample, threshold_sq)
    }
}

/// The ground near where it is expected: the supporting plane of `points_in_cam` (as
/// [`fit_dominant_plane`]) whose normal is within `max_tilt_rad` of `predicted`'s and whose
/// distance from the camera is within a factor `max_distance_ratio` of `predicted`'s (its
/// `-offset`, positive). An aerial camera that tracks its height above flat ground
/// (issue 26) predicts the plane; roofs and tree crowns, nearer than the ground by their
/// height, fall outside the window, which the dominant plane alone cannot tell (a descent
/// towards 6–22 m buildings from 30 m made the roofs the dominant plane on a rendered city
/// flight). Distances are relative to the predicted distance (`config.ransac.inlier_threshold`
/// is the squared fraction of it). `None` with fewer than `config.min_points` points, an
/// invalid prediction, or no such plane.
pub fn fit_plane_near<R: Rng>(
    points_in_cam: &[Point3<f64>],
    predicted: &Plane,
    max_tilt_rad: f64,
    max_distance_ratio: f64,
    config: &GroundPlaneConfig,
    rng: &mut R,
) -> Option<GroundPlane> {
    let unit = -predicted.offset;
    if !(unit.is_finite() && unit > 0.0 && max_distance_ratio >= 1.0) {
        return None;
    }
    let candidates: Vec<Point3<f64>> = points_in_cam
        .iter()
        .filter(|p| in_front(p))
        .map(|p| Point3::from(p.coords / unit))
        .collect();
    if candidates.len() < config.min_points.max(3) {
        return None;
    }
    let problem = PredictedPlaneProblem {
        normal: predicted.normal.normalize(),
        cos_tilt: max_tilt_rad.cos(),
        min_distance: 1.0 / max_distance_ratio,
        max_distance: max_distance_ratio,
    };
    let res = ransac(&problem, &candidates, None, &config.ransac, rng)?;
    let mut plane = problem.near(res.model)?;
    plane.offset *= unit;
    Some(GroundPlane {
        plane,
        camera_height: -plane.offset,
        candidates: candidates.len(),
        inliers: res.inlier_count,
    })
}

/// The dominant plane of `points_in_cam` (camera frame) in any orientation: the ground seen by a
/// downward- or forward-looking aerial camera (issue 26; the paper's aerial mode takes its first
/// scale from the ground). [`ransac`] over every point in front of the camera with distances
/// relative to the points' median distance (`ransac.inlier_threshold`, 5 % by default), each
/// hypothesis scored by its inliers minus the points beyond it (`SupportingPlaneProblem`), its
/// normal within `max_roll_rad` of the camera's y–z plane (no facade beside the camera). The
/// camera height is the distance of the camera centre from the plane, so
/// [`GroundPlane::scale_by_distance`] gives the scale. `None` with fewer than `min_points`
/// points or no plane clear of the camera.
pub fn fit_dominant_plane<R: Rng>(
    points_in_cam: &[Point3<f64>],
    config: &GroundPlaneConfig,
    rng: &mut R,
) -> Option<GroundPlane> {
    let mut candidates: Vec<Point3<f64>> = points_in_cam
        .iter()
        .filter(|p| in_front(p))
        .copied()
        .collect();
    if candidates.len() < config.min_points.max(3) {
        return None;
    }
    let unit = rescale_by_median(&mut candidates, |p| p.coords.norm())?;
    let problem = SupportingPlaneProblem {
        max_normal_x: config.max_roll_rad.sin(),
    };
    let res = ransac(&problem, &candidates, None, &config.ransac, rng)?;
    let mut plane = res.model;
    plane.offset *= unit;
    let camera_height = -plane.offset;
    (camera_height > 0.0).then_some(GroundPlane {
        plane,
        camera_height,
        candidates: candidates.len(),
        inliers: res.inlier_count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn scale_from_a_known_ground_plane() {
        let cam = PinholeCamera::kitti_default();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        // reconstruction in units where the true translation (0.8 m) is 1: ground 1.65 m below
        let unit_m = 0.8;
        let tilt = 0.03_f64;
        let mut pts = Vec::new();
        let mut pxs = Vec::new();
        for _ in 0..400 {
            let x = rng.random_range(-6.0..6.0);
            let z = rng.random_range(4.0..40.0);
            // a slightly pitched road plus 30 % clutter (walls, cars)
            let y = if rng.random_bool(0.3) {
                rng.random_range(-2.0..1.2)
            } else {
                1.65 + tilt * z
            };
            let p_m = Point3::new(x, y, z);
            let Some(px) = cam.project(&p_m) else {
                continue;
            };
            pts.push(Point3::from(p_m.coords / unit_m));
            pxs.push(px);
        }
        let gp =
            fit_ground_plane(&cam, &pts, &pxs, &GroundPlaneConfig::default(), &mut rng).unwrap();
        // −d/b is the height of the plane along the camera y axis (the paper's definition)
        let expected_h = 1.65;
        let s = gp.scale(expected_h);
        assert!((s - unit_m).abs() < 1e-6, "scale {s}");
        assert!(gp.inliers > 150 && gp.inliers < gp.candidates);
        // walls only: rejected by the tilt test
        let walls: Vec<Point3<f64>> = (0..50)
            .map(|i| Point3::new(3.0, 0.1 + 0.02 * f64::from(i), 5.0 + f64::from(i % 7)))
            .collect();
        let wpx: Vec<Point2<f64>> = walls.iter().map(|p| cam.project(p).unwrap()).collect();
        assert!(
            fit_ground_plane(&cam, &walls, &wpx, &GroundPlaneConfig::default(), &mut rng).is_none()
        );
    }

    #[test]
    fn a_facade_beside_the_camera_is_not_taken_for_the_ground() {
        // a forward view pitched 20° down from 30 m over a street 16 m wide: 300 points on the
        // street, 700 on a facade 8.6 m to the right (normal along the camera's x axis, nothing
        // seen beyond it)
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let pitch = 20f64.to_radians();
        let normal = Vector3::new(0.0, pitch.cos(), pitch.sin());
        let along = Vector3::new(0.0, -pitch.sin(), pitch.cos());
        let pts: Vec<Point3<f64>> = (0..1000)
            .map(|i| {
                if i % 10 < 3 {
                    let (a, b) = (rng.random_range(-8.0..8.0), rng.random_range(-5.0..80.0));
                    Point3::from(30.0 * normal + a * Vector3::x() + b * along)
                } else {
                    Point3::new(
                        8.6,
                        rng.random_range(-5.0..25.0),
                        rng.random_range(5.0..60.0),
                    )
                }
            })
            .collect();
        let any_roll = GroundPlaneConfig {
            max_roll_rad: std::f64::consts::FRAC_PI_2,
            ..GroundPlaneConfig::default()
        };
        let facade = fit_dominant_plane(&pts, &any_roll, &mut rng).unwrap();
        assert!(facade.plane.normal.x.abs() > 0.99, "{facade:?}");
        let ground = fit_dominant_plane(&pts, &GroundPlaneConfig::default(), &mut rng).unwrap();
        assert!((ground.camera_height - 30.0).abs() < 0.3, "{ground:?}");
        assert!(ground.plane.normal.dot(&normal) > 0.999, "{ground:?}");
        assert!(
            GroundPlaneConfig {
                max_roll_rad: 0.0,
                ..GroundPlaneConfig::default()
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn the_predicted_ground_is_found_under_larger_roofs() {
        // a downward view 30 m above the ground: 25 % of the points on it, 75 % on roofs 10 m
        // high (20 m below the camera), which the dominant plane takes (more roof points than
        // twice the ground points beyond them)
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let pts: Vec<Point3<f64>> = (0..600)
            .map(|i| {
                let (x, z) = (rng.random_range(-15.0..15.0), rng.random_range(-10.0..10.0));
                let y = if i % 4 == 0 { 30.0 } else { 20.0 };
                // the camera looks down its z axis: depth along z
                Point3::new(x, z, y)
            })
            .collect();
        let cfg = GroundPlaneConfig::default();
        let dominant = fit_dominant_plane(&pts, &cfg, &mut rng).unwrap();
        assert!(
            (dominant.camera_height - 20.0).abs() < 0.5,
            "{}",
            dominant.camera_height
        );
        // predicted 10 % too far and 3° off: the ground within 1.25 of it
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 3f64.to_radians());
        let predicted = Plane {
            normal: tilt * Vector3::z(),
            offset: -33.0,
        };
        let ground = fit_plane_near(&pts, &predicted, 0.15, 1.25, &cfg, &mut rng).unwrap();
        assert!(
            (ground.camera_height - 30.0).abs() < 1e-6,
            "{}",
            ground.camera_height
        );
        assert!(ground.plane.normal.dot(&Vector3::z()) > 1.0 - 1e-9);
        // predicted at the roofs' distance, the window excludes the ground
        let roofs = Plane {
            normal: Vector3::z(),
            offset: -19.0,
        };
        let r = fit_plane_near(&pts, &roofs, 0.15, 1.25, &cfg, &mut rng).unwrap();
        assert!((r.camera_height - 20.0).abs() < 1e-6);
        // a facade's normal is not near the prediction
        let facade = Plane {
            normal: Vector3::x(),
            offset: -30.0,
        };
        assert!(fit_plane_near(&pts, &facade, 0.15, 1.25, &cfg, &mut rng).is_none());
    }

    #[test]
    fn a_plane_through_the_camera_centre_is_refused() {
        // many far points on (nearly) the viewing rays of one image row (y = 0.01 z + 0.002: a
        // plane 2 mm from the camera centre, within the tilt limit) and fewer ground points 1.65
        // below the camera; the ray plane has more inliers but a camera height of 2 mm, i.e. a
        // scale 825 times too large
        let cam = PinholeCamera::kitti_default();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut pts = Vec::new();
        for _ in 0..200 {
            let (x, z) = (rng.random_range(-4.0..4.0), rng.random_range(30.0..80.0));
            pts.push(Point3::new(x, 0.01 * z + 0.002, z));
        }
        for _ in 0..60 {
            let (x, z) = (rng.random_range(-4.0..4.0), rng.random_range(5.0..20.0));
            pts.push(Point3::new(x, 1.65, z));
        }
        let pxs: Vec<Point2<f64>> = pts.iter().map(|p| cam.project(p).unwrap()).collect();
        let gp =
            fit_ground_plane(&cam, &pts, &pxs, &GroundPlaneConfig::default(), &mut rng).unwrap();
        assert!((gp.camera_height - 1.65).abs() < 1e-6, "{gp:?}");
        // (the ground points within the central half of the width)
        assert!(gp.inliers > 40 && gp.inliers <= 60, "{gp:?}");
        // without the height test the ray plane wins (the old behaviour)
        let loose = GroundPlaneConfig {
            min_relative_height: 1e-12,
            ..GroundPlaneConfig::default()
        };
        let bad = fit_ground_plane(&cam, &pts, &pxs, &loose, &mut rng);
        assert!(
            bad.as_ref().is_some_and(|g| g.camera_height < 0.01),
            "{bad:?}"
        );
        assert!(
            GroundPlaneConfig {
                min_relative_height: 0.0,
                ..GroundPlaneConfig::default()
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn the_dominant_plane_is_found_in_any_orientation() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // a camera looking straight down (z) at the ground 40 m away, tilted 10° about x, with
        // 30 % of the points on roofs 5..15 m above the ground; reconstruction units of 4 m
        let unit_m = 4.0;
        let tilt = 10_f64.to_radians();
        let normal = Vector3::new(0.0, -tilt.sin(), tilt.cos());
        let mut pts = Vec::new();
        for k in 0..600 {
            let (x, y) = (rng.random_range(-20.0..20.0), rng.random_range(-15.0..15.0));
            let roof = if k % 10 < 3 {
                rng.random_range(5.0..15.0)
            } else {
                0.0
            };
            // the point of the plane n·p = 40 − roof at (x, y)
            let z = (40.0 - roof + tilt.sin() * y) / tilt.cos();
            pts.push(Point3::new(x, y, z) / unit_m);
        }
        let gp = fit_dominant_plane(&pts, &GroundPlaneConfig::default(), &mut rng).unwrap();
        assert!((gp.plane.normal - normal).norm() < 1e-6, "{gp:?}");
        assert!((gp.camera_height * unit_m - 40.0).abs() < 1e-6, "{gp:?}");
        assert!((gp.scale_by_distance(40.0) - unit_m).abs() < 1e-6);
        // the car's ground fit finds nothing below the camera here
        let pixels: Vec<Point2<f64>> = pts.iter().map(|_| Point2::new(620.0, 300.0)).collect();
        let cam = PinholeCamera::kitti_default();
        let car = fit_ground_plane(&cam, &pts, &pixels, &GroundPlaneConfig::default(), &mut rng);
        assert!(car.is_none_or(|g| (g.camera_height * unit_m - 40.0).abs() > 1.0));
        // too few points
        assert!(fit_dominant_plane(&pts[..2], &GroundPlaneConfig::default(), &mut rng).is_none());
    }
}
