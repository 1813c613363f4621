//! Integration tests of `frame`, one binary.

mod pictures;
mod views;
