//! [`Level`]: the buffers of one pyramid level of a [`crate::Servo`].

use brightness::Brightness;
use frame::{Frame, Image};
use pgm::{Pgm, PgmOptions};
use splat::{RenderOptions, Renderer};
use ucm::Camera;

use crate::vignetting::RadialVignetting;
use crate::{VvsConfig, VvsError};

/// The buffers of one pyramid level (level 0: full resolution).
#[derive(Debug)]
pub(crate) struct Level {
    pub(crate) camera: Camera,
    pub(crate) renderer: Renderer,
    pub(crate) frame: Frame,
    pub(crate) pgm: Pgm,
    pub(crate) brightness: Brightness,
    /// The vignetting model's basis, the corrected rendering, and the transform of its
    /// derivative pictures (used only with `VvsConfig::vignetting`).
    pub(crate) vignetting: RadialVignetting,
    pub(crate) corrected: Frame,
    pub(crate) derivative: Image,
    pub(crate) derivative_pgm: Pgm,
    /// With [`crate::Support::Common`]: the desired picture's features on the pixels compared
    /// (taken again at every iteration), and those pixels.
    pub(crate) desired_pgm: Pgm,
    pub(crate) desired_brightness: Brightness,
    pub(crate) support: Vec<bool>,
    /// The desired picture as compared, at every pixel it observes, and those pixels.
    pub(crate) against: Vec<f32>,
    pub(crate) against_observed: Vec<bool>,
}

/// The PGM's options of `config`, its brightness normalised or not.
fn pgm_options(config: &VvsConfig, normalize: bool) -> PgmOptions {
    PgmOptions {
        stride: config.pgm_stride,
        normalize,
        parallel: config.parallel,
        recursive_from_lambda: config.pgm_recursive_from_lambda,
        interaction_row_step_lambdas: config.pgm_interaction_row_step_lambdas,
        ..PgmOptions::default()
    }
}

impl Level {
    pub(crate) fn new(camera: Camera, config: &VvsConfig) -> Result<Self, VvsError> {
        let options = RenderOptions {
            lod_spacing_px: config.lod_spacing_px,
            parallel: config.parallel,
            ..RenderOptions::default()
        };
        // The camera's pixel grid set up once, shared by every feature of the level.
        let brightness = Brightness::new(&camera).with_normalization(config.normalize);
        let pgm = |normalize| {
            Pgm::from_brightness(brightness.sharing_tables(), pgm_options(config, normalize))
        };
        Ok(Self {
            renderer: Renderer::new(camera.clone(), options)?,
            frame: Frame::for_camera(&camera),
            pgm: pgm(config.normalize)?,
            vignetting: RadialVignetting::new(&camera),
            corrected: Frame::for_camera(&camera),
            derivative: Image::new(camera.width(), camera.height()),
            derivative_pgm: pgm(false)?,
            desired_pgm: pgm(config.normalize)?,
            desired_brightness: brightness
                .sharing_tables()
                .with_normalization(config.normalize),
            brightness,
            support: vec![false; camera.pixel_count()],
            against: vec![0.0; camera.pixel_count()],
            against_observed: vec![false; camera.pixel_count()],
            camera,
        })
    }
}
