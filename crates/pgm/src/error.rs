//! The one error type of the crate.

/// What can go wrong computing a PGM.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PgmError {
    /// An extent outside the supported range.
    #[error("Gaussian extent λ = {0} px is outside the supported range [0.5, 40]")]
    Lambda(f32),
    /// Invalid options.
    #[error("invalid option `{name}`: {message}")]
    Option {
        /// The option.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The brightness stage failed (image size).
    #[error(transparent)]
    Brightness(#[from] brightness::BrightnessError),
}
