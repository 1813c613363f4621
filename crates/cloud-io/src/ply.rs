//! PLY (Stanford polygon files): ASCII and binary of both byte orders.
//!
//! A small reader of our own rather than a crate: the kept PLY crates read a whole
//! element into a map of properties per vertex (a `HashMap` a point: gigabytes for a
//! scanner's cloud), and none bounds its memory by the file's size when a header lies.
//! This one reads the `vertex` element straight into [`Points`]:
//!
//! * coordinates `x`, `y`, `z` of any numeric type, kept as `f64`;
//! * colour `red`, `green`, `blue` (or `r`, `g`, `b`, or `diffuse_red`, …): `uchar`
//!   as 8-bit, `ushort` as 16-bit, floats in `[0, 1]` scaled to 16 bits; without them a
//!   `grey` / `gray` property is a grey colour;
//! * intensity `intensity` or `scalar_intensity` (CloudCompare), any numeric type;
//! * every other property is skipped, as are the elements before `vertex` (lists
//!   included) and everything after it.
//!
//! A binary file's vertex count is checked against its size before anything is
//! allocated; an ASCII file's points are stored as they are read, so memory follows
//! what the file holds. Writing is binary little-endian: `double` coordinates, colour
//! at its depth (`uchar` or `ushort`), `float` intensity.

use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

use glam::DVec3;

use crate::{CloudIoError, ColorScale, Colors, Points};

/// Longest header read, bytes: a header is a few hundred bytes; a file without
/// `end_header` within this is refused rather than read whole.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Vertices decoded at a time from a binary file.
const CHUNK_VERTICES: usize = 65_536;

/// How a PLY file stores its data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyEncoding {
    /// Text.
    Ascii,
    /// Binary, least significant byte first.
    BinaryLittleEndian,
    /// Binary, most significant byte first.
    BinaryBigEndian,
}

/// What was found in a PLY file.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyInfo {
    /// How the data is stored.
    pub encoding: PlyEncoding,
    /// Vertices the header announces.
    pub vertex_count: u64,
    /// The vertex element's properties, in order, as `type name`.
    pub properties: Vec<String>,
    /// The header's `comment` and `obj_info` lines (who wrote the file, often).
    pub comments: Vec<String>,
}

/// A scalar type of the format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    /// The format's name of the type.
    fn name(self) -> &'static str {
        match self {
            Self::I8 => "char",
            Self::U8 => "uchar",
            Self::I16 => "short",
            Self::U16 => "ushort",
            Self::I32 => "int",
            Self::U32 => "uint",
            Self::F32 => "float",
            Self::F64 => "double",
        }
    }

    fn bytes(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Self::F32 | Self::F64)
    }

    /// Decode one value from the first `self.bytes()` bytes of `b`.
    fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:literal) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap_or([0; $n]);
                if big_endian {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self {
            Self::I8 => f64::from(b[0] as i8),
            Self::U8 => f64::from(b[0]),
            Self::I16 => num!(i16, 2),
            Self::U16 => num!(u16, 2),
            Self::I32 => num!(i32, 4),
            Self::U32 => num!(u32, 4),
            Self::F32 => num!(f32, 4),
            Self::F64 => num!(f64, 8),
        }
    }

    /// Parse one ASCII value of this type (integers must be integers in range).
    fn parse_text(self, token: &str) -> Option<f64> {
        match self {
            Self::F32 | Self::F64 => token.parse::<f64>().ok(),
            Self::I8 => token.parse::<i8>().ok().map(f64::from),
            Self::U8 => token.parse::<u8>().ok().map(f64::from),
            Self::I16 => token.parse::<i16>().ok().map(f64::from),
            Self::U16 => token.parse::<u16>().ok().map(f64::from),
            Self::I32 => token.parse::<i32>().ok().map(f64::from),
            Self::U32 => token.parse::<u32>().ok().map(f64::from),
        }
    }
}

/// A property of an element.
#[derive(Clone, Debug)]
enum Property {
    Scalar { name: String, scalar: Scalar },
    List { count: Scalar, item: Scalar },
}

/// An element of the header.
#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

impl Element {
    /// Bytes of one record in a binary file, if it has no list.
    fn record_bytes(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p {
                Property::Scalar { scalar, .. } => Some(scalar.bytes()),
                Property::List { .. } => None,
            })
            .sum()
    }
}

/// What the vertex element's properties mean to us.
#[derive(Clone, Copy, Debug)]
enum Role {
    X,
    Y,
    Z,
    Red,
    Green,
    Blue,
    Grey,
    Intensity,
    Other,
}

