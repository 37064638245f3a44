//! SSIM (Wang et al. 2004) — being built.
