//! [`Image`]: a measured picture, intensity and valid mask, read from PNG or JPEG.

use std::path::Path;

use ::image::{DynamicImage, ImageFormat, ImageReader};

use crate::{AnyImage, FrameError};

/// A measured picture of a camera: intensity in `[0, 1]` and which pixels hold one
/// (inside the camera's valid region), row-major. Its ranges are unknown: the features
/// treat its pixels as seeing points at infinity (`1/ρ = 0`), which matters only for an
/// interaction matrix computed on it.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: u32,
    height: u32,
    /// Intensity of every pixel (0 where not valid).
    pub intensity: Vec<f32>,
    /// Whether the pixel holds a measurement.
    pub valid: Vec<bool>,
}

impl Image {
    /// A picture of the given size, every pixel invalid and dark.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            intensity: vec![0.0; n],
            valid: vec![false; n],
        }
    }

    /// A picture from its buffers (one value per pixel each, [`FrameError::Length`]
    /// otherwise); intensities of invalid pixels are set to 0.
    pub fn from_parts(
        width: u32,
        height: u32,
        mut intensity: Vec<f32>,
        valid: Vec<bool>,
    ) -> Result<Self, FrameError> {
        let n = width as usize * height as usize;
        for (what, got) in [("intensity", intensity.len()), ("valid mask", valid.len())] {
            if got != n {
                return Err(FrameError::Length {
                    what,
                    got,
                    expected: n,
                });
            }
        }
        for (v, &ok) in intensity.iter_mut().zip(&valid) {
            if !ok {
                *v = 0.0;
            }
        }
        Ok(Self {
            width,
            height,
            intensity,
            valid,
        })
    }

    /// The intensities of `frame` where it is observed (hits and sky), as a measured
    /// picture: what an acquisition simulator starts from.
    pub fn from_frame(frame: &crate::Frame) -> Self {
        let valid: Vec<bool> = (0..frame.intensity.len())
            .map(|k| frame.is_observed(k))
            .collect();
        Self::from_parts(
            frame.width(),
            frame.height(),
            frame.intensity.clone(),
            valid,
        )
        .expect("a frame's buffers have one value per pixel")
    }

    /// Read a picture file (PNG or JPEG, grey or colour, 8 or 16 bits per channel) taken
    /// by `camera`: colours become Rec. 709 luminance, values are scaled to `[0, 1]`,
    /// and the pixels outside the camera's valid region are invalid. `crop`
    /// (`[x, y, width, height]`, pixels) selects the calibrated part of a larger
    /// picture; without it the picture must have the camera's size. The picture's size
    /// is checked against [`ucm::MAX_PIXELS`] before it is decoded.
    pub fn load(
        path: impl AsRef<Path>,
        camera: &ucm::Camera,
        crop: Option<[u32; 4]>,
    ) -> Result<Self, FrameError> {
        let path = path.as_ref();
        let error = |source| FrameError::Image {
            path: path.to_owned(),
            source,
        };
        let io = |e| error(::image::ImageError::IoError(e));
        let (picture_width, picture_height) = Self::dimensions(path)?;
        let pixels = u64::from(picture_width) * u64::from(picture_height);
        if pixels > ucm::MAX_PIXELS {
            return Err(FrameError::TooManyPixels {
                path: path.to_owned(),
                pixels,
                limit: ucm::MAX_PIXELS,
            });
        }
        let [x, y, width, height] = crop.unwrap_or([0, 0, picture_width, picture_height]);
        if u64::from(x) + u64::from(width) > u64::from(picture_width)
            || u64::from(y) + u64::from(height) > u64::from(picture_height)
        {
            return Err(FrameError::Crop {
                path: path.to_owned(),
                x,
                y,
                width,
                height,
                picture_width,
                picture_height,
            });
        }
        if (width, height) != (camera.width(), camera.height()) {
            return Err(FrameError::Size {
                what: "picture (cropped)",
                got_width: width,
                got_height: height,
                width: camera.width(),
                height: camera.height(),
            });
        }
        let reader = ImageReader::open(path)
            .map_err(io)?
            .with_guessed_format()
            .map_err(io)?;
        if reader.format() == Some(ImageFormat::Jpeg) && !jpeg_is_complete(path).map_err(io)? {
            return Err(FrameError::TruncatedJpeg {
                path: path.to_owned(),
            });
        }
        let decoded = reader
            .decode()
            .map_err(error)?
            .crop_imm(x, y, width, height);
        let intensity = luminance(decoded);
        Self::from_parts(width, height, intensity, camera.valid_pixels().to_vec())
    }

    /// The width and height of a picture file, read from its header alone.
    pub fn dimensions(path: impl AsRef<Path>) -> Result<(u32, u32), FrameError> {
        let path = path.as_ref();
        let error = |source| FrameError::Image {
            path: path.to_owned(),
            source,
        };
        let io = |e| error(::image::ImageError::IoError(e));
        ImageReader::open(path)
            .map_err(io)?
            .with_guessed_format()
            .map_err(io)?
            .into_dimensions()
            .map_err(error)
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of valid pixels.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }

    /// The picture at `1/factor` of its resolution (the size of
    /// [`ucm::Camera::downsampled`]): each `factor × factor` block becomes one pixel
    /// whose intensity is the mean over the block's valid pixels; the pixel is valid
    /// when `camera_coarse` says so and the block holds a valid pixel.
    pub fn downsampled(
        &self,
        factor: u32,
        camera_coarse: &ucm::Camera,
    ) -> Result<Self, FrameError> {
        let (width, height) = crate::downsampled_size(self, factor, camera_coarse)?;
        let mut out = Image::new(width, height);
        let (w, k) = (self.width as usize, factor as usize);
        let region = camera_coarse.valid_pixels();
        for y in 0..height as usize {
            for x in 0..width as usize {
                let index = y * width as usize + x;
                let (mut count, mut sum) = (0usize, 0.0f32);
                for dy in 0..k {
                    let row = (y * k + dy) * w + x * k;
                    for i in row..row + k {
                        if self.valid[i] {
                            count += 1;
                            sum += self.intensity[i];
                        }
                    }
                }
                if region[index] && count > 0 {
                    out.valid[index] = true;
                    out.intensity[index] = sum / count as f32;
                }
            }
        }
        Ok(out)
    }

    /// Save the intensity as an 8-bit grey PNG; invalid pixels are drawn black.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), FrameError> {
        let path = path.as_ref();
        let picture = ::image::GrayImage::from_fn(self.width, self.height, |i, j| {
            let k = (j * self.width + i) as usize;
            let v = if self.valid[k] {
                self.intensity[k]
            } else {
                0.0
            };
            ::image::Luma([(v.clamp(0.0, 1.0) * 255.0).round() as u8])
        });
        picture.save(path).map_err(|source| FrameError::Image {
            path: path.to_owned(),
            source,
        })
    }

    /// Save the intensity as a 16-bit grey PNG (invalid pixels black), keeping the
    /// precision an 8-bit file would round away.
    pub fn save_png16(&self, path: impl AsRef<Path>) -> Result<(), FrameError> {
        let path = path.as_ref();
        let picture = ::image::ImageBuffer::<::image::Luma<u16>, Vec<u16>>::from_fn(
            self.width,
            self.height,
            |i, j| {
                let k = (j * self.width + i) as usize;
                let v = if self.valid[k] {
                    self.intensity[k]
                } else {
                    0.0
                };
                ::image::Luma([(v.clamp(0.0, 1.0) * 65535.0).round() as u16])
            },
        );
        picture.save(path).map_err(|source| FrameError::Image {
            path: path.to_owned(),
            source,
        })
    }
}