fn role(name: &str) -> Role {
    match name.to_ascii_lowercase().as_str() {
        "x" => Role::X,
        "y" => Role::Y,
        "z" => Role::Z,
        "red" | "r" | "diffuse_red" => Role::Red,
        "green" | "g" | "diffuse_green" => Role::Green,
        "blue" | "b" | "diffuse_blue" => Role::Blue,
        "grey" | "gray" => Role::Grey,
        "intensity" | "scalar_intensity" => Role::Intensity,
        _ => Role::Other,
    }
}

struct Header {
    encoding: PlyEncoding,
    elements: Vec<Element>,
    comments: Vec<String>,
    /// Bytes of the header, `end_header` line included.
    bytes: u64,
}

fn ply_error(path: &Path, message: impl Into<String>) -> CloudIoError {
    CloudIoError::Ply {
        path: path.to_owned(),
        message: message.into(),
    }
}

fn read_header(path: &Path, reader: &mut impl BufRead) -> Result<Header, CloudIoError> {
    let io_error = |source| CloudIoError::Io {
        path: path.to_owned(),
        source,
    };
    let mut bytes = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    let mut line = Vec::new();
    for number in 1.. {
        line.clear();
        let n = reader
            .by_ref()
            .take((MAX_HEADER_BYTES - bytes) as u64)
            .read_until(b'\n', &mut line)
            .map_err(io_error)?;
        bytes += n;
        if n == 0 || !line.ends_with(b"\n") {
            return Err(ply_error(
                path,
                if bytes >= MAX_HEADER_BYTES {
                    format!("no `end_header` in its first {MAX_HEADER_BYTES} bytes")
                } else {
                    "the file ends before `end_header`".to_owned()
                },
            ));
        }
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end_matches(['\n', '\r']);
        let words: Vec<&str> = text.split_whitespace().collect();
        let bad = |what: &str| ply_error(path, format!("header line {number} `{text}`: {what}"));
        match words.as_slice() {
            ["ply"] if number == 1 => {}
            _ if number == 1 => return Err(bad("the first line must be `ply`")),
            ["format", kind, version] => {
                if !version.starts_with('1') {
                    return Err(bad("only version 1.0 exists"));
                }
                encoding = Some(match *kind {
                    "ascii" => PlyEncoding::Ascii,
                    "binary_little_endian" => PlyEncoding::BinaryLittleEndian,
                    "binary_big_endian" => PlyEncoding::BinaryBigEndian,
                    _ => return Err(bad("an unknown format")),
                });
            }
            ["comment" | "obj_info", ..] => {
                if comments.len() < 64 {
                    comments.push(text.to_owned());
                }
            }
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| bad("the count is not a non-negative integer"))?;
                elements.push(Element {
                    name: (*name).to_owned(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, item, _name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad("a property before any element"))?;
                let count = Scalar::parse(count).ok_or_else(|| bad("an unknown type"))?;
                let item = Scalar::parse(item).ok_or_else(|| bad("an unknown type"))?;
                if count.is_float() {
                    return Err(bad("a list's count must be an integer type"));
                }
                element.properties.push(Property::List { count, item });
            }
            ["property", scalar, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad("a property before any element"))?;
                let scalar = Scalar::parse(scalar).ok_or_else(|| bad("an unknown type"))?;
                element.properties.push(Property::Scalar {
                    name: (*name).to_owned(),
                    scalar,
                });
            }
            ["end_header"] => {
                let encoding =
                    encoding.ok_or_else(|| ply_error(path, "the header has no `format` line"))?;
                return Ok(Header {
                    encoding,
                    elements,
                    comments,
                    bytes: bytes as u64,
                });
            }
            [] => {}
            _ => return Err(bad("not a PLY header line")),
        }
    }
    unreachable!("the loop returns")
}

/// Where each wanted value of a vertex lies.
struct Layout {
    roles: Vec<(Role, Scalar)>,
    color: Option<Scalar>,
    grey: Option<Scalar>,
    intensity: bool,
}

