//! visnav-loop (being built).
