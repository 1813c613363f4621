#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod align;
mod dataset;
mod error;
mod fusion;
mod pictures;

pub use align::{AlignOptions, DepthAlignment, Surface, align_depth};
pub use dataset::{
    FuseReport, MAX_FRAMES, PoseOf, RgbdDataset, frame_path, isometry_from_rows, nearest_rotation,
};
pub use error::RgbdError;
pub use fusion::{FrameStats, FuseOptions, Fusion, Sensor};
pub use pictures::{ColorImage, DepthImage};
