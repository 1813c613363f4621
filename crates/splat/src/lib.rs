#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod cloud;
mod error;
mod render;
pub mod rng;

pub use cloud::{
    Cell, DEFAULT_CELL_SIZE_M, MAX_OFFSET_M, MIN_CELL_SIZE_M, PackedPoint, PointCloud, luminance,
};
pub use error::SplatError;
pub use render::{RenderOptions, RenderStats, Renderer};
