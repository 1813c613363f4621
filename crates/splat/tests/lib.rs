//! Integration tests of `splat`, one binary (modules below) for fast linking.

mod cloud;
mod common;
mod render;
