//! Stereo visual odometry (RotROCC) — being built.
