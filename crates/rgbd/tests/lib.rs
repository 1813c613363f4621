//! Tests of the `rgbd` crate: fusion of synthetic frames with known geometry and
//! colour, the dataset description and its pose files, and the real house pictures.

mod align;
mod dataset;
mod fusion;
mod scenes;
