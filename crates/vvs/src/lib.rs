#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod config;
mod error;
mod outcome;
mod servo;
pub mod solve;

pub use config::{JacobianKind, Method, Robust, VvsConfig};
pub use error::VvsError;
pub use outcome::{Divergence, IterationRecord, Outcome, StopReason};
pub use servo::Servo;
