//! Monocular visual odometry — being built.
