//! Errors of the flow stage.

/// What can go wrong when computing dense flow.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FlowError {
    /// The two images differ in size.
    #[error("image sizes differ: first {width1}x{height1}, second {width2}x{height2}")]
    SizeMismatch {
        /// Width of the first image.
        width1: usize,
        /// Height of the first image.
        height1: usize,
        /// Width of the second image.
        width2: usize,
        /// Height of the second image.
        height2: usize,
    },
    /// The images are too small for the matching resolution.
    #[error("image {width}x{height} is too small: at least {min}x{min} pixels are needed")]
    TooSmall {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Minimum side length in pixels.
        min: usize,
    },
    /// A prior flow field does not match the image size.
    #[error("prior flow is {got_width}x{got_height}, the images are {width}x{height}")]
    PriorSize {
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// Prior width.
        got_width: usize,
        /// Prior height.
        got_height: usize,
    },
    /// A configuration value is out of range.
    #[error("invalid flow configuration: {field} = {value} ({expected})")]
    InvalidConfig {
        /// The offending field.
        field: &'static str,
        /// Its value, formatted.
        value: String,
        /// What is expected.
        expected: &'static str,
    },
}

impl FlowError {
    /// `Ok((width, height))` when the two images have the same size and both sides hold at
    /// least `min_side` pixels, else [`FlowError::SizeMismatch`] or [`FlowError::TooSmall`].
    ///
    /// # Errors
    /// As described.
    pub fn check_sizes(
        img1: &visnav_core::GrayImage,
        img2: &visnav_core::GrayImage,
        min_side: usize,
    ) -> Result<(usize, usize), Self> {
        let (w, h) = (img1.width(), img1.height());
        if (w, h) != (img2.width(), img2.height()) {
            return Err(Self::SizeMismatch {
                width1: w,
                height1: h,
                width2: img2.width(),
                height2: img2.height(),
            });
        }
        if w < min_side || h < min_side {
            return Err(Self::TooSmall {
                width: w,
                height: h,
                min: min_side,
            });
        }
        Ok((w, h))
    }
}
