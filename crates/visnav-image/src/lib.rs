//! Image operations of visnav (being built): pyramids, gradients, Shi–Tomasi corners,
//! pyramidal Lucas–Kanade tracking, SSIM.

pub mod ssim;
