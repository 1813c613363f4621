//! [`Frame`]: what the renderer produces for every pixel.

use std::path::Path;

use crate::SplatError;

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

/// A rendered (or acquired) image with its per-pixel range and status, row-major.
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
    pub fn inverse_range(&self, out: &mut [f32]) -> Result<(), SplatError> {
        if out.len() != self.range_m.len() {
            return Err(SplatError::AttributeLength {
                what: "inverse range buffer",
                got: out.len(),
                expected: self.range_m.len(),
            });
        }
        for ((o, &r), &s) in out.iter_mut().zip(&self.range_m).zip(&self.status) {
            *o = if s == PixelStatus::Hit { 1.0 / r } else { 0.0 };
        }
        Ok(())
    }

    /// Save the intensity as an 8-bit grey PNG; masked pixels are drawn black.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), SplatError> {
        let path = path.as_ref();
        let image = image::GrayImage::from_fn(self.width, self.height, |i, j| {
            let k = (j * self.width + i) as usize;
            let v = match self.status[k] {
                PixelStatus::Masked => 0.0,
                _ => self.intensity[k],
            };
            image::Luma([(v.clamp(0.0, 1.0) * 255.0).round() as u8])
        });
        image.save(path).map_err(|source| SplatError::Image {
            path: path.to_owned(),
            source,
        })
    }
}
