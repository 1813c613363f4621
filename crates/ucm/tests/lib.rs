//! Integration tests of `ucm`, one binary (modules below) for fast linking.

mod common;
mod files;
mod jacobians;
mod projection;
mod se3;
