//! Integration tests of `cloud-io`, one binary (modules below) for fast linking.

mod common;
mod convert;
mod e57;
mod las;
mod ply;
