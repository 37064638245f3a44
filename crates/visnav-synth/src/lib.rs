//! visnav-synth (being built).
