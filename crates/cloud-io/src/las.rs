//! LAS and LAZ (every point format, with or without colour).
//!
//! * **Colour depth is detected**: LAS stores 16-bit colour channels, but many files
//!   put 8-bit values in them. If no channel of any point exceeds 255 the values are
//!   taken as 8-bit; otherwise as 16-bit.
//! * **Without colour**, the points keep the LAS `intensity` attribute.
//! * The header's bounds are reported, never used (they may lie): the cloud's origin
//!   comes from the data.
//! * Writing uses LAS 1.2, point format 2 (position, intensity and colour, 16-bit full
//!   range: 8-bit colours are written `v · 257`); a `.laz` extension compresses. The
//!   coordinates are stored on a grid ([`LasGrid`]): the one given, or 0.1 mm from the
//!   points' minimum corner (1 mm, then 1 cm, when the extent does not fit 32 bits).

use std::path::Path;

use glam::DVec3;

use crate::{CloudIoError, ColorScale, Colors, Points};

/// Points read from a LAS file at a time.
const LAS_CHUNK_POINTS: u64 = 50_000;

/// Most points read from a LAZ file at a time: about 20 of its compressed chunks
/// (50 000 points each, as LASzip writes them), decompressed in parallel on rayon's
/// threads (`las`'s `laz-parallel`).
const LAZ_CHUNK_POINTS: u64 = 1 << 20;

/// The grid LAS coordinates are stored on: `coordinate = offset + scale · integer`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LasGrid {
    /// Scale factors along x, y, z, metres.
    pub scale_m: DVec3,
    /// Offsets, metres.
    pub offset_m: DVec3,
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
    /// The grid of the coordinates.
    pub grid: LasGrid,
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> CloudIoError + Copy + '_ {
    move |source| CloudIoError::Io {
        path: path.to_owned(),
        source,
    }
}

fn las_error(path: &Path) -> impl Fn(las::Error) -> CloudIoError + '_ {
    move |source| CloudIoError::Las {
        path: path.to_owned(),
        source: Box::new(source),
    }
}

/// Refuse a LAZ file whose `laszip` record describes no point item (the `laz` crate
/// panics on one rather than report it): a corrupt file. Returns the record, if the
/// file has one that reads.
fn check_laz_items(
    path: &Path,
    raw: &las::raw::Header,
) -> Result<Option<laz::LazVlr>, CloudIoError> {
    use std::io::{Seek, SeekFrom};
    let io_error = io_error(path);
    let mut file = std::io::BufReader::new(std::fs::File::open(path).map_err(io_error)?);
    file.seek(SeekFrom::Start(u64::from(raw.header_size)))
        .map_err(io_error)?;
    for _ in 0..raw.number_of_variable_length_records {
        let Ok(vlr) = las::raw::Vlr::read_from(&mut file, false) else {
            return Ok(None); // a truncated record list: `las` reports it
        };
        let user_id = String::from_utf8_lossy(&vlr.user_id);
        if vlr.record_id == 22204 && user_id.trim_end_matches('\0') == "laszip encoded" {
            return match laz::LazVlr::read_from(vlr.data.as_slice()) {
                Ok(laszip) if !laszip.items().is_empty() => Ok(Some(laszip)),
                _ => Err(invalid(
                    path,
                    "its laszip record describes no point item (corrupt LAZ)".into(),
                )),
            };
        }
    }
    Ok(None)
}

/// The most bytes a LAZ chunk may decompress to: the `laz` crate sizes its buffers
/// from the chunk's point count (the laszip record's `chunk_size`, or the chunk
/// table's counts) before it decodes anything. LASzip writes 50 000 points a chunk
/// (1.3 MB of format-2 points); a chunk may hold at most 64 MiB, or 256 times
/// the file's size (LAZ compresses points 5 to 15 times), whichever is larger.
fn laz_chunk_budget(file_bytes: u64) -> u64 {
    (64u64 << 20).max(file_bytes.saturating_mul(256))
}

/// Refuse a LAZ file whose chunks announce more points than [`laz_chunk_budget`]
/// allows, or more compressed bytes than the file holds: the `laz` crate would
/// allocate them before reading (111 GB for a 500-point file whose `chunk_size` was
/// set to 2³² − 16). Reads the chunk table as `laz` does.
fn check_laz_chunks(
    path: &Path,
    laszip: &laz::LazVlr,
    data_start: u64,
    file_bytes: u64,
) -> Result<(), CloudIoError> {
    use std::io::{Seek, SeekFrom};
    let io_error = io_error(path);
    let mut file = std::io::BufReader::new(std::fs::File::open(path).map_err(io_error)?);
    file.seek(SeekFrom::Start(data_start)).map_err(io_error)?;
    let Ok(table) = laz::laszip::ChunkTable::read_from(&mut file, laszip) else {
        return Ok(()); // no chunk table, or a truncated one: `laz` reports it
    };
    let point_bytes = laszip.items_size().max(1);
    let budget = laz_chunk_budget(file_bytes);
    let mut compressed = 0u64;
    for (k, entry) in table.as_ref().iter().enumerate() {
        let decoded = entry.point_count.saturating_mul(point_bytes);
        if decoded > budget {
            return Err(invalid(
                path,
                format!(
                    "its chunk {k} announces {} points of {point_bytes} bytes, more than a \
                     chunk of a {file_bytes}-byte file may hold ({budget} bytes; corrupt LAZ)",
                    entry.point_count
                ),
            ));
        }
        compressed = compressed.saturating_add(entry.byte_count);
    }
    if compressed > file_bytes {
        return Err(CloudIoError::Truncated {
            path: path.to_owned(),
            announced: None,
            found: format!(
                "chunks of {compressed} compressed bytes in {file_bytes} bytes (corrupt LAZ)"
            ),
        });
    }
    Ok(())
}

