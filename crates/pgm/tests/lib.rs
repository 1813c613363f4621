//! Integration tests of `pgm`, one binary (modules below) for fast linking.

mod common;
mod convolve;
mod transform;