/// Rec. 709 luminance in `[0, 1]` of a decoded picture, at its own bit depth.
fn luminance(picture: DynamicImage) -> Vec<f32> {
    use ::image::DynamicImage as D;
    match picture {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => picture
            .into_luma8()
            .into_raw()
            .into_iter()
            .map(|v| f32::from(v) / 255.0)
            .collect(),
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => picture
            .into_luma16()
            .into_raw()
            .into_iter()
            .map(|v| f32::from(v) / 65535.0)
            .collect(),
        other => other
            .into_rgb32f()
            .pixels()
            .map(|p| (0.2126 * p.0[0] + 0.7152 * p.0[1] + 0.0722 * p.0[2]).clamp(0.0, 1.0))
            .collect(),
    }
}

impl AnyImage for Image {
    fn width(&self) -> u32 {
        self.width
    }

    fn check_buffers(&self) -> Result<(), FrameError> {
        crate::check_length("intensity", self.intensity.len(), self)?;
        crate::check_length("valid", self.valid.len(), self)
    }

    fn height(&self) -> u32 {
        self.height
    }

    fn intensity(&self) -> &[f32] {
        &self.intensity
    }

    #[inline]
    fn is_observed(&self, index: usize) -> bool {
        self.valid[index]
    }

    #[inline]
    fn observed(&self, pixels: std::ops::Range<usize>, out: &mut [bool]) {
        out.copy_from_slice(&self.valid[pixels]);
    }

    #[inline]
    fn observed_intensity(&self, pixels: std::ops::Range<usize>, out: &mut [f32]) {
        assert_eq!(out.len(), pixels.len(), "one value per pixel");
        let valid = &self.valid[pixels.clone()];
        for ((o, &i), &v) in out.iter_mut().zip(&self.intensity[pixels]).zip(valid) {
            *o = if v { i } else { 0.0 };
        }
    }

    fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError> {
        if out.len() != self.intensity.len() {
            return Err(FrameError::Length {
                what: "inverse range buffer",
                got: out.len(),
                expected: self.intensity.len(),
            });
        }
        out.fill(0.0);
        Ok(())
    }

    fn downsampled(&self, factor: u32, camera_coarse: &ucm::Camera) -> Result<Self, FrameError> {
        Image::downsampled(self, factor, camera_coarse)
    }
}

/// Whether the JPEG file at `path` holds an end-of-image marker after its last scan's
/// start (`FF D9` after the last `FF DA`): a truncated file does not, and the decoder
/// fills what it lacks with grey. Inside a scan a data byte `FF` is followed by `00`
/// (or a restart marker), so the markers are found by reading the bytes in one pass,
/// in constant memory.
fn jpeg_is_complete(path: &Path) -> std::io::Result<bool> {
    use std::io::Read;
    let mut reader = std::io::BufReader::new(std::fs::File::open(path)?);
    let (mut scan_seen, mut ended_after_scan, mut previous_ff) = (false, false, false);
    let mut buffer = [0u8; 64 * 1024];
    loop {
        let read = reader.read(&mut buffer)?;
        if read == 0 {
            return Ok(scan_seen && ended_after_scan);
        }
        for &byte in &buffer[..read] {
            if previous_ff {
                match byte {
                    0xDA => {
                        scan_seen = true;
                        ended_after_scan = false;
                    }
                    0xD9 => ended_after_scan = true,
                    _ => {}
                }
            }
            previous_ff = byte == 0xFF;
        }
    }
}
