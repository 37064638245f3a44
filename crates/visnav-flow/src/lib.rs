//! visnav-flow (being built).
