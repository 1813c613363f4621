#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod e57;
mod error;
mod las;
mod ply;
mod points;

use std::io::Read;
use std::path::Path;

use splat::PointCloud;

pub use crate::e57::E57Info;
pub use error::CloudIoError;
pub use las::{LasGrid, LasInfo};
pub use ply::{PlyEncoding, PlyInfo};
pub use points::{CONSTANT_INTENSITY, ColorScale, Colors, IntensitySource, Points};

/// A point cloud file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloudFormat {
    /// ASPRS LAS.
    Las,
    /// LAS compressed by LASzip.
    Laz,
    /// Stanford PLY.
    Ply,
    /// ASTM E57.
    E57,
}

impl CloudFormat {
    /// Every format, in the order of their names in messages.
    pub const ALL: [Self; 4] = [Self::Las, Self::Laz, Self::Ply, Self::E57];

    /// The file name extension of the format, lower case.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Las => "las",
            Self::Laz => "laz",
            Self::Ply => "ply",
            Self::E57 => "e57",
        }
    }

    /// The format a file's content is in, from its first bytes (its signature), not its
    /// name: `LASF` (LAZ when the point format's compression bit is set), `ply`, or
    /// `ASTM-E57`.
    pub fn of_file(path: &Path) -> Result<Self, CloudIoError> {
        let io_error = |source| CloudIoError::Io {
            path: path.to_owned(),
            source,
        };
        let mut head = Vec::with_capacity(105);
        std::fs::File::open(path)
            .map_err(io_error)?
            .take(105)
            .read_to_end(&mut head)
            .map_err(io_error)?;
        if head.starts_with(b"LASF") {
            // The point data record format (byte 104) has its top bit set in LAZ.
            return Ok(match head.get(104) {
                Some(f) if f & 0x80 != 0 => Self::Laz,
                _ => Self::Las,
            });
        }
        if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
            return Ok(Self::Ply);
        }
        if head.starts_with(b"ASTM-E57") {
            return Ok(Self::E57);
        }
        Err(CloudIoError::UnknownFormat {
            path: path.to_owned(),
            signature: String::from_utf8_lossy(&head[..head.len().min(8)]).into_owned(),
        })
    }

    /// The format an output file's name asks for (`.las`, `.laz`, `.ply`, `.e57`, any
    /// case); also checks that its folder exists. Call it before long work.
    pub fn of_output(path: &Path) -> Result<Self, CloudIoError> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let format = Self::ALL
            .into_iter()
            .find(|f| extension.as_deref() == Some(f.extension()))
            .ok_or_else(|| CloudIoError::Parameter {
                name: "path",
                message: format!(
                    "{} must end in .las, .laz, .ply or .e57 (the format to write)",
                    path.display()
                ),
            })?;
        if let Some(folder) = path.parent().filter(|p| !p.as_os_str().is_empty())
            && !folder.is_dir()
        {
            return Err(CloudIoError::Parameter {
                name: "path",
                message: format!(
                    "{}: the folder {} does not exist",
                    path.display(),
                    folder.display()
                ),
            });
        }
        Ok(format)
    }
}

impl std::fmt::Display for CloudFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Las => "LAS",
            Self::Laz => "LAZ",
            Self::Ply => "PLY",
            Self::E57 => "E57",
        })
    }
}

/// What a file held, by format.
#[derive(Clone, Debug, PartialEq)]
pub enum FileInfo {
    /// A LAS or LAZ file.
    Las(LasInfo),
    /// A PLY file.
    Ply(PlyInfo),
    /// An E57 file.
    E57(E57Info),
}

/// What was read from a cloud file.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudInfo {
    /// Its format, from its content.
    pub format: CloudFormat,
    /// Points read.
    pub points: u64,
    /// What the format's header said.
    pub file: FileInfo,
}

/// Read a cloud file's points as it holds them, whatever its format (chosen by
/// content: [`CloudFormat::of_file`]).
pub fn read_points(path: impl AsRef<Path>) -> Result<(Points, CloudInfo), CloudIoError> {
    let path = path.as_ref();
    let format = CloudFormat::of_file(path)?;
    // The decoders of `laz` and `e57` may panic on corrupt input rather than report
    // it; a panic inside one is reported as a corrupt file (nothing it decoded
    // survives). A binary built with `panic = "abort"` loses this net.
    let read = catch_decoder_panic(|| match format {
        CloudFormat::Las | CloudFormat::Laz => las::read(path).map(|(p, i)| (p, FileInfo::Las(i))),
        CloudFormat::Ply => ply::read(path).map(|(p, i)| (p, FileInfo::Ply(i))),
        CloudFormat::E57 => e57::read(path).map(|(p, i)| (p, FileInfo::E57(i))),
    });
    let (points, file) = read.map_err(|message| corrupt(path, format, &message))??;
    points.validate()?;
    let info = CloudInfo {
        format,
        points: points.len() as u64,
        file,
    };
    Ok((points, info))
}

