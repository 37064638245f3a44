//! visnav-odometry (being built).
