//! The one error type of the crate.

use std::path::PathBuf;

/// Everything that can go wrong when building or rendering a cloud.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SplatError {
    /// A cloud with no point.
    #[error("the point cloud is empty")]
    EmptyCloud,
    /// A point with a NaN or infinite coordinate.
    #[error("point {index} has a non-finite coordinate {value:?}")]
    NonFinitePoint {
        /// Index of the point in the input.
        index: usize,
        /// Its coordinates.
        value: [f64; 3],
    },
    /// More points than the renderer can index (`u32`).
    #[error("{0} points exceed the renderer's limit of 4294967295")]
    TooManyPoints(usize),
    /// Per-point attributes of the wrong length.
    #[error("{what}: {got} values for {expected} points")]
    AttributeLength {
        /// Which attribute.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The number of points.
        expected: usize,
    },
    /// A frame of the wrong size for the camera.
    #[error("frame is {frame_width}x{frame_height} but the camera is {width}x{height}")]
    FrameSize {
        /// Frame width.
        frame_width: u32,
        /// Frame height.
        frame_height: u32,
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
    },
    /// A frame whose per-pixel buffer does not hold one value per pixel (its fields
    /// are public, so a caller may have resized one).
    #[error("the frame's {what} holds {got} values for {expected} pixels")]
    FrameBuffer {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The frame's pixel count.
        expected: usize,
    },
    /// A camera whose valid pixels reach farther than the renderer addresses (a
    /// splat's first column and row are 16-bit signed integers, and projections are
    /// clamped to ±30 000 pixels before rounding).
    #[error(
        "the camera's valid pixels reach column {columns} and row {rows}; the renderer draws at most {max} of each"
    )]
    RegionTooLarge {
        /// One past the last column holding a valid pixel.
        columns: usize,
        /// One past the last row holding a valid pixel.
        rows: usize,
        /// The most columns and rows the renderer draws.
        max: usize,
    },
    /// A pose with NaN or infinite components.
    #[error("pose is not finite")]
    NonFinitePose,
    /// A parameter out of its documented range.
    #[error("invalid parameter `{name}`: {message}")]
    Parameter {
        /// The parameter.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// An image (texture, PNG output) could not be read or written.
    #[error("image {path}: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: image::ImageError,
    },
    /// A file system error.
    #[error("cannot access {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}
