//! [`Frame`]: what the renderer produces for every pixel.

use std::path::Path;

use crate::{AnyImage, FrameError};

/// What a pixel of a frame holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum PixelStatus {
    /// A rendered point: intensity and range are valid.
    Hit,
    /// Inside the valid region but no point: the background (sky) intensity, infinite
    /// range.
    #[default]
    Sky,
    /// Outside the camera's valid region: intensity 0 and NaN range, to be ignored.
    Masked,
}

/// A rendered image with its per-pixel range and status, row-major (a measured picture,
/// whose ranges are unknown, is an [`crate::Image`]).
///
/// Not `PartialEq`: masked pixels hold NaN ranges; compare with
/// [`Frame::bitwise_eq`].
#[derive(Clone)]
pub struct Frame {
    width: u32,
    height: u32,
    /// Intensity in `[0, 1]`.
    pub intensity: Vec<f32>,
    /// Range `ρ` (distance from the viewpoint, metres) of the rendered point; `+∞` for
    /// sky, NaN where masked.
    pub range_m: Vec<f32>,
    /// What each pixel holds.
    pub status: Vec<PixelStatus>,
}

impl std::fmt::Debug for Frame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (hit, sky, masked) = self.counts();
        f.debug_struct("Frame")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("hit", &hit)
            .field("sky", &sky)
            .field("masked", &masked)
            .finish_non_exhaustive()
    }
}

impl Frame {
    /// Whether two frames are identical bit for bit (NaN ranges included).
    pub fn bitwise_eq(&self, other: &Frame) -> bool {
        self.width == other.width
            && self.height == other.height
            && self.status == other.status
            && self
                .intensity
                .iter()
                .map(|v| v.to_bits())
                .eq(other.intensity.iter().map(|v| v.to_bits()))
            && self
                .range_m
                .iter()
                .map(|v| v.to_bits())
                .eq(other.range_m.iter().map(|v| v.to_bits()))
    }