/// Refuse a LAS 1.4 file whose first extended record (the one `las` reads with the
/// header) reaches beyond the file's end: `las` would allocate the length it
/// announces (a 64-bit count) before reading it.
fn check_evlr(path: &Path, raw: &las::raw::Header, file_bytes: u64) -> Result<(), CloudIoError> {
    use std::io::{Read, Seek, SeekFrom};
    let Some(evlr) = raw.evlr else {
        return Ok(());
    };
    let io_error = io_error(path);
    // The record's header: reserved (2), user id (16), record id (2), the length (8),
    // a description (32).
    const HEADER_BYTES: u64 = 60;
    let mut file = std::fs::File::open(path).map_err(io_error)?;
    let mut head = [0u8; HEADER_BYTES as usize];
    if file
        .seek(SeekFrom::Start(evlr.start_of_first_evlr))
        .is_err()
        || file.read_exact(&mut head).is_err()
    {
        return Ok(()); // beyond the file: `las` reports it
    }
    let length = u64::from_le_bytes(head[20..28].try_into().expect("8 bytes"));
    let end = evlr
        .start_of_first_evlr
        .saturating_add(HEADER_BYTES)
        .saturating_add(length);
    if end > file_bytes {
        return Err(CloudIoError::Truncated {
            path: path.to_owned(),
            announced: None,
            found: format!(
                "an extended record of {length} bytes at byte {} of a {file_bytes}-byte file",
                evlr.start_of_first_evlr
            ),
        });
    }
    Ok(())
}

