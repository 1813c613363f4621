//! [`Restricted`]: a picture seen only on a set of pixels.

use crate::{AnyImage, FrameError};

/// A picture (measured or rendered) whose pixels count as observed only where
/// `support` is true as well: what two pictures are compared on when each holds
/// intensities where the other may not (a rendering's holes where the cloud has no
/// point, a picture's pixels outside its sensor's field). Intensities and ranges are
/// the picture's; the view copies nothing.
#[derive(Clone, Copy, Debug)]
pub struct Restricted<'a, P> {
    picture: &'a P,
    support: &'a [bool],
}

impl<'a, P: AnyImage> Restricted<'a, P> {
    /// `picture` seen on `support` (one flag per pixel, row-major;
    /// [`FrameError::Length`] otherwise).
    pub fn new(picture: &'a P, support: &'a [bool]) -> Result<Self, FrameError> {
        let n = picture.width() as usize * picture.height() as usize;
        if support.len() != n {
            return Err(FrameError::Length {
                what: "support",
                got: support.len(),
                expected: n,
            });
        }
        Ok(Self { picture, support })
    }

    /// The whole picture.
    pub fn picture(&self) -> &'a P {
        self.picture
    }

    /// The support.
    pub fn support(&self) -> &'a [bool] {
        self.support
    }
}

impl<P: AnyImage> AnyImage for Restricted<'_, P> {
    fn width(&self) -> u32 {
        self.picture.width()
    }

    fn height(&self) -> u32 {
        self.picture.height()
    }

    fn intensity(&self) -> &[f32] {
        self.picture.intensity()
    }

    fn check_buffers(&self) -> Result<(), FrameError> {
        self.picture.check_buffers()?;
        crate::check_length("support", self.support.len(), self)
    }

    #[inline]
    fn is_observed(&self, index: usize) -> bool {
        self.support[index] && self.picture.is_observed(index)
    }

    #[inline]
    fn observed(&self, pixels: std::ops::Range<usize>, out: &mut [bool]) {
        self.picture.observed(pixels.clone(), out);
        for (o, &s) in out.iter_mut().zip(&self.support[pixels]) {
            *o &= s;
        }
    }

    #[inline]
    fn observed_intensity(&self, pixels: std::ops::Range<usize>, out: &mut [f32]) {
        self.picture.observed_intensity(pixels.clone(), out);
        for (o, &s) in out.iter_mut().zip(&self.support[pixels]) {
            *o = if s { *o } else { 0.0 };
        }
    }

    /// The picture's inverse ranges, 0 outside the support.
    #[inline]
    fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError> {
        self.picture.inverse_range(out)?;
        for (o, &s) in out.iter_mut().zip(self.support) {
            *o = if s { *o } else { 0.0 };
        }
        Ok(())
    }

    /// Not available for a view: downsample the picture and its support instead.
    fn downsampled(&self, _factor: u32, camera_coarse: &ucm::Camera) -> Result<Self, FrameError> {
        Err(FrameError::Size {
            what: "restricted view (downsample the picture itself)",
            got_width: self.width(),
            got_height: self.height(),
            width: camera_coarse.width(),
            height: camera_coarse.height(),
        })
    }
}
