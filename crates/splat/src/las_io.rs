//! Reading and writing LAS/LAZ files (every point format, with or without colour).
//!
//! * **Colour scaling is detected**: LAS stores 16-bit colour channels, but many files
//!   put 8-bit values in them. If no channel of any point exceeds 255 the values are
//!   taken as 8-bit; otherwise as 16-bit and scaled down (`v / 257`).
//! * **Without colour**, a point's intensity is its LAS `intensity` attribute divided
//!   by the largest intensity of the file; if every intensity is zero, every point gets
//!   the constant [`CONSTANT_INTENSITY`].
//! * The cloud's origin is the points' minimum corner (not the header's bounds, which
//!   may lie), rounded down to the metre, so that `f32` positions keep millimetre
//!   precision on georeferenced data.
//! * Writing uses LAS 1.2 point format 2 (position and colour, 16-bit full range,
//!   millimetre resolution); a `.laz` extension compresses. A cloud without colour
//!   is written in grey levels of its intensity, so that it renders the same when
//!   read back.

use std::path::Path;

use glam::DVec3;

use crate::{PointCloud, SplatError};

/// Points read from a LAS/LAZ file at a time.
const LAS_CHUNK_POINTS: u64 = 50_000;

/// Intensity of every point of a cloud that has neither colour nor intensity.
pub const CONSTANT_INTENSITY: f32 = 0.5;

/// How a file's colours were interpreted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorScale {
    /// 8-bit values stored in the 16-bit fields.
    EightBit,
    /// Full 16-bit range.
    SixteenBit,
}

/// Where the intensities of a loaded cloud come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntensitySource {
    /// Luminance of the colours, interpreted with this scale.
    Color(ColorScale),
    /// The LAS intensity attribute, normalised by its maximum.
    IntensityAttribute,
    /// [`CONSTANT_INTENSITY`].
    Constant,
}

/// What was found in a LAS/LAZ file.
#[derive(Clone, Debug, PartialEq)]
pub struct LasInfo {
    /// Number of points in the header.
    pub header_point_count: u64,
    /// LAS point format number.
    pub point_format: u8,
    /// LAS version `(major, minor)`.
    pub version: (u8, u8),
    /// Header bounds `(min, max)`.
    pub bounds: (DVec3, DVec3),
    /// Largest colour channel value over all points, if the format has colour.
    pub max_color_value: Option<u16>,
    /// How intensities were made.
    pub intensity_source: IntensitySource,
}

fn las_error(path: &Path) -> impl Fn(las::Error) -> SplatError + '_ {
    move |source| SplatError::Las {
        path: path.to_owned(),
        source: Box::new(source),
    }
}

/// Refuse a LAZ file whose `laszip` record describes no point item (the `laz` crate
/// panics on one rather than report it): a corrupt file.
fn check_laz_items(path: &Path, raw: &las::raw::Header) -> Result<(), SplatError> {
    use std::io::{Seek, SeekFrom};
    let io_error = |source| SplatError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = std::io::BufReader::new(std::fs::File::open(path).map_err(io_error)?);
    file.seek(SeekFrom::Start(u64::from(raw.header_size)))
        .map_err(io_error)?;
    for _ in 0..raw.number_of_variable_length_records {
        let Ok(vlr) = las::raw::Vlr::read_from(&mut file, false) else {
            return Ok(()); // a truncated record list: `las` reports it
        };
        let user_id = String::from_utf8_lossy(&vlr.user_id);
        if vlr.record_id == 22204 && user_id.trim_end_matches('\0') == "laszip encoded" {
            let items = laz::LazVlr::read_from(vlr.data.as_slice()).map(|v| v.items().len());
            if let Ok(0) | Err(_) = items {
                return Err(SplatError::Las {
                    path: path.to_owned(),
                    source: Box::new(las::Error::Io(std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        "its laszip record describes no point item (corrupt LAZ)",
                    ))),
                });
            }
            return Ok(());
        }
    }
    Ok(())
}

