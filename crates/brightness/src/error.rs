//! The one error type of the crate.

/// What can go wrong computing the feature.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BrightnessError {
    /// An image whose size is not the camera's.
    #[error("image is {got_width}x{got_height} but the camera is {width}x{height}")]
    ImageSize {
        /// Image width.
        got_width: u32,
        /// Image height.
        got_height: u32,
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
    },
    /// A picture whose buffers do not hold a value per pixel
    /// ([`frame::AnyImage::check_buffers`]).
    #[error("the picture: {0}")]
    Picture(#[from] frame::FrameError),
    /// Buffers of different lengths.
    #[error("{what}: length {got}, expected {expected}")]
    Length {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The expected length.
        expected: usize,
    },
}
