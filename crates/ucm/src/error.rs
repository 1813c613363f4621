//! The one error type of the crate.

use std::path::PathBuf;

/// Everything that can go wrong when building, loading or saving a camera, or when
/// handing the model malformed input.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum UcmError {
    /// A parameter is NaN or infinite.
    #[error("camera parameter `{name}` must be finite, got {value}")]
    NonFinite {
        /// Parameter name as in the TOML file.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A generalised focal length is zero or negative.
    #[error("camera parameter `{name}` must be > 0 (pixels), got {value}")]
    NonPositiveFocal {
        /// `alpha_u` or `alpha_v`.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The mirror parameter ξ is negative.
    #[error("mirror parameter `xi` must be >= 0, got {0}")]
    NegativeXi(f64),
    /// The image has no pixel.
    #[error("image size must be positive, got {width}x{height}")]
    EmptyImage {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// More pixels than [`crate::MAX_PIXELS`] (every per-pixel buffer of the crates
    /// above is sized by the image).
    #[error(
        "a {width}x{height} image has more than the {max} pixels a camera may have",
        max = crate::MAX_PIXELS
    )]
    TooManyPixels {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The annulus radii are not `0 <= inner < outer`.
    #[error(
        "annulus radii must satisfy 0 <= inner < outer, got inner {inner} px, outer {outer} px"
    )]
    BadAnnulus {
        /// Inner radius, pixels.
        inner: f64,
        /// Outer radius, pixels.
        outer: f64,
    },
    /// The mask image does not have the size of the camera image.
    #[error("mask is {mask_width}x{mask_height} but the image is {width}x{height}")]
    MaskSizeMismatch {
        /// Mask width.
        mask_width: u32,
        /// Mask height.
        mask_height: u32,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// A mask with no valid pixel.
    #[error("the valid region of the image is empty")]
    EmptyRegion,
    /// A pose or twist with NaN or infinite components.
    #[error("pose or twist must be finite, got {values:?}")]
    NonFinitePose {
        /// The offending vector.
        values: [f64; 6],
    },
    /// Two slices handed to a batch function have different lengths.
    #[error("batch length mismatch: {input} inputs but {output} outputs")]
    LengthMismatch {
        /// Length of the input slice.
        input: usize,
        /// Length of the output slice.
        output: usize,
    },
    /// Reading or writing a file failed.
    #[error("cannot access {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A camera or calibration file is not a small UTF-8 text file.
    #[error("{path} is not a camera or calibration file: {message}")]
    NotText {
        /// The file.
        path: PathBuf,
        /// What it is instead.
        message: String,
    },
    /// A camera TOML file could not be parsed.
    #[error("invalid camera file {path}: {source}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// The cause, with line and column.
        source: Box<toml::de::Error>,
    },
    /// A camera could not be written as TOML.
    #[error("cannot serialise camera to TOML: {0}")]
    TomlWrite(#[from] toml::ser::Error),
    /// A mask image could not be read or written.
    #[error("mask image {path}: {source}")]
    MaskImage {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: image::ImageError,
    },
    /// A Mei calibration (YAML) could not be understood.
    #[error("invalid Mei calibration {path}: {message}")]
    Calibration {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}
