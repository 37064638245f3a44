//! visnav-eval (being built).
