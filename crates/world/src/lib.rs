#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

pub mod city;
mod error;
pub mod sequence;

pub use city::{City, CityParams, KERB_HEIGHT_M, Textures, camera_looking_down};
pub use error::WorldError;
pub use sequence::{Acquisition, Shake, Trajectory, Turn};
