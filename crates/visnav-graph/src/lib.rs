//! visnav-graph (being built).
