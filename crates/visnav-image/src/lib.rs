//! visnav-image (being built).