/// Refuse a LAZ file whose chunk table announces more chunks than the file has bytes
/// (the `laz` crate would allocate the table from that count: 25 GB for a corrupt
/// 10 KB file, found by our fuzzing). Mirrors `laz`'s own reading of the table's
/// offset: at the start of the point data, or in the file's last 8 bytes.
fn check_laz_chunk_table(path: &Path, data_start: u64, file_bytes: u64) -> Result<(), SplatError> {
    use std::io::{Read, Seek, SeekFrom};
    let io_error = |source| SplatError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(io_error)?;
    let read_i64 = |file: &mut std::fs::File, at: SeekFrom| -> std::io::Result<i64> {
        file.seek(at)?;
        let mut bytes = [0u8; 8];
        file.read_exact(&mut bytes)?;
        Ok(i64::from_le_bytes(bytes))
    };
    let Ok(mut table) = read_i64(&mut file, SeekFrom::Start(data_start)) else {
        return Ok(()); // too short: `laz` reports it
    };
    if table <= data_start as i64 {
        match read_i64(&mut file, SeekFrom::End(-8)) {
            Ok(t) if t > data_start as i64 => table = t,
            _ => return Ok(()), // no chunk table: `laz` reports it
        }
    }
    let mut head = [0u8; 8];
    if file.seek(SeekFrom::Start(table as u64)).is_err() || file.read_exact(&mut head).is_err() {
        return Ok(()); // beyond the file: `laz` reports it
    }
    let chunks = u64::from(u32::from_le_bytes([head[4], head[5], head[6], head[7]]));
    if chunks > file_bytes {
        return Err(SplatError::Truncated {
            path: path.to_owned(),
            announced: None,
            found: format!("a chunk table of {chunks} chunks in {file_bytes} bytes (corrupt)"),
        });
    }
    Ok(())
}

/// Whether a read failed because the point data ended (a truncated LAS, or a LAZ
/// whose compressed chunks stop), rather than on corrupt data.
fn ends_early(error: &las::Error) -> bool {
    let eof = |e: &std::io::Error| e.kind() == std::io::ErrorKind::UnexpectedEof;
    match error {
        las::Error::Io(e) => eof(e),
        las::Error::LasZipError(laz::LasZipError::IoError(e)) => eof(e),
        _ => false,
    }
}

/// What [`decode_points`] read from a file, before it becomes a cloud.
struct Decoded {
    header: las::Header,
    point_format: u8,
    version: (u8, u8),
    bounds: (DVec3, DVec3),
    has_rgb: bool,
    positions: Vec<DVec3>,
    raw_rgb: Vec<[u16; 3]>,
    raw_intensity: Vec<u16>,
}

/// Decode a checked file's points by chunks (memory follows what the file holds).
fn decode_points(
    path: &Path,
    raw: &las::raw::Header,
    file_bytes: u64,
) -> Result<Decoded, SplatError> {
    let mut reader = las::Reader::from_path(path).map_err(|e| {
        if ends_early(&e) {
            SplatError::Truncated {
                path: path.to_owned(),
                announced: None,
                found: "too few bytes for its header, its point data or its chunk table".into(),
            }
        } else {
            las_error(path)(e)
        }
    })?;
    let header = reader.header().clone();
    let format = header.point_format();
    let point_format = format.to_u8().map_err(las_error(path))?;
    let version = (header.version().major, header.version().minor);
    let b = header.bounds();
    let bounds = (
        DVec3::new(b.min.x, b.min.y, b.min.z),
        DVec3::new(b.max.x, b.max.y, b.max.z),
    );
    let announced = header.number_of_points();
    // An uncompressed file cannot hold more points than its bytes after the header;
    // checked before anything is allocated. A LAZ file is read by chunks, so memory
    // follows what it really holds, never its header.
    if !format.is_compressed {
        let record_bytes = u64::from(raw.point_data_record_length).max(1);
        let room = file_bytes.saturating_sub(u64::from(raw.offset_to_point_data));
        if announced > room / record_bytes {
            return Err(SplatError::Truncated {
                path: path.to_owned(),
                announced: Some(announced),
                found: format!(
                    "{} points (its {room} bytes of points)",
                    room / record_bytes
                ),
            });
        }
    }
    let mut positions: Vec<DVec3> = Vec::new();
    let mut raw_rgb: Vec<[u16; 3]> = Vec::new();
    let mut raw_intensity: Vec<u16> = Vec::new();
    let has_rgb = format.has_color;
    let mut chunk = las::PointDataBuilder::new().for_header(&header).build();
    let mut read = 0u64;
    while read < announced {
        let want = (announced - read).min(LAS_CHUNK_POINTS);
        let got = match reader.fill_points(want, &mut chunk) {
            Ok(n) => n,
            Err(e) if ends_early(&e) => 0,
            Err(e) => return Err(las_error(path)(e)),
        };
        if got == 0 {
            break;
        }
        positions.extend(
            chunk
                .x()
                .zip(chunk.y())
                .zip(chunk.z())
                .map(|((x, y), z)| DVec3::new(x, y, z)),
        );
        match chunk.rgb() {
            Some(rgb) if has_rgb => raw_rgb.extend(rgb.map(|(r, g, b)| [r, g, b])),
            _ => raw_intensity.extend(chunk.intensity()),
        }
        read += got;
    }
    if read < announced {
        return Err(SplatError::Truncated {
            path: path.to_owned(),
            announced: Some(announced),
            found: format!(
                "{read} points before its data ends (read by chunks of {LAS_CHUNK_POINTS}: up to \
                 {} more in the last one)",
                LAS_CHUNK_POINTS - 1
            ),
        });
    }
    Ok(Decoded {
        header,
        point_format,
        version,
        bounds,
        has_rgb,
        positions,
        raw_rgb,
        raw_intensity,
    })
}

