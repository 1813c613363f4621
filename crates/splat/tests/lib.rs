//! Integration tests of `splat`, one binary (modules below) for fast linking.

mod common;
mod las;
mod render;