/// Refuse a LAZ file whose chunk table announces more chunks than the file has bytes
/// (the `laz` crate would allocate the table from that count: 25 GB for a corrupt
/// 10 KB file, found by our fuzzing). Mirrors `laz`'s own reading of the table's
/// offset: at the start of the point data, or in the file's last 8 bytes.
fn check_laz_chunk_table(
    path: &Path,
    data_start: u64,
    file_bytes: u64,
) -> Result<(), CloudIoError> {
    use std::io::{Read, Seek, SeekFrom};
    let io_error = io_error(path);
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
        return Err(CloudIoError::Truncated {
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
    grid: LasGrid,
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
) -> Result<Decoded, CloudIoError> {
    let mut reader = las::Reader::from_path(path).map_err(|e| {
        if ends_early(&e) {
            CloudIoError::Truncated {
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
    let t = header.transforms();
    let grid = LasGrid {
        scale_m: DVec3::new(t.x.scale, t.y.scale, t.z.scale),
        offset_m: DVec3::new(t.x.offset, t.y.offset, t.z.offset),
    };
    let announced = header.number_of_points();
    // An uncompressed file cannot hold more points than its bytes after the header;
    // checked before anything is allocated. A LAZ file is read by chunks, so memory
    // follows what it really holds, never its header.
    if !format.is_compressed {
        let record_bytes = u64::from(raw.point_data_record_length).max(1);
        let room = file_bytes.saturating_sub(u64::from(raw.offset_to_point_data));
        if announced > room / record_bytes {
            return Err(CloudIoError::Truncated {
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
    // `las` sizes its buffer from a request before decoding it: a LAZ file's requests
    // are budgeted in bytes, growing with the file's size (4 to 64 MiB), so that a
    // small file that lies about its count, or has long records, allocates little. (An
    // uncompressed file's count was checked against its size above.)
    let chunk_points = if format.is_compressed {
        let record_bytes = u64::from(raw.point_data_record_length).max(1);
        (file_bytes.clamp(4 << 20, 64 << 20) / record_bytes).clamp(1, LAZ_CHUNK_POINTS)
    } else {
        LAS_CHUNK_POINTS
    };
    let mut read = 0u64;
    while read < announced {
        let want = (announced - read).min(chunk_points);
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
        if let Some(rgb) = chunk.rgb().filter(|_| has_rgb) {
            raw_rgb.extend(rgb.map(|(r, g, b)| [r, g, b]));
        }
        raw_intensity.extend(chunk.intensity());
        read += got;
    }
    if read < announced {
        return Err(CloudIoError::Truncated {
            path: path.to_owned(),
            announced: Some(announced),
            found: format!(
                "{read} points before its data ends (read by chunks of {chunk_points}: up to \
                 {} more in the last one)",
                chunk_points - 1
            ),
        });
    }
    Ok(Decoded {
        header,
        grid,
        point_format,
        version,
        bounds,
        has_rgb,
        positions,
        raw_rgb,
        raw_intensity,
    })
}

/// Read a LAS or LAZ file's points.
pub(crate) fn read(path: &Path) -> Result<(Points, LasInfo), CloudIoError> {
    let io_error = io_error(path);
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
        return Err(invalid(
            path,
            format!(
                "the header's scale factors {scales:?} must be finite and non-zero, its \
                 offsets {offsets:?} finite"
            ),
        ));
    }
    check_evlr(path, &raw, file_bytes)?;
    if raw.point_data_record_format & 0x80 != 0 {
        let laszip = check_laz_items(path, &raw)?;
        let data_start = u64::from(raw.offset_to_point_data);
        check_laz_chunk_table(path, data_start, file_bytes)?;
        if let Some(laszip) = &laszip {
            check_laz_chunks(path, laszip, data_start, file_bytes)?;
        }
    }
    // The `laz` decoder asserts (panics) on some corrupt inputs instead of reporting
    // them (an empty item list, an arithmetic-coder symbol out of range: found by our
    // fuzzing); the checks above catch the known ones with a clear message, and
    // `read_points` reports any other panic inside the decoder as a corrupt file.
    let decoded = decode_points(path, &raw, file_bytes)?;
    let max_color_value = decoded
        .has_rgb
        .then(|| decoded.raw_rgb.iter().flatten().copied().max().unwrap_or(0));
    let colors = max_color_value.map(|max| Colors {
        values: decoded.raw_rgb,
        scale: if max <= 255 {
            ColorScale::EightBit
        } else {
            ColorScale::SixteenBit
        },
    });
    let points = Points {
        positions_m: decoded.positions,
        colors,
        intensities: Some(
            decoded
                .raw_intensity
                .iter()
                .map(|&i| f32::from(i))
                .collect(),
        ),
    };
    Ok((
        points,
        LasInfo {
            header_point_count: decoded.header.number_of_points(),
            point_format: decoded.point_format,
            version: decoded.version,
            bounds: decoded.bounds,
            max_color_value,
            grid: decoded.grid,
        },
    ))
}

/// A corrupt or unsupported file's error.
fn invalid(path: &Path, message: String) -> CloudIoError {
    CloudIoError::Las {
        path: path.to_owned(),
        source: Box::new(las::Error::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            message,
        ))),
    }
}

impl LasGrid {
    /// The finest of 0.1 mm, 1 mm and 1 cm on which every point is a 32-bit step from
    /// the points' minimum corner rounded down to the metre.
    pub fn fitting(positions_m: &[DVec3]) -> Self {
        let (lo, hi) = positions_m.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let offset_m = if lo.is_finite() {
            lo.floor()
        } else {
            DVec3::ZERO
        };
        let extent = (hi - offset_m).max_element();
        let scale = [1e-4, 1e-3, 1e-2]
            .into_iter()
            .find(|s| extent / s < f64::from(i32::MAX) - 1.0)
            .unwrap_or(1e-2);
        Self {
            scale_m: DVec3::splat(scale),
            offset_m,
        }
    }
}

/// Write points as LAS (or LAZ, by the `.laz` extension) on `grid`: LAS 1.2, point
/// format 2 with 16-bit colour (8-bit colours as `v · 257`), or format 0 without
/// colour; intensity rounded to 16 bits (normalised by its maximum unless it is
/// already within `[0, 65535]`; 0 without intensity).
pub(crate) fn write(points: &Points, path: &Path, grid: LasGrid) -> Result<(), CloudIoError> {
    let err = las_error(path);
    let mut builder = las::Builder::from((1, 2));
    let format = if points.colors.is_some() { 2 } else { 0 };
    builder.point_format = las::point::Format::new(format).map_err(&err)?;
    builder.generating_software = "pgm-omni-vvs cloud-io".into();
    let axis = |scale: f64, offset: f64| las::Transform { scale, offset };
    builder.transforms = las::Vector {
        x: axis(grid.scale_m.x, grid.offset_m.x),
        y: axis(grid.scale_m.y, grid.offset_m.y),
        z: axis(grid.scale_m.z, grid.offset_m.z),
    };
    let header = builder.into_header().map_err(&err)?;
    let intensity_16 = crate::intensity_to_u16(points.intensities.as_deref());
    let mut writer = las::Writer::from_path(path, header).map_err(&err)?;
    for (i, p) in points.positions_m.iter().enumerate() {
        let intensity = intensity_16.as_ref().map_or(0, |v| v[i]);
        let color = points.colors.as_ref().map(|c| {
            let rgb = match c.scale {
                ColorScale::EightBit => c.values[i].map(|v| v.min(255) * 257),
                ColorScale::SixteenBit => c.values[i],
            };
            las::Color::new(rgb[0], rgb[1], rgb[2])
        });
        let point = las::Point {
            x: p.x,
            y: p.y,
            z: p.z,
            intensity,
            color,
            ..Default::default()
        };
        writer.write_point(point).map_err(&err)?;
    }
    writer.close().map_err(&err)?;
    Ok(())
}