/// Read a LAS or LAZ file into a cloud (point spacing estimated from the data).
pub fn read_las(path: impl AsRef<Path>) -> Result<(PointCloud, LasInfo), SplatError> {
    let path = path.as_ref();
    if !path.exists() {
        return Err(SplatError::Io {
            path: path.to_owned(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        });
    }
    let io_error = |source| SplatError::Io {
        path: path.to_owned(),
        source,
    };
    let file_bytes = std::fs::metadata(path).map_err(io_error)?.len();
    let raw = std::fs::File::open(path)
        .map_err(io_error)
        .and_then(|file| {
            las::raw::Header::read_from(std::io::BufReader::new(file)).map_err(las_error(path))
        })?;
    let scales = [raw.x_scale_factor, raw.y_scale_factor, raw.z_scale_factor];
    let offsets = [raw.x_offset, raw.y_offset, raw.z_offset];
    if !scales.iter().all(|s| s.is_finite() && *s != 0.0) || !offsets.iter().all(|o| o.is_finite())
    {
        return Err(SplatError::Las {
            path: path.to_owned(),
            source: Box::new(las::Error::Io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "the header's scale factors {scales:?} must be finite and non-zero, its \
                     offsets {offsets:?} finite"
                ),
            ))),
        });
    }
    if raw.point_data_record_format & 0x80 != 0 {
        check_laz_items(path, &raw)?;
        check_laz_chunk_table(path, u64::from(raw.offset_to_point_data), file_bytes)?;
    }
    // The `laz` decoder asserts (panics) on some corrupt inputs instead of reporting
    // them (an empty item list, an arithmetic-coder symbol out of range: found by our
    // fuzzing); the checks above catch the known ones with a clear message, and any
    // other panic inside the decoder is caught here and reported as a corrupt file.
    // Nothing decoded survives a caught panic. (A binary built with
    // `panic = "abort"` loses this net.)
    let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        decode_points(path, &raw, file_bytes)
    }))
    .map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".to_owned());
        SplatError::Las {
            path: path.to_owned(),
            source: Box::new(las::Error::Io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("the point decoder failed on corrupt data ({message})"),
            ))),
        }
    })??;
    if decoded.positions.is_empty() {
        return Err(SplatError::EmptyCloud);
    }
    // The origin comes from the data (the header's bounds may lie): the minimum
    // corner, rounded down to the metre.
    let origin = decoded
        .positions
        .iter()
        .fold(DVec3::splat(f64::INFINITY), |m, p| m.min(*p))
        .floor();

    let (intensities, colors, max_color_value, intensity_source) = match decoded.has_rgb {
        true => {
            let raw = decoded.raw_rgb;
            let max = raw.iter().flatten().copied().max().unwrap_or(0);
            let scale = if max <= 255 {
                ColorScale::EightBit
            } else {
                ColorScale::SixteenBit
            };
            let colors: Vec<[u8; 3]> = raw
                .iter()
                .map(|c| {
                    c.map(|v| match scale {
                        ColorScale::EightBit => v as u8,
                        ColorScale::SixteenBit => ((u32::from(v) + 128) / 257) as u8,
                    })
                })
                .collect();
            let intensities = colors.iter().map(|&c| crate::luminance(c)).collect();
            (
                intensities,
                Some(colors),
                Some(max),
                IntensitySource::Color(scale),
            )
        }
        false => {
            let raw = decoded.raw_intensity;
            let max = raw.iter().copied().max().unwrap_or(0);
            if max == 0 {
                (
                    vec![CONSTANT_INTENSITY; raw.len()],
                    None,
                    None,
                    IntensitySource::Constant,
                )
            } else {
                let inv = 1.0 / f32::from(max);
                (
                    raw.iter().map(|&i| f32::from(i) * inv).collect(),
                    None,
                    None,
                    IntensitySource::IntensityAttribute,
                )
            }
        }
    };
    let cloud = PointCloud::from_points(origin, &decoded.positions, &intensities, colors, None)?;
    Ok((
        cloud,
        LasInfo {
            header_point_count: decoded.header.number_of_points(),
            point_format: decoded.point_format,
            version: decoded.version,
            bounds: decoded.bounds,
            max_color_value,
            intensity_source,
        },
    ))
}

