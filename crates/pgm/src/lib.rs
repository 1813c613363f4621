#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

pub mod convolve;
mod error;
pub mod recursive;
mod simd;
mod transform;

pub use error::PgmError;
pub use transform::{LAMBDA_RANGE, MAX_KERNEL_RADIUS_LAMBDAS, Pgm, PgmJacobian, PgmOptions};
