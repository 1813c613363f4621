#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod cloud;
mod error;
pub mod las_io;
mod render;
pub mod rng;

pub use cloud::{
    Cell, DEFAULT_CELL_SIZE_M, MAX_OFFSET_M, MIN_CELL_SIZE_M, PackedPoint, PointCloud, luminance,
};
pub use error::SplatError;
pub use las_io::{LasInfo, check_las_path, read_las, write_las};
pub use render::{RenderOptions, RenderStats, Renderer};
