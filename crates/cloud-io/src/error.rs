//! The one error type of the crate.

use std::path::PathBuf;

/// Everything that can go wrong when reading, converting or writing a cloud file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CloudIoError {
    /// A file whose first bytes are the signature of no format this crate reads.
    #[error(
        "{path}: not a point cloud file this program reads: its first bytes {signature:?} are \
         the signature of none of LAS/LAZ (\"LASF\"), PLY (\"ply\") and E57 (\"ASTM-E57\")"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Its first bytes (at most 8), lossily as text.
        signature: String,
    },
    /// A LAS/LAZ file could not be read or written (truncated, corrupt, unsupported).
    #[error("LAS/LAZ file {path}: {source}")]
    Las {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: Box<las::Error>,
    },
    /// A file that holds fewer points than its header announces.
    #[error(
        "{path} is truncated or its header lies: {}the file holds {found}",
        announced.map_or(String::new(), |n| format!("its header announces {n} points, "))
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The header's point count, if the header could be read.
        announced: Option<u64>,
        /// What the file holds instead (for LAS and binary PLY, the points its bytes
        /// hold; for LAZ and ASCII PLY, the points decoded before its data ended). E57
        /// files that end early are [`CloudIoError::E57`] errors.
        found: String,
    },
    /// A PLY file that breaks the format or holds no usable vertex.
    #[error("PLY file {path}: {message}")]
    Ply {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
    /// An E57 file that could not be read or written.
    #[error("E57 file {path}: {source}")]
    E57 {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: Box<e57::Error>,
    },
    /// A file that holds no point with valid coordinates.
    #[error("{path} holds no point with valid coordinates")]
    NoPoint {
        /// The file.
        path: PathBuf,
    },
    /// The points could not become a renderer's cloud (a coordinate too far from the
    /// others, too many points, …).
    #[error("{path}: {source}")]
    Cloud {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: splat::SplatError,
    },
    /// Points whose attributes do not match (lengths), or an output path that cannot
    /// name a cloud file.
    #[error("invalid parameter `{name}`: {message}")]
    Parameter {
        /// The parameter.
        name: &'static str,
        /// What is wrong.
        message: String,
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
