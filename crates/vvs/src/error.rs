//! The one error type of the crate.

/// Invalid input to the optimiser. A run that diverges is not an error: it returns an
/// [`crate::Outcome`] whose [`crate::StopReason`] says so.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum VvsError {
    /// A configuration value out of its documented range.
    #[error("invalid configuration `{name}`: {message}")]
    Config {
        /// The field.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A configuration file that cannot be read or parsed.
    #[error("configuration file: {0}")]
    ConfigFile(String),
    /// The desired image does not have the camera's size.
    #[error("desired image is {got_width}x{got_height} but the camera is {width}x{height}")]
    DesiredSize {
        /// Image width.
        got_width: u32,
        /// Image height.
        got_height: u32,
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
    },
    /// The desired image holds no intensity on the camera's valid region.
    #[error("the desired image holds no intensity on the camera's valid region")]
    EmptyDesired,
    /// The desired image holds one intensity wherever it is observed: nothing to align.
    #[error(
        "the desired image is uniform ({value} on its {observed} observed pixels of the camera's region): nothing to localise"
    )]
    UniformDesired {
        /// Its one intensity.
        value: f32,
        /// Its observed pixels in the camera's region.
        observed: usize,
    },
    /// The desired image holds a NaN or infinite intensity.
    #[error("the desired image's pixel {index} is not finite")]
    NonFiniteDesired {
        /// The pixel, row-major.
        index: usize,
    },
    /// The initial pose is not finite.
    #[error("initial pose is not finite")]
    NonFinitePose,
    /// [`crate::Method::Global`] asked of a call that runs local methods: the global
    /// search takes a prior box.
    #[error(
        "the global method searches a prior box: give one (Localizer::prior, \
         Servo::localize_in_box)"
    )]
    GlobalWithoutPrior,
    /// At the initial pose the camera sees too little of the cloud to start (a pose far
    /// from the cloud, looking away from it, or a camera that sees nothing).
    #[error(
        "at the initial pose the camera sees the cloud on fewer than {min_percent}% of its pixels: nothing to start from (is the pose in the cloud's frame, and the camera right?)"
    )]
    CloudNotInView {
        /// `VvsConfig::min_hit_fraction`, in per cent.
        min_percent: f64,
    },
    /// A camera with more pixels than the optimiser sets up.
    #[error(
        "the camera has {pixels} pixels, more than the {max} the optimiser sets up (about {bytes_per_pixel} bytes each): downsample or crop the picture"
    )]
    TooManyPixels {
        /// The camera's pixels.
        pixels: u64,
        /// [`crate::MAX_SERVO_PIXELS`].
        max: u64,
        /// Set-up memory per pixel, bytes (approximate).
        bytes_per_pixel: u64,
    },
    /// A name (of a method, a stop reason) that names nothing.
    #[error("unknown {what} `{text}` (expected one of: {expected})")]
    UnknownName {
        /// What was named.
        what: &'static str,
        /// The text.
        text: String,
        /// The names there are.
        expected: String,
    },
    /// [`crate::Tracker::align`] after the track was lost.
    #[error("the track is lost: an alignment diverged (or failed, and so did the search after it)")]
    TrackLost,
    /// [`crate::Tracker::track`] reached a frame it must use but was not given.
    #[error("frame {0} of the sequence is to be tracked but was not given")]
    MissingFrame(usize),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] splat::SplatError),
    /// A cloud file could not be read.
    #[error(transparent)]
    CloudFile(#[from] cloud_io::CloudIoError),
    /// A camera file could not be read or describes no valid camera.
    #[error(transparent)]
    Camera(#[from] ucm::UcmError),
    /// A picture could not be used (size, pyramid).
    #[error(transparent)]
    Frame(#[from] frame::FrameError),
    /// The PGM stage failed.
    #[error(transparent)]
    Pgm(#[from] pgm::PgmError),
    /// The brightness stage failed.
    #[error(transparent)]
    Brightness(#[from] brightness::BrightnessError),
}
