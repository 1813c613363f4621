//! [`Level`]: the buffers of one pyramid level of a [`crate::Servo`].

use brightness::Brightness;
use frame::{Frame, Image};
use pgm::{Pgm, PgmOptions};
use splat::{PointCloud, RenderOptions, RenderStats, Renderer};
use ucm::{Camera, Isometry3};

use crate::vignetting::RadialVignetting;
use crate::{VvsConfig, VvsError};

/// The buffers of one pyramid level (level 0: full resolution).
#[derive(Debug)]
pub(crate) struct Level {
    pub(crate) camera: Camera,
    pub(crate) renderer: Renderer,
    pub(crate) frame: Frame,
    /// The pose `frame` was last rendered at and what that rendering did, for
    /// [`render_once`].
    pub(crate) rendered_at: Option<(Isometry3, RenderStats)>,
    /// The rendering's PGM; a brightness stage (PoVS) computes the brightness with the
    /// buffers of its brightness stage ([`Pgm::brightness_mut`]).
    pub(crate) pgm: Pgm,
    /// The vignetting model's buffers, with [`VvsConfig::vignetting`] only.
    pub(crate) vignetting: Option<Box<VignettingBuffers>>,
    /// With [`crate::Support::Common`]: the desired picture's features on the pixels
    /// compared (taken again at every iteration; its brightness stage for a brightness
    /// stage), and those pixels.
    pub(crate) desired_pgm: Pgm,
    pub(crate) support: Vec<bool>,
    /// The desired picture as compared, at every pixel it observes, and those pixels.
    pub(crate) against: Vec<f32>,
    pub(crate) against_observed: Vec<bool>,
    /// With [`VvsConfig::rerender_px`]: every pixel's ray (computed by the first
    /// iteration that warps, [`crate::servo::warp::rays`]), the points the last
    /// rendering's hits see ([`crate::servo::warp::lift`]), and the picture warped into
    /// it (empty without).
    pub(crate) rays: Vec<[f32; 3]>,
    pub(crate) points: Vec<[f32; 3]>,
    pub(crate) warped: Image,
}

/// The vignetting model's basis, the corrected rendering, and the transform of its
/// derivative pictures.
#[derive(Debug)]
pub(crate) struct VignettingBuffers {
    pub(crate) model: RadialVignetting,
    pub(crate) corrected: Frame,
    pub(crate) derivative: Image,
    pub(crate) derivative_pgm: Pgm,
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
        let pgm = Pgm::from_brightness(
            Brightness::new(&camera),
            pgm_options(config, config.normalize),
        )?;
        let sharing = |normalize| {
            Pgm::from_brightness(
                pgm.brightness().sharing_tables(),
                pgm_options(config, normalize),
            )
        };
        let vignetting = if config.vignetting {
            Some(Box::new(VignettingBuffers {
                model: RadialVignetting::new(&camera),
                corrected: Frame::for_camera(&camera),
                derivative: Image::new(camera.width(), camera.height()),
                derivative_pgm: sharing(false)?,
            }))
        } else {
            None
        };
        Ok(Self {
            renderer: Renderer::new(camera.clone(), options)?,
            frame: Frame::for_camera(&camera),
            rendered_at: None,
            desired_pgm: sharing(config.normalize)?,
            pgm,
            vignetting,
            support: vec![false; camera.pixel_count()],
            against: vec![0.0; camera.pixel_count()],
            against_observed: vec![false; camera.pixel_count()],
            rays: Vec::new(),
            points: if config.rerender_px.is_some() {
                vec![[f32::NAN; 3]; camera.pixel_count()]
            } else {
                Vec::new()
            },
            warped: if config.rerender_px.is_some() {
                Image::new(camera.width(), camera.height())
            } else {
                Image::new(0, 0)
            },
            camera,
        })
    }
}

/// Render `cloud` at `world_from_camera` into `frame`, unless `frame` holds that
/// rendering already (`rendered_at`, the same pose to the bit: a stage that starts
/// where the one before stalled, at the same level, takes the frame as it is; the
/// renderer is deterministic, so the bits are the same either way).
pub(crate) fn render_once(
    renderer: &mut Renderer,
    rendered_at: &mut Option<(Isometry3, RenderStats)>,
    cloud: &PointCloud,
    world_from_camera: &Isometry3,
    frame: &mut Frame,
) -> Result<RenderStats, VvsError> {
    if let Some((pose, stats)) = rendered_at
        && same_bits(pose, world_from_camera)
    {
        return Ok(*stats);
    }
    // A failed rendering may leave the frame half written.
    *rendered_at = None;
    let stats = renderer.render(cloud, &world_from_camera.inverse(), frame)?;
    *rendered_at = Some((*world_from_camera, stats));
    Ok(stats)
}

/// Whether two poses are the same to the bit.
fn same_bits(a: &Isometry3, b: &Isometry3) -> bool {
    let bits = |p: &Isometry3| {
        let (q, t) = (p.rotation.to_array(), p.translation.to_array());
        [q[0], q[1], q[2], q[3], t[0], t[1], t[2]].map(f64::to_bits)
    };
    bits(a) == bits(b)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// The frame is rendered again at a new pose, and taken as it is at the pose of
    /// its last rendering (shown by a pixel changed in between), after a failed
    /// rendering too.
    #[test]
    fn a_frame_is_rendered_once_per_pose() {
        let (cloud, camera) = crate::servo::test_plane();
        let mut level = Level::new(camera, &VvsConfig::default()).unwrap();
        let Level {
            renderer,
            frame,
            rendered_at,
            ..
        } = &mut level;
        let here = Isometry3::from_pose_vector([-2.0, 1.0, -1.0, 0.0, 0.0, 0.0]).unwrap();
        let there = Isometry3::from_pose_vector([-2.0, 1.2, -1.0, 0.0, 0.0, 0.0]).unwrap();
        let first = render_once(renderer, rendered_at, &cloud, &here, frame).unwrap();
        assert!(first.pixels_hit > 0);
        let rendered = frame.clone();
        frame.intensity[0] = 42.0;
        assert_eq!(
            render_once(renderer, rendered_at, &cloud, &here, frame).unwrap(),
            first
        );
        assert_eq!(frame.intensity[0], 42.0, "rendered again at the same pose");
        render_once(renderer, rendered_at, &cloud, &there, frame).unwrap();
        assert_ne!(frame.intensity, rendered.intensity);
        render_once(renderer, rendered_at, &cloud, &here, frame).unwrap();
        assert_eq!(frame.intensity, rendered.intensity);
        let nowhere = Isometry3 {
            translation: DVec3::NAN,
            ..here
        };
        assert!(render_once(renderer, rendered_at, &cloud, &nowhere, frame).is_err());
        assert!(rendered_at.is_none());
        render_once(renderer, rendered_at, &cloud, &here, frame).unwrap();
        assert_eq!(frame.intensity, rendered.intensity);
    }
}
