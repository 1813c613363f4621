#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod config;
mod error;
pub mod global;
pub mod localize;
mod outcome;
mod servo;
pub mod solve;
pub mod track;
pub mod vignetting;

pub use config::{MAX_ITERATIONS, MAX_PGM_STRIDE, Method, Robust, Support, VvsConfig};
pub use error::VvsError;
pub use global::{
    GlobalConfig, PriorBox, SearchPhase, SearchProgress, SearchReport, turned,
    turned_about_optical_axis,
};
pub use localize::{CameraFile, LocalizeFiles, Localized, Localizer, PreparedLocalizer};
pub use outcome::{Divergence, IterationRecord, Outcome, StopReason};
pub use pgm::PgmJacobian;
pub use servo::{MAX_SERVO_PIXELS, SERVO_BYTES_PER_PIXEL, Servo};
pub use track::{Prediction, Recovery, TrackReport, TrackedFrame, Tracker};
