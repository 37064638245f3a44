//! Evaluation of visnav (being built): the KITTI odometry metric exactly as the official devkit,
//! ATE/RPE, flow metrics, plots. Depends on no estimator.

pub mod flow;
