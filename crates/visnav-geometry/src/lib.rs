//! visnav-geometry (being built).