/// Read a cloud file, whatever its format, into the renderer's cloud
/// ([`Points::to_cloud`]: colours brought to 8 bits, intensities normalised, point
/// spacing estimated from the data).
pub fn read_cloud(
    path: impl AsRef<Path>,
) -> Result<(PointCloud, CloudInfo, IntensitySource), CloudIoError> {
    let path = path.as_ref();
    let (points, info) = read_points(path)?;
    let (cloud, source) = points.to_cloud(path)?;
    Ok((cloud, info, source))
}

/// Write points in the format the path's extension names ([`CloudFormat::of_output`]):
/// PLY and E57 keep the `f64` coordinates, colours at their depth and intensities as
/// they are; LAS and LAZ store the coordinates on [`LasGrid::fitting`] (0.1 mm) and
/// colours as 16 bits. Use [`write_points_on_grid`] to choose the LAS grid.
pub fn write_points(points: &Points, path: impl AsRef<Path>) -> Result<(), CloudIoError> {
    write_points_on_grid(points, path, None)
}

/// As [`write_points`], with the grid of LAS/LAZ coordinates (ignored for the other
/// formats; `None`: [`LasGrid::fitting`]).
pub fn write_points_on_grid(
    points: &Points,
    path: impl AsRef<Path>,
    las_grid: Option<LasGrid>,
) -> Result<(), CloudIoError> {
    let path = path.as_ref();
    let format = CloudFormat::of_output(path)?;
    points.validate()?;
    match format {
        CloudFormat::Las | CloudFormat::Laz => {
            let grid = las_grid.unwrap_or_else(|| LasGrid::fitting(&points.positions_m));
            las::write(points, path, grid)
        }
        CloudFormat::Ply => ply::write(points, path),
        CloudFormat::E57 => e57::write(points, path),
    }
}

/// Write a renderer's cloud in the format its path's extension names: its points in
/// world coordinates, 8-bit colours (grey levels of the intensity without colour, so
/// that it renders the same when read back), its intensities; LAS/LAZ on a millimetre
/// grid from the cloud's origin.
pub fn write_cloud(cloud: &PointCloud, path: impl AsRef<Path>) -> Result<(), CloudIoError> {
    let path = path.as_ref();
    CloudFormat::of_output(path)?;
    let grid = LasGrid {
        scale_m: glam::DVec3::splat(1e-3),
        offset_m: cloud.origin(),
    };
    write_points_on_grid(&Points::from_cloud(cloud), path, Some(grid))
}

/// Convert a cloud file into another format (by the output's extension), keeping its
/// `f64` coordinates and its colours (8- or 16-bit) exactly; a LAS or LAZ source keeps
/// its grid when written as LAS or LAZ. Intensities go along as each format stores
/// them (E57's normalised to `[0, 1]`, LAS's rounded to 16 bits). Returns what was
/// read.
pub fn convert(
    input: impl AsRef<Path>,
    output: impl AsRef<Path>,
) -> Result<CloudInfo, CloudIoError> {
    let output = output.as_ref();
    CloudFormat::of_output(output)?;
    let (points, info) = read_points(input)?;
    let grid = match &info.file {
        FileInfo::Las(las) => Some(las.grid),
        _ => None,
    };
    write_points_on_grid(&points, output, grid)?;
    Ok(info)
}

/// Run a third-party decoder, turning a panic into its message.
pub(crate) fn catch_decoder_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".to_owned())
    })
}

fn corrupt(path: &Path, format: CloudFormat, message: &str) -> CloudIoError {
    let message = format!("the decoder failed on corrupt data ({message})");
    match format {
        CloudFormat::Las | CloudFormat::Laz => CloudIoError::Las {
            path: path.to_owned(),
            source: Box::new(::las::Error::Io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                message,
            ))),
        },
        CloudFormat::Ply => CloudIoError::Ply {
            path: path.to_owned(),
            message,
        },
        CloudFormat::E57 => CloudIoError::E57 {
            path: path.to_owned(),
            source: Box::new(::e57::Error::Invalid {
                desc: message,
                source: None,
            }),
        },
    }
}

/// Intensities as LAS's 16-bit integers: kept (rounded) when every one is within
/// `[0, 65535]` and one exceeds 1, otherwise scaled so that the largest is 65535.
pub(crate) fn intensity_to_u16(intensities: Option<&[f32]>) -> Option<Vec<u16>> {
    let values = intensities?;
    let clean = |v: f32| if v > 0.0 && v.is_finite() { v } else { 0.0 };
    let max = values.iter().copied().map(clean).fold(0.0f32, f32::max);
    let keep = max > 1.0 && max <= 65_535.0;
    Some(
        values
            .iter()
            .map(|&v| match (keep, max > 0.0) {
                (true, _) => clean(v).round() as u16,
                (false, true) => (f64::from(clean(v)) / f64::from(max) * 65_535.0).round() as u16,
                (false, false) => 0,
            })
            .collect(),
    )
}