fn layout(path: &Path, vertex: &Element) -> Result<Layout, CloudIoError> {
    let mut roles = Vec::new();
    let mut seen = [false; 8];
    for p in &vertex.properties {
        match p {
            Property::Scalar { name, scalar } => {
                let r = role(name);
                let index = r as usize;
                if index < 8 && std::mem::replace(&mut seen[index], true) {
                    return Err(ply_error(
                        path,
                        format!("the vertex element names `{name}` twice"),
                    ));
                }
                roles.push((r, *scalar));
            }
            Property::List { .. } => {
                return Err(ply_error(
                    path,
                    "the vertex element holds a list property: not a point cloud this reader takes",
                ));
            }
        }
    }
    if !(seen[Role::X as usize] && seen[Role::Y as usize] && seen[Role::Z as usize]) {
        return Err(ply_error(path, "the vertex element lacks x, y or z"));
    }
    let type_of = |wanted: Role| {
        roles
            .iter()
            .find(|(r, _)| *r as usize == wanted as usize)
            .map(|(_, s)| *s)
    };
    let color = match (
        type_of(Role::Red),
        type_of(Role::Green),
        type_of(Role::Blue),
    ) {
        (Some(r), Some(g), Some(b)) => {
            if r != g || g != b {
                return Err(ply_error(
                    path,
                    format!("red, green and blue have different types ({r:?}, {g:?}, {b:?})"),
                ));
            }
            Some(r)
        }
        (None, None, None) => None,
        _ => {
            return Err(ply_error(
                path,
                "the vertex element has some colour channels only",
            ));
        }
    };
    let grey = if color.is_none() {
        type_of(Role::Grey)
    } else {
        None
    };
    Ok(Layout {
        color,
        grey,
        intensity: seen[Role::Intensity as usize],
        roles,
    })
}

/// A colour channel as its depth's integer: 8-bit for `uchar`/`char`, 16-bit for
/// the rest (floats in `[0, 1]` scaled to 16 bits, clamped).
fn channel(scalar: Scalar, v: f64) -> u16 {
    let v = if v.is_finite() { v } else { 0.0 };
    if scalar.is_float() {
        (v.clamp(0.0, 1.0) * 65_535.0).round() as u16
    } else {
        v.clamp(0.0, 65_535.0) as u16
    }
}

fn color_scale(scalar: Scalar) -> ColorScale {
    match scalar {
        Scalar::U8 | Scalar::I8 => ColorScale::EightBit,
        _ => ColorScale::SixteenBit,
    }
}

/// Collects the vertices' values.
struct Sink {
    layout: Layout,
    positions: Vec<DVec3>,
    colors: Vec<[u16; 3]>,
    intensities: Vec<f32>,
    values: Vec<f64>,
}

impl Sink {
    fn new(layout: Layout) -> Self {
        let n = layout.roles.len();
        Self {
            layout,
            positions: Vec::new(),
            colors: Vec::new(),
            intensities: Vec::new(),
            values: Vec::with_capacity(n),
        }
    }

    fn reserve(&mut self, n: usize) {
        self.positions.reserve(n);
        if self.layout.color.is_some() || self.layout.grey.is_some() {
            self.colors.reserve(n);
        }
        if self.layout.intensity {
            self.intensities.reserve(n);
        }
    }

    /// Store the vertex whose values are in `self.values`.
    fn push(&mut self) {
        let mut p = DVec3::ZERO;
        let mut rgb = [0u16; 3];
        let mut intensity = 0.0;
        for (&(role, scalar), &v) in self.layout.roles.iter().zip(&self.values) {
            match role {
                Role::X => p.x = v,
                Role::Y => p.y = v,
                Role::Z => p.z = v,
                Role::Red => rgb[0] = channel(scalar, v),
                Role::Green => rgb[1] = channel(scalar, v),
                Role::Blue => rgb[2] = channel(scalar, v),
                Role::Grey if self.layout.color.is_none() => rgb = [channel(scalar, v); 3],
                Role::Intensity => intensity = v as f32,
                Role::Grey | Role::Other => {}
            }
        }
        self.positions.push(p);
        if self.layout.color.is_some() || self.layout.grey.is_some() {
            self.colors.push(rgb);
        }
        if self.layout.intensity {
            self.intensities.push(intensity);
        }
    }

    fn finish(self) -> Points {
        let scale = self.layout.color.or(self.layout.grey).map(color_scale);
        Points {
            positions_m: self.positions,
            colors: scale.map(|scale| Colors {
                values: self.colors,
                scale,
            }),
            intensities: self.layout.intensity.then_some(self.intensities),
        }
    }
}

/// Reads whitespace-separated tokens of an ASCII body.
struct Tokens<R> {
    reader: R,
    /// The current line's bytes (reused from line to line).
    bytes: Vec<u8>,
    /// Its text (reused too).
    line: String,
    pos: usize,
    line_number: u64,
}

