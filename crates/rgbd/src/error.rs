//! The one error type of the crate.

use std::path::PathBuf;

use ucm::{Camera, Isometry3};

/// Everything that can go wrong when reading RGB-D frames and fusing them.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RgbdError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A picture could not be decoded.
    #[error("{path}: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: Box<image::ImageError>,
    },
    /// A picture of another size than its camera's.
    #[error("{what} {path} is {got_width}x{got_height} but its camera is {width}x{height}")]
    Size {
        /// Colour or depth.
        what: &'static str,
        /// The file (or `<memory>`).
        path: PathBuf,
        /// The picture's width.
        got_width: u32,
        /// The picture's height.
        got_height: u32,
        /// The camera's width.
        width: u32,
        /// The camera's height.
        height: u32,
    },
    /// A depth picture whose samples are not 16-bit (or 8-bit) grey.
    #[error("depth picture {path} is {kind}, expected 16-bit grey")]
    DepthFormat {
        /// The file.
        path: PathBuf,
        /// What it holds.
        kind: String,
    },
    /// A buffer of the wrong length.
    #[error("{what}: {got} values for {expected} pixels")]
    Length {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The pixel count.
        expected: usize,
    },
    /// A pose file that cannot be read as poses.
    #[error("pose file {path}, line {line}: {message}")]
    Pose {
        /// The file.
        path: PathBuf,
        /// Line number (1-based; 0 for the whole file).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A frame number without a pose.
    #[error("frame {frame} has no pose in {path} ({available})")]
    MissingPose {
        /// The frame number.
        frame: u64,
        /// The pose file.
        path: PathBuf,
        /// Which frames have one.
        available: String,
    },
    /// A dataset description that cannot be used.
    #[error("dataset {path}: {message}")]
    Dataset {
        /// The description file (or `<memory>`).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A setting out of its range.
    #[error("{name}: {message}")]
    Parameter {
        /// The setting.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The fusion would hold more voxels than allowed.
    #[error(
        "the fused cloud would hold more than {limit} voxels (raise max_voxels, or take a coarser voxel or fewer frames)"
    )]
    TooManyVoxels {
        /// The limit.
        limit: usize,
    },
    /// No voxel was seen by enough frames.
    #[error(
        "no voxel was seen by {min_frames} frames or more ({voxels} voxels seen by fewer): nothing to write"
    )]
    Empty {
        /// The required number of frames.
        min_frames: u32,
        /// Voxels seen by fewer frames.
        voxels: usize,
    },
    /// No query point falls near a target surface.
    #[error("none of the {points} query points falls near any of the {surfaces} surfaces")]
    NoOverlap {
        /// Query points with a normal.
        points: usize,
        /// Target surfaces.
        surfaces: usize,
    },
    /// The paired surfaces leave a direction of the pose free (a single plane, say).
    #[error(
        "the {pairs} pairs do not constrain every direction of the pose (eigenvalue ratio {ratio:.1e})"
    )]
    Degenerate {
        /// Pairs of the last pass.
        pairs: usize,
        /// Smallest over largest eigenvalue of the normal equations.
        ratio: f64,
    },
    /// A camera could not be read or used.
    #[error(transparent)]
    Camera(#[from] ucm::UcmError),
    /// The cloud could not be built.
    #[error(transparent)]
    Cloud(#[from] splat::SplatError),
}

/// A picture of its camera's size (`got`, read from `path`), or the error that says it
/// is not.
pub(crate) fn check_size(
    what: &'static str,
    path: PathBuf,
    got: (u32, u32),
    camera: &Camera,
) -> Result<(), RgbdError> {
    if got == (camera.width(), camera.height()) {
        return Ok(());
    }
    Err(RgbdError::Size {
        what,
        path,
        got_width: got.0,
        got_height: got.1,
        width: camera.width(),
        height: camera.height(),
    })
}

/// A finite pose, or the error that says `name` is not.
pub(crate) fn check_pose(name: &'static str, pose: &Isometry3) -> Result<(), RgbdError> {
    if pose.is_finite() {
        return Ok(());
    }
    Err(RgbdError::Parameter {
        name,
        message: "the pose is not finite".into(),
    })
}
