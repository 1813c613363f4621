#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod error;
mod frame;
mod image;
mod resample;
mod restricted;

pub use error::FrameError;
pub use frame::{Frame, PixelStatus};
pub use image::Image;
pub use resample::seen_through;
pub use restricted::Restricted;

/// What a feature reads from a picture, measured ([`Image`]) or rendered ([`Frame`]):
/// its size, its intensities, which pixels hold one, and the inverse range where it is
/// known.
pub trait AnyImage {
    /// Width, pixels.
    fn width(&self) -> u32;

    /// Height, pixels.
    fn height(&self) -> u32;

    /// Intensity of every pixel, row-major (meaningless where not observed).
    fn intensity(&self) -> &[f32];

    /// Whether pixel `index` (row-major) holds an intensity.
    fn is_observed(&self, index: usize) -> bool;

    /// The intensities of the pixels `pixels` (row-major indices) where observed, 0
    /// where not, into `out` (one value per pixel of `pixels`). Panics if `pixels` is
    /// outside the picture or `out` is not as long. The pictures of this crate
    /// override it with a loop without branches (the one per pixel mispredicted at
    /// every edge between sky and ground).
    fn observed_intensity(&self, pixels: std::ops::Range<usize>, out: &mut [f32]) {
        assert_eq!(out.len(), pixels.len(), "one value per pixel");
        let intensity = &self.intensity()[pixels.clone()];
        for ((o, &i), k) in out.iter_mut().zip(intensity).zip(pixels) {
            *o = if self.is_observed(k) { i } else { 0.0 };
        }
    }

    /// Whether each pixel of `pixels` (row-major indices) holds an intensity, into
    /// `out` (one flag per pixel of `pixels`). Panics if `pixels` is outside the
    /// picture or `out` is not as long.
    fn observed(&self, pixels: std::ops::Range<usize>, out: &mut [bool]) {
        assert_eq!(out.len(), pixels.len(), "one flag per pixel");
        for (o, k) in out.iter_mut().zip(pixels) {
            *o = self.is_observed(k);
        }
    }

    /// Write `1/ρ` of every pixel into `out` (ρ the range in metres; 0 where it is
    /// unknown, infinite or the pixel is not observed). `out` must have one value per
    /// pixel ([`FrameError::Length`] otherwise).
    fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError>;

    /// The picture at `1/factor` of its resolution, of the size of `camera_coarse`
    /// ([`ucm::Camera::downsampled`]; [`FrameError::Size`] otherwise), for image
    /// pyramids.
    fn downsampled(&self, factor: u32, camera_coarse: &ucm::Camera) -> Result<Self, FrameError>
    where
        Self: Sized;

    /// [`FrameError::Length`] unless every per-pixel buffer of the picture holds one
    /// value per pixel (its buffers are public fields, which a caller may have
    /// resized): what a feature checks before it reads them. The default checks the
    /// intensities; the pictures of this crate check each of their buffers.
    fn check_buffers(&self) -> Result<(), FrameError> {
        check_length("intensity", self.intensity().len(), self)
    }

    /// [`FrameError::Size`] unless the picture has `camera`'s size, and
    /// [`FrameError::Length`] unless its buffers hold a value per pixel
    /// ([`AnyImage::check_buffers`]).
    fn check_size(&self, what: &'static str, camera: &ucm::Camera) -> Result<(), FrameError> {
        if self.width() == camera.width() && self.height() == camera.height() {
            self.check_buffers()
        } else {
            Err(FrameError::Size {
                what,
                got_width: self.width(),
                got_height: self.height(),
                width: camera.width(),
                height: camera.height(),
            })
        }
    }
}

/// The size of `picture` downsampled by `factor`, checked against `camera_coarse`.
fn downsampled_size(
    picture: &impl AnyImage,
    factor: u32,
    camera_coarse: &ucm::Camera,
) -> Result<(u32, u32), FrameError> {
    let (width, height) = (
        picture.width().checked_div(factor).unwrap_or(0),
        picture.height().checked_div(factor).unwrap_or(0),
    );
    if width != camera_coarse.width() || height != camera_coarse.height() {
        return Err(FrameError::Size {
            what: "downsampled picture",
            got_width: width,
            got_height: height,
            width: camera_coarse.width(),
            height: camera_coarse.height(),
        });
    }
    Ok((width, height))
}

/// [`FrameError::Length`] unless a buffer of `got` values holds one per pixel of
/// `picture`.
fn check_length(
    what: &'static str,
    got: usize,
    picture: &(impl AnyImage + ?Sized),
) -> Result<(), FrameError> {
    let expected = picture.width() as usize * picture.height() as usize;
    if got == expected {
        Ok(())
    } else {
        Err(FrameError::Length {
            what,
            got,
            expected,
        })
    }
}