    /// A frame of the given size, all sky.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            intensity: vec![0.0; n],
            range_m: vec![f32::INFINITY; n],
            status: vec![PixelStatus::Sky; n],
        }
    }

    /// A frame of a camera's size.
    pub fn for_camera(camera: &ucm::Camera) -> Self {
        Self::new(camera.width(), camera.height())
    }

    /// The frame at `1/factor` of its resolution, for image pyramids (the size of
    /// [`ucm::Camera::downsampled`]): each `factor × factor` block becomes one pixel
    /// whose intensity and range are the means over the block's hits. The pixel is a
    /// hit when at least half of the block's valid pixels are hits, masked when
    /// `camera_coarse` masks it, and sky otherwise. `camera_coarse` must have the
    /// coarse size ([`FrameError::Size`] otherwise).
    pub fn downsampled(
        &self,
        factor: u32,
        camera_coarse: &ucm::Camera,
    ) -> Result<Frame, FrameError> {
        let (width, height) = crate::downsampled_size(self, factor, camera_coarse)?;
        let mut out = Frame::new(width, height);
        let (w, k) = (self.width as usize, factor as usize);
        let valid = camera_coarse.valid_pixels();
        for y in 0..height as usize {
            for x in 0..width as usize {
                let index = y * width as usize + x;
                if !valid[index] {
                    out.status[index] = PixelStatus::Masked;
                    out.intensity[index] = 0.0;
                    out.range_m[index] = f32::NAN;
                    continue;
                }
                let (mut hits, mut unmasked) = (0u32, 0u32);
                let (mut intensity, mut range) = (0.0f32, 0.0f32);
                for dy in 0..k {
                    let row = (y * k + dy) * w + x * k;
                    for i in row..row + k {
                        match self.status[i] {
                            PixelStatus::Hit => {
                                hits += 1;
                                unmasked += 1;
                                intensity += self.intensity[i];
                                range += self.range_m[i];
                            }
                            PixelStatus::Sky => unmasked += 1,
                            PixelStatus::Masked => {}
                        }
                    }
                }
                if hits > 0 && 2 * hits >= unmasked {
                    out.status[index] = PixelStatus::Hit;
                    out.intensity[index] = intensity / hits as f32;
                    out.range_m[index] = range / hits as f32;
                } else {
                    out.intensity[index] = self.sky_intensity(y * k, x * k, k);
                }
            }
        }
        Ok(out)
    }

    /// The intensity of the first sky pixel of a block (the background), else 0.
    fn sky_intensity(&self, y0: usize, x0: usize, k: usize) -> f32 {
        let w = self.width as usize;
        (0..k)
            .flat_map(|dy| (0..k).map(move |dx| (y0 + dy) * w + x0 + dx))
            .find(|&i| self.status[i] == PixelStatus::Sky)
            .map_or(0.0, |i| self.intensity[i])
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of pixels with each status: `(hit, sky, masked)`.
    pub fn counts(&self) -> (usize, usize, usize) {
        self.status
            .iter()
            .fold((0, 0, 0), |(h, s, m), st| match st {
                PixelStatus::Hit => (h + 1, s, m),
                PixelStatus::Sky => (h, s + 1, m),
                PixelStatus::Masked => (h, s, m + 1),
            })
    }

    /// Write `1/ρ` of every pixel into `out` (0 for sky and masked pixels).
    #[inline]
    pub fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError> {
        if out.len() != self.range_m.len() {
            return Err(FrameError::Length {
                what: "inverse range buffer",
                got: out.len(),
                expected: self.range_m.len(),
            });
        }
        // Without a branch (every pixel's quotient taken, kept or not), so that the
        // loop vectorises.
        for ((o, &r), &s) in out.iter_mut().zip(&self.range_m).zip(&self.status) {
            let inverse = 1.0 / r;
            *o = if s == PixelStatus::Hit { inverse } else { 0.0 };
        }
        Ok(())
    }

    /// Save the intensity as an 8-bit grey PNG; masked pixels are drawn black.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), FrameError> {
        let path = path.as_ref();
        let image = image::GrayImage::from_fn(self.width, self.height, |i, j| {
            let k = (j * self.width + i) as usize;
            let v = match self.status[k] {
                PixelStatus::Masked => 0.0,
                _ => self.intensity[k],
            };
            image::Luma([(v.clamp(0.0, 1.0) * 255.0).round() as u8])
        });
        image.save(path).map_err(|source| FrameError::Image {
            path: path.to_owned(),
            source,
        })
    }
}

impl AnyImage for Frame {
    fn width(&self) -> u32 {
        self.width
    }

    fn check_buffers(&self) -> Result<(), FrameError> {
        crate::check_length("intensity", self.intensity.len(), self)?;
        crate::check_length("range_m", self.range_m.len(), self)?;
        crate::check_length("status", self.status.len(), self)
    }

    fn height(&self) -> u32 {
        self.height
    }

    fn intensity(&self) -> &[f32] {
        &self.intensity
    }

    #[inline]
    fn is_observed(&self, index: usize) -> bool {
        self.status[index] != PixelStatus::Masked
    }

    #[inline]
    fn observed(&self, pixels: std::ops::Range<usize>, out: &mut [bool]) {
        assert_eq!(out.len(), pixels.len(), "one flag per pixel");
        for (o, &s) in out.iter_mut().zip(&self.status[pixels]) {
            *o = s != PixelStatus::Masked;
        }
    }

    #[inline]
    fn observed_intensity(&self, pixels: std::ops::Range<usize>, out: &mut [f32]) {
        assert_eq!(out.len(), pixels.len(), "one value per pixel");
        let status = &self.status[pixels.clone()];
        for ((o, &i), &s) in out.iter_mut().zip(&self.intensity[pixels]).zip(status) {
            *o = if s != PixelStatus::Masked { i } else { 0.0 };
        }
    }

    #[inline]
    fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError> {
        Frame::inverse_range(self, out)
    }

    fn downsampled(&self, factor: u32, camera_coarse: &ucm::Camera) -> Result<Self, FrameError> {
        Frame::downsampled(self, factor, camera_coarse)
    }
}
