//! The valid region of a catadioptric image: where the mirror is imaged and the robot
//! (or the camera itself, at the centre) is not.

use std::path::{Path, PathBuf};

use crate::UcmError;

/// An annulus centred on a point of the image, radii in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Annulus {
    /// Centre `(u, v)`, pixels; by default the principal point.
    pub center_px: [f64; 2],
    /// Pixels closer to the centre than this are masked (the nadir and the robot).
    pub inner_radius_px: f64,
    /// Pixels farther from the centre than this are masked (beyond the mirror's rim).
    pub outer_radius_px: f64,
}

impl Annulus {
    fn validate(&self) -> Result<(), UcmError> {
        for (name, value) in [
            ("center_px[0]", self.center_px[0]),
            ("center_px[1]", self.center_px[1]),
            ("inner_radius_px", self.inner_radius_px),
            ("outer_radius_px", self.outer_radius_px),
        ] {
            if !value.is_finite() {
                return Err(UcmError::NonFinite { name, value });
            }
        }
        if !(self.inner_radius_px >= 0.0 && self.inner_radius_px < self.outer_radius_px) {
            return Err(UcmError::BadAnnulus {
                inner: self.inner_radius_px,
                outer: self.outer_radius_px,
            });
        }
        Ok(())
    }

    fn contains(&self, u: f64, v: f64) -> bool {
        let du = u - self.center_px[0];
        let dv = v - self.center_px[1];
        let r2 = du * du + dv * dv;
        r2 >= self.inner_radius_px * self.inner_radius_px
            && r2 <= self.outer_radius_px * self.outer_radius_px
    }
}

/// An explicit mask: one flag per pixel, row-major, `true` where valid.
#[derive(Clone, PartialEq)]
pub struct Mask {
    width: u32,
    height: u32,
    valid: Vec<bool>,
    source: Option<PathBuf>,
}

impl std::fmt::Debug for Mask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mask")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("valid", &self.valid.iter().filter(|&&v| v).count())
            .field("source", &self.source)
            .finish()
    }
}

impl Mask {
    /// A mask from row-major flags. The length must be `width × height`.
    pub fn new(width: u32, height: u32, valid: Vec<bool>) -> Result<Self, UcmError> {
        if valid.len() != width as usize * height as usize {
            return Err(UcmError::LengthMismatch {
                input: valid.len(),
                output: width as usize * height as usize,
            });
        }
        Ok(Self {
            width,
            height,
            valid,
            source: None,
        })
    }

    /// Read a mask image: any pixel whose (luma) value is above half the range is valid.
    /// Its size is checked against [`crate::MAX_PIXELS`] before it is decoded.
    pub fn from_image_file(path: &Path) -> Result<Self, UcmError> {
        let error = |source| UcmError::MaskImage {
            path: path.to_owned(),
            source,
        };
        let reader = image::ImageReader::open(path)
            .map_err(|e| error(image::ImageError::IoError(e)))?
            .with_guessed_format()
            .map_err(|e| error(image::ImageError::IoError(e)))?;
        let (width, height) = reader.into_dimensions().map_err(error)?;
        if u64::from(width) * u64::from(height) > crate::MAX_PIXELS {
            return Err(UcmError::TooManyPixels { width, height });
        }
        let image = image::open(path).map_err(error)?.into_luma8();
        let (width, height) = image.dimensions();
        let valid = image.pixels().map(|p| p.0[0] >= 128).collect();
        Ok(Self {
            width,
            height,
            valid,
            source: Some(path.to_owned()),
        })
    }

    /// Write the mask as an 8-bit PNG (255 valid, 0 masked).
    pub fn save_png(&self, path: &Path) -> Result<(), UcmError> {
        let buffer = image::GrayImage::from_fn(self.width, self.height, |i, j| {
            image::Luma([if self.valid[(j * self.width + i) as usize] {
                255
            } else {
                0
            }])
        });
        buffer.save(path).map_err(|source| UcmError::MaskImage {
            path: path.to_owned(),
            source,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major flags.
    pub fn flags(&self) -> &[bool] {
        &self.valid
    }

    /// The file the mask was read from, if any.
    pub fn source(&self) -> Option<&Path> {
        self.source.as_deref()
    }
}

/// Where a catadioptric image carries information.
#[derive(Clone, Debug, PartialEq)]
pub enum ValidRegion {
    /// The whole image.
    Full,
    /// An annulus (the usual catadioptric case).
    Annulus(Annulus),
    /// An explicit per-pixel mask of the image's size.
    Mask(Mask),
}

impl ValidRegion {
    pub(crate) fn validate(&self, width: u32, height: u32) -> Result<(), UcmError> {
        match self {
            ValidRegion::Full => Ok(()),
            ValidRegion::Annulus(a) => a.validate(),
            ValidRegion::Mask(m) if m.width != width || m.height != height => {
                Err(UcmError::MaskSizeMismatch {
                    mask_width: m.width,
                    mask_height: m.height,
                    width,
                    height,
                })
            }
            ValidRegion::Mask(_) => Ok(()),
        }
    }

    /// Row-major validity of every pixel centre of a `width × height` image.
    pub(crate) fn rasterise(&self, width: u32, height: u32) -> Vec<bool> {
        match self {
            ValidRegion::Full => vec![true; width as usize * height as usize],
            ValidRegion::Annulus(a) => (0..height)
                .flat_map(|j| (0..width).map(move |i| a.contains(f64::from(i), f64::from(j))))
                .collect(),
            ValidRegion::Mask(m) => m.valid.clone(),
        }
    }
}
