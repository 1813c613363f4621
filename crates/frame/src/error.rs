//! The one error type of the crate.

use std::path::PathBuf;

/// What can go wrong with an image or a frame.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// An image or frame does not have the size it must have.
    #[error("{what} is {got_width}x{got_height} but must be {width}x{height}")]
    Size {
        /// What was checked.
        what: &'static str,
        /// Its width, pixels.
        got_width: u32,
        /// Its height, pixels.
        got_height: u32,
        /// The expected width, pixels.
        width: u32,
        /// The expected height, pixels.
        height: u32,
    },
    /// A per-pixel buffer has the wrong length.
    #[error("{what}: {got} values for {expected} pixels")]
    Length {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The number of pixels.
        expected: usize,
    },
    /// The crop rectangle leaves the picture.
    #[error(
        "crop x={x}, y={y}, {width}x{height} exceeds the {picture_width}x{picture_height} picture {path}"
    )]
    Crop {
        /// The picture's file.
        path: PathBuf,
        /// Left column of the crop.
        x: u32,
        /// Top row of the crop.
        y: u32,
        /// Crop width.
        width: u32,
        /// Crop height.
        height: u32,
        /// The picture's width.
        picture_width: u32,
        /// The picture's height.
        picture_height: u32,
    },
    /// The picture is larger than [`ucm::MAX_PIXELS`].
    #[error("picture {path} has {pixels} pixels, more than the limit of {limit}")]
    TooManyPixels {
        /// The picture's file.
        path: PathBuf,
        /// Its pixel count as announced by its header.
        pixels: u64,
        /// [`ucm::MAX_PIXELS`].
        limit: u64,
    },
    /// A JPEG picture ends before its last scan does: a truncated file, which the
    /// decoder would fill with grey.
    #[error("picture {path} is truncated: its JPEG data end inside the image's last scan")]
    TruncatedJpeg {
        /// The picture's file.
        path: PathBuf,
    },
    /// A camera could not be built.
    #[error(transparent)]
    Camera(#[from] ucm::UcmError),
    /// Reading, decoding or writing a picture failed.
    #[error("image {path}: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What the `image` crate reported.
        source: image::ImageError,
    },
}
