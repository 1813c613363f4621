//! The one error type of the crate.

use std::path::PathBuf;

/// What can go wrong while building the synthetic world.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// A city parameter is out of its range.
    #[error("invalid city parameter `{name}`: {message}")]
    Parameter {
        /// The parameter.
        name: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// A texture picture could not be read.
    #[error("texture {path}: {source}")]
    Texture {
        /// The file.
        path: PathBuf,
        /// What the `image` crate reported.
        source: image::ImageError,
    },
    /// A file or folder could not be accessed.
    #[error("cannot access {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
    /// A trajectory or acquisition setting is invalid.
    #[error("sequence: {0}")]
    Sequence(String),
    /// A rendering or picture that is not of its camera's size, or whose buffers do not
    /// hold a value per pixel.
    #[error(transparent)]
    Picture(#[from] frame::FrameError),
    /// The generated points do not make a cloud (more than the renderer handles).
    #[error(transparent)]
    Cloud(#[from] splat::SplatError),
}
