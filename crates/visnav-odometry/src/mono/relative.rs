//! Relative pose between two images of a monocular run that need not be consecutive (loop
//! closures, §5 of Ng, Li & Kim 2021): the motion estimation of [`super::MonoOdometry`] with its
//! small-motion rules, given the dense flow from the first image to the second and the fused depth
//! map of the first image.
//!
//! * **PnP** (always): the depth map of the first camera and the flow give 3-D–2-D matches; P3P
//!   RANSAC and Gauss–Newton on the Mahalanobis reprojection error. It is the metric pose and the
//!   one used when the parallax is small — for a revisit the two images may be nearly identical,
//!   so the relative pose is near the identity and the eight-point is undefined.
//! * **Eight-point** (only with parallax, §5: 75th percentile of the flow magnitude above
//!   `parallax.min_flow_p75_px` and a translational parallax of at least
//!   `parallax.min_translational_parallax_px`): the Mahalanobis eight-point gives the rotation
//!   and the translation direction; its scale is the PnP translation length (a revisit has no
//!   ground-plane continuity to draw on). Fused with PnP (average translation, slerp of the
//!   rotations) when their rotations agree within `fusion_max_rotation_rad`, else PnP alone.
//!
//! The KLT part of the parallax test is not run here (it needs both image pyramids; the flow
//! test decides alone).

use nalgebra::Matrix6;
use serde::Serialize;
use visnav_core::{PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::{Correspondence, estimate_fundamental, relative_pose_from_fundamental};

use super::config::MonoConfig;
use super::correspondence::{
    correspondences_from_flow, flow_percentile_px, translational_parallax_px,
};
use super::covariance::pnp_information;
use super::depth::DepthMap;
use super::error::MonoError;
use super::result::PoseSource;
use super::tracker::pnp_against_depth;

/// Fewest PnP inliers for a relative pose.
const MIN_PNP_INLIERS: usize = 10;

/// The relative pose of two images and its uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RelativePose {
    /// Maps points of the first camera into the second, metres (scale of the first depth map).
    pub second_from_first: Pose,
    /// Which estimator produced it: `pnp` or `fused`.
    pub source: PoseSource,
    /// Information matrix (inverse covariance) of the pose, ordered `(v, ω)` for the left
    /// perturbation `Exp(δ) · second_from_first` (1/m², 1/rad²): the Gauss–Newton Hessian
    /// `Σ Jᵀ Y J` of the PnP inliers, `Y` the flow's information matrix (eq. 1).
    #[serde(skip)]
    pub information: Matrix6<f64>,
    /// 75th percentile of the flow magnitude, pixels.
    pub flow_p75_px: f64,
    /// Median translational parallax (rotation removed), pixels.
    pub translational_parallax_px: Option<f64>,
    /// PnP correspondences and inliers.
    pub pnp_correspondences: usize,
    /// PnP inliers.
    pub pnp_inliers: usize,
    /// Eight-point RANSAC inliers (0 when the eight-point was not run).
    pub eight_point_inliers: usize,
}

/// The relative pose `second_from_first` from the dense flow first → second and the fused depth
/// map of the first camera (see the module docs). `Ok(None)` when PnP finds no pose with at least
/// 10 inliers.
///
/// # Errors
/// [`MonoError::SizeMismatch`] when the flow is not the camera's size, [`MonoError`] for an
/// invalid configuration.
pub fn relative_pose_from_flow(
    camera: &PinholeCamera,
    config: &MonoConfig,
    flow: &DenseFlow,
    first_depth: &DepthMap,
    seed: u64,
) -> Result<Option<RelativePose>, MonoError> {
    config.validate()?;
    let (ew, eh) = (camera.width as usize, camera.height as usize);
    if (flow.width, flow.height) != (ew, eh) {
        return Err(MonoError::SizeMismatch {
            what: "flow",
            expected_w: ew,
            expected_h: eh,
            got_w: flow.width,
            got_h: flow.height,
        });
    }
    let mut rng = visnav_geometry::seeded_rng(config.seed ^ seed);
    let (data, pnp) = pnp_against_depth(camera, &config.pnp, first_depth, flow, &mut rng);
    let Some(pnp) = pnp.filter(|r| r.inlier_count >= MIN_PNP_INLIERS) else {
        return Ok(None);
    };
    let pnp_pose = pnp.cam_from_world;

    let flow_p75_px = flow_percentile_px(flow, 0.75);
    let corrs = correspondences_from_flow(flow, config.grid_cell_px);
    let translational = translational_parallax_px(camera, &corrs, &pnp_pose.rotation);
    let parallax = config.parallax.for_width(camera.width);
    let parallax_ok = flow_p75_px > parallax.min_flow_p75_px
        && translational.is_some_and(|p| p >= parallax.min_translational_parallax_px);
    let mut eight_point_inliers = 0;
    let eight_point = if parallax_ok {
        estimate_fundamental(&corrs, &config.eight_point, &mut rng).and_then(|r| {
            eight_point_inliers = r.inlier_count;
            let inl: Vec<&Correspondence> = corrs
                .iter()
                .zip(&r.inliers)
                .filter_map(|(c, &ok)| ok.then_some(c))
                .collect();
            relative_pose_from_fundamental(&r.model, camera, &inl).map(|p| p.cam2_from_cam1)
        })
    } else {
        None
    };
    let (second_from_first, source) = match eight_point {
        Some(unit)
            if (unit.rotation.inverse() * pnp_pose.rotation).angle()
                <= config.fusion_max_rotation_rad =>
        {
            let t = 0.5
                * (unit.translation.vector * pnp_pose.translation.vector.norm()
                    + pnp_pose.translation.vector);
            let r = unit.rotation.slerp(&pnp_pose.rotation, 0.5);
            (Pose::from_parts(t.into(), r), PoseSource::Fused)
        }
        _ => (pnp_pose, PoseSource::Pnp),
    };

    let information = pnp_information(camera, &data, &pnp, 0.0);
    Ok(Some(RelativePose {
        second_from_first,
        source,
        information,
        flow_p75_px,
        translational_parallax_px: translational,
        pnp_correspondences: data.len(),
        pnp_inliers: pnp.inlier_count,
        eight_point_inliers,
    }))
}