impl<R: BufRead> Tokens<R> {
    /// The next token, or `None` at the end of the file.
    fn next(&mut self) -> std::io::Result<Option<&str>> {
        loop {
            let rest = &self.line[self.pos..];
            let start = rest.len() - rest.trim_start().len();
            let rest = &rest[start..];
            if !rest.is_empty() {
                let len = rest.find(char::is_whitespace).unwrap_or(rest.len());
                let begin = self.pos + start;
                self.pos = begin + len;
                return Ok(Some(&self.line[begin..begin + len]));
            }
            self.line.clear();
            self.bytes.clear();
            self.pos = 0;
            if self.reader.read_until(b'\n', &mut self.bytes)? == 0 {
                return Ok(None);
            }
            self.line_number += 1;
            self.line.push_str(&String::from_utf8_lossy(&self.bytes));
        }
    }
}

/// Read a PLY file's vertices.
pub(crate) fn read(path: &Path) -> Result<(Points, PlyInfo), CloudIoError> {
    let io_error = |source| CloudIoError::Io {
        path: path.to_owned(),
        source,
    };
    let file_bytes = std::fs::metadata(path).map_err(io_error)?.len();
    let mut reader =
        BufReader::with_capacity(1 << 16, std::fs::File::open(path).map_err(io_error)?);
    let header = read_header(path, &mut reader)?;
    let vertex_index = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| ply_error(path, "the header declares no `vertex` element"))?;
    let vertex = header.elements[vertex_index].clone();
    let layout = layout(path, &vertex)?;
    let info = PlyInfo {
        encoding: header.encoding,
        vertex_count: vertex.count,
        properties: vertex
            .properties
            .iter()
            .map(|p| match p {
                Property::Scalar { name, scalar } => format!("{} {name}", scalar.name()),
                Property::List { .. } => "list".to_owned(),
            })
            .collect(),
        comments: header.comments.clone(),
    };
    let mut sink = Sink::new(layout);
    let body_bytes = file_bytes.saturating_sub(header.bytes);
    match header.encoding {
        PlyEncoding::Ascii => {
            let mut tokens = Tokens {
                reader,
                bytes: Vec::new(),
                line: String::new(),
                pos: 0,
                line_number: 0,
            };
            for element in &header.elements[..vertex_index] {
                skip_ascii(path, &mut tokens, element)?;
            }
            let width = sink.layout.roles.len();
            let mut read = 0u64;
            while read < vertex.count {
                sink.values.clear();
                for k in 0..width {
                    let (_, scalar) = sink.layout.roles[k];
                    let Some(token) = tokens.next().map_err(io_error)? else {
                        return Err(CloudIoError::Truncated {
                            path: path.to_owned(),
                            announced: Some(vertex.count),
                            found: format!("{read} vertices before its text ends"),
                        });
                    };
                    let Some(value) = scalar.parse_text(token) else {
                        let token = token.to_owned();
                        return Err(ply_error(
                            path,
                            format!(
                                "vertex {read} (body line {}): `{token}` is not a {scalar:?}",
                                tokens.line_number
                            ),
                        ));
                    };
                    sink.values.push(value);
                }
                sink.push();
                read += 1;
            }
        }
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => {
            let big = header.encoding == PlyEncoding::BinaryBigEndian;
            let mut skipped = 0u64;
            for element in &header.elements[..vertex_index] {
                skipped += skip_binary(path, &mut reader, element, big, body_bytes - skipped)?;
            }
            let record = vertex.record_bytes().unwrap_or(0).max(1);
            let room = (body_bytes - skipped) / record as u64;
            if vertex.count > room {
                return Err(CloudIoError::Truncated {
                    path: path.to_owned(),
                    announced: Some(vertex.count),
                    found: format!(
                        "{room} vertices (its {} bytes after the header)",
                        body_bytes - skipped
                    ),
                });
            }
            sink.reserve(vertex.count as usize);
            let offsets: Vec<usize> = sink
                .layout
                .roles
                .iter()
                .scan(0, |at, (_, s)| {
                    let here = *at;
                    *at += s.bytes();
                    Some(here)
                })
                .collect();
            // At most 4 MiB a chunk, and no more vertices than announced (which the
            // file's size bounds): a header of many properties allocates little.
            let chunk = CHUNK_VERTICES
                .min(vertex.count as usize)
                .min(((4 << 20) / record).max(1));
            let mut buffer = vec![0u8; record * chunk];
            let mut left = vertex.count as usize;
            while left > 0 {
                let n = left.min(chunk);
                let chunk = &mut buffer[..n * record];
                reader.read_exact(chunk).map_err(io_error)?;
                for r in chunk.chunks_exact(record) {
                    sink.values.clear();
                    for (&(_, scalar), &at) in sink.layout.roles.iter().zip(&offsets) {
                        sink.values.push(scalar.decode(&r[at..], big));
                    }
                    sink.push();
                }
                left -= n;
            }
        }
    }
    Ok((sink.finish(), info))
}

