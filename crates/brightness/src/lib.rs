#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod error;
mod feature;
mod gradient;
mod normal;
mod photometric;

pub use error::BrightnessError;
pub use feature::{Against, Brightness, PixelRows};
pub use gradient::masked_gradient;
pub use normal::{normal_equations, normal_equations_with_column};
