//! [`Points`]: a file's points as the file holds them (double coordinates, 8- or 16-bit
//! colour, raw intensity), between a file and a renderer's [`PointCloud`].

use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use splat::PointCloud;

use crate::CloudIoError;

/// Intensity of every point of a cloud that has neither colour nor intensity.
pub const CONSTANT_INTENSITY: f32 = 0.5;

/// The depth of a file's colour channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorScale {
    /// 8-bit values (`0..=255`), whatever the width of the fields that hold them.
    EightBit,
    /// The full 16-bit range (`0..=65535`).
    SixteenBit,
}

impl ColorScale {
    /// The largest value of a channel.
    pub fn max_value(self) -> u16 {
        match self {
            Self::EightBit => 255,
            Self::SixteenBit => 65_535,
        }
    }

    /// A channel value as the renderer's 8 bits (16-bit values rounded: `v / 257`).
    pub fn to_u8(self, value: u16) -> u8 {
        match self {
            Self::EightBit => value.min(255) as u8,
            Self::SixteenBit => ((u32::from(value) + 128) / 257) as u8,
        }
    }
}

/// Per-point colours and their depth.
#[derive(Clone, Debug, PartialEq)]
pub struct Colors {
    /// Red, green, blue of each point, in `0..=scale.max_value()`.
    pub values: Vec<[u16; 3]>,
    /// Their depth.
    pub scale: ColorScale,
}

/// Where the intensities of a cloud made from [`Points`] come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntensitySource {
    /// Luminance of the colours, interpreted with this scale.
    Color(ColorScale),
    /// The file's intensity attribute, normalised by its maximum.
    IntensityAttribute,
    /// [`CONSTANT_INTENSITY`] (neither colour nor a non-zero intensity).
    Constant,
}

/// Points as a file holds them: `f64` coordinates in the file's frame, colours at their
/// depth, intensities as stored (non-negative; a reader that knows the sensor's range
/// gives them in `[0, 1]`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Points {
    /// Coordinates, metres.
    pub positions_m: Vec<DVec3>,
    /// Colours, one per point.
    pub colors: Option<Colors>,
    /// Intensities, one per point.
    pub intensities: Option<Vec<f32>>,
}

impl Points {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions_m.len()
    }

    /// Whether there is no point.
    pub fn is_empty(&self) -> bool {
        self.positions_m.is_empty()
    }

    /// Check that every attribute holds one value per point.
    pub fn validate(&self) -> Result<(), CloudIoError> {
        let n = self.positions_m.len();
        let mismatch = |what: &str, got: usize| CloudIoError::Parameter {
            name: "points",
            message: format!("{got} {what} for {n} positions"),
        };
        if let Some(c) = &self.colors
            && c.values.len() != n
        {
            return Err(mismatch("colours", c.values.len()));
        }
        if let Some(i) = &self.intensities
            && i.len() != n
        {
            return Err(mismatch("intensities", i.len()));
        }
        Ok(())
    }

    /// The renderer's cloud of these points (point spacing estimated from the data).
    ///
    /// * With colours, a point's intensity is the luminance of its colour brought to
    ///   8 bits ([`ColorScale::to_u8`]).
    /// * Without, its intensity attribute divided by the largest (a NaN or negative
    ///   intensity counts as 0); if every intensity is zero or there is none, every
    ///   point gets [`CONSTANT_INTENSITY`].
    /// * The cloud's origin is the points' minimum corner rounded down to the metre, so
    ///   that georeferenced coordinates keep their precision.
    ///
    /// `path` names the file in errors.
    pub fn to_cloud(&self, path: &Path) -> Result<(PointCloud, IntensitySource), CloudIoError> {
        self.validate()?;
        if self.positions_m.is_empty() {
            return Err(CloudIoError::NoPoint {
                path: path.to_owned(),
            });
        }
        let origin = self
            .positions_m
            .par_iter()
            .copied()
            .reduce(|| DVec3::splat(f64::INFINITY), DVec3::min)
            .floor();
        let origin = if origin.is_finite() {
            origin
        } else {
            DVec3::ZERO // a non-finite coordinate: `PointCloud` names it
        };
        let (intensities, colors, source) = match (&self.colors, &self.intensities) {
            (Some(colors), _) => {
                let rgb: Vec<[u8; 3]> = colors
                    .values
                    .par_iter()
                    .map(|c| c.map(|v| colors.scale.to_u8(v)))
                    .collect();
                let intensities = rgb.par_iter().map(|&c| splat::luminance(c)).collect();
                (intensities, Some(rgb), IntensitySource::Color(colors.scale))
            }
            (None, Some(raw)) => {
                let clean = |v: f32| if v > 0.0 && v.is_finite() { v } else { 0.0 };
                let max = raw.iter().copied().map(clean).fold(0.0f32, f32::max);
                if max > 0.0 {
                    let intensities = raw.iter().map(|&v| clean(v) / max).collect();
                    (intensities, None, IntensitySource::IntensityAttribute)
                } else {
                    (
                        vec![CONSTANT_INTENSITY; raw.len()],
                        None,
                        IntensitySource::Constant,
                    )
                }
            }
            (None, None) => (
                vec![CONSTANT_INTENSITY; self.positions_m.len()],
                None,
                IntensitySource::Constant,
            ),
        };
        let cloud = PointCloud::from_points(origin, &self.positions_m, &intensities, colors, None)
            .map_err(|source| CloudIoError::Cloud {
                path: path.to_owned(),
                source,
            })?;
        Ok((cloud, source))
    }

    /// The points of a renderer's cloud, in its order: world coordinates, 8-bit colours
    /// (or, without colour, grey levels of its intensity, so that the cloud renders the
    /// same when read back) and its intensities.
    pub fn from_cloud(cloud: &PointCloud) -> Self {
        let mut positions_m = Vec::with_capacity(cloud.len());
        let mut values = Vec::with_capacity(cloud.len());
        let mut intensities = Vec::with_capacity(cloud.len());
        for (i, (p, intensity)) in cloud.decoded().enumerate() {
            positions_m.push(cloud.origin() + p);
            let rgb = match cloud.colors() {
                Some(c) => c[i],
                None => [(intensity * 255.0).round() as u8; 3],
            };
            values.push(rgb.map(u16::from));
            intensities.push(intensity);
        }
        Self {
            positions_m,
            colors: Some(Colors {
                values,
                scale: ColorScale::EightBit,
            }),
            intensities: Some(intensities),
        }
    }
}
