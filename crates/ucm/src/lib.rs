#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod batch;
mod camera;
mod error;
mod intrinsics;
pub mod io;
pub mod model;
mod real;
mod region;
pub mod se3;

pub use batch::{PixelGrid, PixelJacobian};

/// Most pixels a camera may have (8192 × 8192): every per-pixel buffer of the crates
/// that use a camera is sized by its image, so a size read from a file is bounded here.
pub const MAX_PIXELS: u64 = 1 << 26;
pub use camera::Camera;
pub use error::UcmError;
pub use intrinsics::{Distortion, Intrinsics, Params};
pub use model::OutOfView;
pub use real::Real;
pub use region::{Annulus, Mask, ValidRegion};
pub use se3::{Isometry3, Twist};
