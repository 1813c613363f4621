//! The two pictures of an RGB-D frame: [`DepthImage`] (metres per pixel) and
//! [`ColorImage`] (8-bit RGB).

use std::path::Path;

use image::{DynamicImage, ImageReader};

use crate::RgbdError;

/// A depth picture in metres, row-major; 0 where the sensor measured nothing.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    width: u32,
    height: u32,
    /// Depth along the optical axis (`Z`), metres; 0: no measurement.
    pub depth_m: Vec<f32>,
}

/// A colour picture, 8 bits per channel, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ColorImage {
    width: u32,
    height: u32,
    /// `[R, G, B]` of every pixel.
    pub rgb: Vec<[u8; 3]>,
}

/// Open a picture after checking its size against `max_pixels` from its header.
fn decode(path: &Path, max_pixels: u64) -> Result<DynamicImage, RgbdError> {
    let error = |source| RgbdError::Image {
        path: path.to_owned(),
        source: Box::new(source),
    };
    let io = |e| error(image::ImageError::IoError(e));
    let reader = || {
        ImageReader::open(path)
            .map_err(io)?
            .with_guessed_format()
            .map_err(io)
    };
    let (width, height) = reader()?.into_dimensions().map_err(error)?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels > max_pixels {
        return Err(RgbdError::Parameter {
            name: "picture",
            message: format!(
                "{} has {pixels} pixels, more than the {max_pixels} allowed",
                path.display()
            ),
        });
    }
    reader()?.decode().map_err(error)
}

impl DepthImage {
    /// A depth picture from its values (metres, 0 for none; NaN, infinite and negative
    /// values count as none).
    pub fn from_metres(width: u32, height: u32, mut depth_m: Vec<f32>) -> Result<Self, RgbdError> {
        let expected = width as usize * height as usize;
        if depth_m.len() != expected {
            return Err(RgbdError::Length {
                what: "depth",
                got: depth_m.len(),
                expected,
            });
        }
        for d in &mut depth_m {
            if !(d.is_finite() && *d > 0.0) {
                *d = 0.0;
            }
        }
        Ok(Self {
            width,
            height,
            depth_m,
        })
    }

    /// Read a 16-bit grey PNG or binary PGM (8-bit grey is accepted too): each sample
    /// times `scale_m` metres (0.001 for millimetres); the samples listed in `invalid`
    /// (and 0) are no measurement. Its size is checked against [`ucm::MAX_PIXELS`]
    /// before it is decoded.
    pub fn load(path: impl AsRef<Path>, scale_m: f64, invalid: &[u16]) -> Result<Self, RgbdError> {
        let path = path.as_ref();
        if !(scale_m > 0.0 && scale_m.is_finite()) {
            return Err(RgbdError::Parameter {
                name: "depth_scale_m",
                message: format!("must be > 0, got {scale_m}"),
            });
        }
        let picture = decode(path, ucm::MAX_PIXELS)?;
        let (width, height) = (picture.width(), picture.height());
        let samples: Vec<u16> = match picture {
            DynamicImage::ImageLuma16(p) => p.into_raw(),
            DynamicImage::ImageLuma8(p) => p.into_raw().into_iter().map(u16::from).collect(),
            other => {
                return Err(RgbdError::DepthFormat {
                    path: path.to_owned(),
                    kind: format!("{:?}", other.color()),
                });
            }
        };
        let depth_m = samples
            .into_iter()
            .map(|s| {
                if s == 0 || invalid.contains(&s) {
                    0.0
                } else {
                    (f64::from(s) * scale_m) as f32
                }
            })
            .collect();
        Self::from_metres(width, height, depth_m)
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Pixels with a measurement.
    pub fn measured_count(&self) -> usize {
        self.depth_m.iter().filter(|&&d| d > 0.0).count()
    }
}

impl ColorImage {
    /// A colour picture from its pixels.
    pub fn from_rgb(width: u32, height: u32, rgb: Vec<[u8; 3]>) -> Result<Self, RgbdError> {
        let expected = width as usize * height as usize;
        if rgb.len() != expected {
            return Err(RgbdError::Length {
                what: "colour",
                got: rgb.len(),
                expected,
            });
        }
        Ok(Self { width, height, rgb })
    }

    /// Read a PNG or JPEG (grey or colour, 8 or 16 bits: reduced to 8-bit RGB). Its
    /// size is checked against [`ucm::MAX_PIXELS`] before it is decoded.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, RgbdError> {
        let picture = decode(path.as_ref(), ucm::MAX_PIXELS)?.into_rgb8();
        let (width, height) = picture.dimensions();
        let rgb = picture
            .into_raw()
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        Self::from_rgb(width, height, rgb)
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The colour at `(u, v)` (pixel centres at integers), bilinear between the four
    /// nearest pixels, as `f32` in `[0, 255]`; `None` outside the picture, and for an
    /// empty picture or one whose `rgb` does not hold a colour per pixel.
    pub fn bilinear(&self, u: f32, v: f32) -> Option<[f32; 3]> {
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 || self.rgb.len() != w * h {
            return None;
        }
        if !(u >= 0.0 && v >= 0.0 && u <= (w - 1) as f32 && v <= (h - 1) as f32) {
            return None;
        }
        let (x0, y0) = (
            (u as usize).min(w.saturating_sub(2)),
            (v as usize).min(h.saturating_sub(2)),
        );
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (u - x0 as f32, v - y0 as f32);
        let at = |x: usize, y: usize| self.rgb[y * w + x].map(f32::from);
        let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
        Some(std::array::from_fn(|i| {
            (a[i] * (1.0 - fx) + b[i] * fx) * (1.0 - fy) + (c[i] * (1.0 - fx) + d[i] * fx) * fy
        }))
    }
}