/// Check that `path` can name a cloud to write: it ends in `.las` or `.laz` (any case),
/// and its folder exists. [`write_las`] checks it; call it before long work too.
pub fn check_las_path(path: &Path) -> Result<(), SplatError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(extension.as_deref(), Some("las" | "laz")) {
        return Err(SplatError::Parameter {
            name: "path",
            message: format!("{} must end in .las or .laz", path.display()),
        });
    }
    if let Some(folder) = path.parent().filter(|p| !p.as_os_str().is_empty())
        && !folder.is_dir()
    {
        return Err(SplatError::Parameter {
            name: "path",
            message: format!(
                "{}: the folder {} does not exist",
                path.display(),
                folder.display()
            ),
        });
    }
    Ok(())
}

/// Write a cloud as LAS (or LAZ, by the `.laz` extension): LAS 1.2, point format 2,
/// millimetre resolution, 16-bit colour (grey levels of the intensity if the cloud has
/// no colour).
pub fn write_las(cloud: &PointCloud, path: impl AsRef<Path>) -> Result<(), SplatError> {
    let path = path.as_ref();
    check_las_path(path)?;
    let err = las_error(path);
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = las::point::Format::new(2).map_err(&err)?;
    builder.generating_software = "pgm-omni-vvs splat".into();
    let origin = cloud.origin();
    builder.transforms = las::Vector {
        x: las::Transform {
            scale: 0.001,
            offset: origin.x,
        },
        y: las::Transform {
            scale: 0.001,
            offset: origin.y,
        },
        z: las::Transform {
            scale: 0.001,
            offset: origin.z,
        },
    };
    let header = builder.into_header().map_err(&err)?;
    let mut writer = las::Writer::from_path(path, header).map_err(&err)?;
    for (i, (p, intensity)) in cloud.decoded().enumerate() {
        let rgb = match cloud.colors() {
            Some(c) => c[i],
            None => [(intensity * 255.0).round() as u8; 3],
        };
        let w = cloud.origin() + p;
        let point = las::Point {
            x: w.x,
            y: w.y,
            z: w.z,
            color: Some(las::Color::new(
                u16::from(rgb[0]) * 257,
                u16::from(rgb[1]) * 257,
                u16::from(rgb[2]) * 257,
            )),
            ..Default::default()
        };
        writer.write_point(point).map_err(&err)?;
    }
    writer.close().map_err(&err)?;
    Ok(())
}
