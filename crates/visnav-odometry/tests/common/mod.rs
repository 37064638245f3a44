//! Helpers shared by the odometry tests.
#![allow(dead_code, clippy::unwrap_used)]

use visnav_flow::DenseFlow;
use visnav_odometry::stereo::FrameStatus;
use visnav_synth::FlowGt;

/// Ground-truth flow as a `DenseFlow` with information `1/σ²` (σ = 0.5 px) everywhere.
pub fn dense_flow_from_gt(gt: &FlowGt) -> DenseFlow {
    let (w, h) = (gt.flow.width, gt.flow.height);
    let flow: Vec<[f32; 2]> = gt.flow.uv.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    let valid: Vec<bool> = gt
        .valid
        .iter()
        .zip(&flow)
        .map(|(&v, f)| v && f[0].abs() < 1e4 && f[1].abs() < 1e4)
        .collect();
    DenseFlow {
        width: w,
        height: h,
        flow,
        information: vec![[4.0, 0.0, 4.0]; w * h],
        valid,
    }
}

/// Asserts that no stereo frame after the first fell back to the constant-velocity prediction.
pub fn assert_no_fallback(status: &[FrameStatus]) {
    assert!(
        status
            .iter()
            .skip(1)
            .all(|s| !matches!(s, FrameStatus::Fallback(_))),
        "{status:?}"
    );
}