/// The error of a file that ends inside the records of an element before the vertices.
fn element_ended(path: &Path, element: &Element) -> CloudIoError {
    CloudIoError::Truncated {
        path: path.to_owned(),
        announced: None,
        found: format!(
            "fewer than the {} `{}` records before its vertices",
            element.count, element.name
        ),
    }
}

fn skip_ascii<R: BufRead>(
    path: &Path,
    tokens: &mut Tokens<R>,
    element: &Element,
) -> Result<(), CloudIoError> {
    let ended = || element_ended(path, element);
    let io_error = |source| CloudIoError::Io {
        path: path.to_owned(),
        source,
    };
    if element.properties.is_empty() {
        return Ok(()); // records of nothing, however many
    }
    for _ in 0..element.count {
        for p in &element.properties {
            let items = match p {
                Property::Scalar { .. } => 1,
                Property::List { .. } => {
                    let token = tokens.next().map_err(io_error)?.ok_or_else(ended)?;
                    token.parse::<u64>().map_err(|_| {
                        ply_error(path, format!("a list count `{token}` is not a count"))
                    })?
                }
            };
            for _ in 0..items {
                tokens.next().map_err(io_error)?.ok_or_else(ended)?;
            }
        }
    }
    Ok(())
}

/// Skip an element of a binary file; returns the bytes skipped (at most `room`).
fn skip_binary(
    path: &Path,
    reader: &mut impl Read,
    element: &Element,
    big: bool,
    room: u64,
) -> Result<u64, CloudIoError> {
    let ended = || element_ended(path, element);
    let skip = |reader: &mut dyn Read, bytes: u64, done: &mut u64| {
        if *done + bytes > room {
            return Err(ended());
        }
        let copied =
            std::io::copy(&mut reader.take(bytes), &mut std::io::sink()).map_err(|source| {
                CloudIoError::Io {
                    path: path.to_owned(),
                    source,
                }
            })?;
        if copied < bytes {
            return Err(ended());
        }
        *done += bytes;
        Ok(())
    };
    let mut done = 0u64;
    if let Some(record) = element.record_bytes() {
        let total = element.count.checked_mul(record as u64).ok_or_else(ended)?;
        skip(reader, total, &mut done)?;
        return Ok(done);
    }
    for _ in 0..element.count {
        for p in &element.properties {
            match p {
                Property::Scalar { scalar, .. } => skip(reader, scalar.bytes() as u64, &mut done)?,
                Property::List { count, item } => {
                    let mut b = [0u8; 8];
                    let n = count.bytes();
                    if done + n as u64 > room {
                        return Err(ended());
                    }
                    reader.read_exact(&mut b[..n]).map_err(|_| ended())?;
                    done += n as u64;
                    let items = count.decode(&b, big).max(0.0) as u64;
                    let bytes = items.checked_mul(item.bytes() as u64).ok_or_else(ended)?;
                    skip(reader, bytes, &mut done)?;
                }
            }
        }
    }
    Ok(done)
}

/// Write points as binary little-endian PLY.
pub(crate) fn write(points: &Points, path: &Path) -> Result<(), CloudIoError> {
    let io_error = |source| CloudIoError::Io {
        path: path.to_owned(),
        source,
    };
    let file = std::fs::File::create(path).map_err(io_error)?;
    let mut out = BufWriter::with_capacity(1 << 16, file);
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by pgm-omni-vvs cloud-io\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n",
        points.len()
    );
    let color_type = points.colors.as_ref().map(|c| match c.scale {
        ColorScale::EightBit => "uchar",
        ColorScale::SixteenBit => "ushort",
    });
    if let Some(t) = color_type {
        for c in ["red", "green", "blue"] {
            header.push_str(&format!("property {t} {c}\n"));
        }
    }
    if points.intensities.is_some() {
        header.push_str("property float intensity\n");
    }
    header.push_str("end_header\n");
    out.write_all(header.as_bytes()).map_err(io_error)?;
    let mut record = Vec::with_capacity(34);
    for (i, p) in points.positions_m.iter().enumerate() {
        record.clear();
        for v in [p.x, p.y, p.z] {
            record.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(c) = &points.colors {
            for v in c.values[i] {
                match c.scale {
                    ColorScale::EightBit => record.push(v.min(255) as u8),
                    ColorScale::SixteenBit => record.extend_from_slice(&v.to_le_bytes()),
                }
            }
        }
        if let Some(intensities) = &points.intensities {
            record.extend_from_slice(&intensities[i].to_le_bytes());
        }
        out.write_all(&record).map_err(io_error)?;
    }
    out.flush().map_err(io_error)?;
    Ok(())
}
