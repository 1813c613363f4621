//! Camera files: the project's TOML format (read and write) and Mei calibrations
//! (YAML, read).
//!
//! # The camera TOML file
//!
//! ```toml
//! [image]
//! width = 320            # pixels
//! height = 240
//!
//! [intrinsics]
//! alpha_u = 54.0         # generalised focal lengths, pixels (> 0)
//! alpha_v = 54.0
//! u0 = 159.5             # principal point, pixels (pixel (i, j) is centred on u = i, v = j)
//! v0 = 119.5
//! xi = 0.9               # mirror parameter (>= 0; 0 = pinhole)
//! # skew = 0.0           # optional, pixels: u = alpha_u x + skew y + u0
//!
//! # [distortion]         # optional, radial-tangential (Mei's, or plumb-bob with k3)
//! # k1 = 0.0
//! # k2 = 0.0
//! # p1 = 0.0
//! # p2 = 0.0
//! # k3 = 0.0           # optional (OpenCV/ROS plumb-bob calibrations)
//!
//! [region]               # the valid part of the image
//! kind = "annulus"       # "full", "annulus" or "mask"
//! inner_radius_px = 27.0
//! outer_radius_px = 117.0
//! # center_px = [159.5, 119.5]   # optional, defaults to the principal point
//! # kind = "mask" takes `path = "mask.png"`, relative to the TOML file; pixels >= 128 are valid
//! ```
//!
//! Unknown keys are errors (a typo must not silently fall back to a default).

use std::io::Read;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use yaml_rust2::{Yaml, YamlLoader};

use crate::{Annulus, Camera, Distortion, Intrinsics, Mask, UcmError, ValidRegion};

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    image: ImageSection,
    intrinsics: Intrinsics,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    distortion: Option<Distortion>,
    region: RegionSpec,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ImageSection {
    width: u32,
    height: u32,
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum RegionSpec {
    Full,
    Annulus {
        inner_radius_px: f64,
        outer_radius_px: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        center_px: Option<[f64; 2]>,
    },
    Mask {
        path: PathBuf,
    },
}

impl Camera {
    /// Parse a camera from TOML text. Relative mask paths are resolved against
    /// `base_dir` (the current directory if `None`).
    pub fn from_toml_str(text: &str, base_dir: Option<&Path>) -> Result<Self, UcmError> {
        Self::parse_toml(text, base_dir, Path::new("<string>"))
    }

    fn parse_toml(text: &str, base_dir: Option<&Path>, origin: &Path) -> Result<Self, UcmError> {
        let file: CameraFile = toml::from_str(text).map_err(|source| UcmError::Toml {
            path: origin.to_owned(),
            source: Box::new(source),
        })?;
        // Validate the intrinsics first so that a bad principal point is reported as
        // such rather than through a bad annulus centre.
        file.intrinsics.validate()?;
        let region = match file.region {
            RegionSpec::Full => ValidRegion::Full,
            RegionSpec::Annulus {
                inner_radius_px,
                outer_radius_px,
                center_px,
            } => ValidRegion::Annulus(Annulus {
                center_px: center_px.unwrap_or([file.intrinsics.u0, file.intrinsics.v0]),
                inner_radius_px,
                outer_radius_px,
            }),
            RegionSpec::Mask { path } => {
                let path = match base_dir {
                    Some(dir) if path.is_relative() => dir.join(path),
                    _ => path,
                };
                ValidRegion::Mask(Mask::from_image_file(&path)?)
            }
        };
        Camera::new(
            file.intrinsics,
            file.distortion,
            file.image.width,
            file.image.height,
            region,
        )
    }

    /// Read a camera TOML file (format in the [module documentation](crate::io)).
    pub fn load_toml(path: impl AsRef<Path>) -> Result<Self, UcmError> {
        let path = path.as_ref();
        let text = read_text_file(path)?;
        Self::parse_toml(&text, path.parent(), path)
    }

    /// The camera as TOML text. A mask region is written as the path it was read
    /// from; a mask built in memory cannot be written this way (use
    /// [`Camera::save_toml`], which writes the mask beside the file).
    pub fn to_toml_string(&self) -> Result<String, UcmError> {
        let mask_path = match self.region() {
            ValidRegion::Mask(m) => {
                Some(
                    m.source()
                        .map(Path::to_owned)
                        .ok_or_else(|| UcmError::Calibration {
                            path: PathBuf::from("<memory>"),
                            message: "an in-memory mask has no file to refer to; use save_toml"
                                .into(),
                        })?,
                )
            }
            _ => None,
        };
        self.toml_with_mask_path(mask_path)
    }

    fn toml_with_mask_path(&self, mask_path: Option<PathBuf>) -> Result<String, UcmError> {
        let region = match (self.region(), mask_path) {
            (ValidRegion::Full, _) => RegionSpec::Full,
            (ValidRegion::Annulus(a), _) => RegionSpec::Annulus {
                inner_radius_px: a.inner_radius_px,
                outer_radius_px: a.outer_radius_px,
                center_px: (a.center_px != [self.intrinsics().u0, self.intrinsics().v0])
                    .then_some(a.center_px),
            },
            (ValidRegion::Mask(_), path) => RegionSpec::Mask {
                path: path.unwrap_or_default(),
            },
        };
        let file = CameraFile {
            image: ImageSection {
                width: self.width(),
                height: self.height(),
            },
            intrinsics: *self.intrinsics(),
            distortion: self.distortion().copied(),
            region,
        };
        Ok(toml::to_string_pretty(&file)?)
    }

    /// Write the camera as a TOML file. A mask region is written as a PNG beside it
    /// (`<name>.mask.png`), referred to by a relative path.
    pub fn save_toml(&self, path: impl AsRef<Path>) -> Result<(), UcmError> {
        let path = path.as_ref();
        let mask_path = match self.region() {
            ValidRegion::Mask(m) => {
                let stem = path.file_stem().unwrap_or_default().to_string_lossy();
                let name = format!("{stem}.mask.png");
                m.save_png(&path.with_file_name(&name))?;
                Some(PathBuf::from(name))
            }
            _ => None,
        };
        let text = self.toml_with_mask_path(mask_path)?;
        std::fs::write(path, text).map_err(|source| UcmError::Io {
            path: path.to_owned(),
            source,
        })
    }

    /// Read a Mei calibration in the YAML layout of `omniunwarp` (keys `K`: the 3×3
    /// matrix `[fx, s, u0; 0, fy, v0; 0, 0, 1]` row-major, `D`: `[k1, k2, p1, p2]`,
    /// `Xi`: `[ξ]` or `ξ`), in flow (`[a, b]`) or block (`- a` lines) style, or each an
    /// OpenCV matrix (`!!opencv-matrix` with `data: [...]`; OpenCV's `%YAML:1.0` first
    /// line is accepted). The file holds no image size or mask: give them. Files over
    /// [`MAX_TEXT_FILE_BYTES`] are refused unread.
    pub fn load_mei_yaml(
        path: impl AsRef<Path>,
        width: u32,
        height: u32,
        region: ValidRegion,
    ) -> Result<Self, UcmError> {
        let path = path.as_ref();
        let bad = |message: String| UcmError::Calibration {
            path: path.to_owned(),
            message,
        };
        let text = read_text_file(path)?;
        let document = yaml_document(&text).map_err(&bad)?;
        let k = yaml_numbers(&document, "K").map_err(&bad)?;
        let d = yaml_numbers(&document, "D").map_err(&bad)?;
        let xi = yaml_numbers(&document, "Xi").map_err(&bad)?;
        if k.len() != 9 || d.len() != 4 || xi.len() != 1 {
            return Err(bad(format!(
                "expected 9 values in K, 4 in D and 1 in Xi, found {}, {} and {}",
                k.len(),
                d.len(),
                xi.len()
            )));
        }
        if k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(bad(format!(
                "K is not upper triangular with K[2][2] = 1: {k:?}"
            )));
        }
        let intrinsics = Intrinsics {
            alpha_u: k[0],
            alpha_v: k[4],
            u0: k[2],
            v0: k[5],
            xi: xi[0],
            skew: k[1],
        };
        let distortion = Distortion {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: 0.0,
        };
        Camera::new(intrinsics, Some(distortion), width, height, region)
    }
}

/// The largest camera or calibration file read (either is a few hundred bytes).
pub const MAX_TEXT_FILE_BYTES: u64 = 1 << 20;

/// The text of a camera or calibration file: at most [`MAX_TEXT_FILE_BYTES`], UTF-8.
fn read_text_file(path: &Path) -> Result<String, UcmError> {
    let io = |source| UcmError::Io {
        path: path.to_owned(),
        source,
    };
    let not_text = |message: String| UcmError::NotText {
        path: path.to_owned(),
        message,
    };
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_TEXT_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_TEXT_FILE_BYTES {
        return Err(not_text(format!("larger than {MAX_TEXT_FILE_BYTES} bytes")));
    }
    String::from_utf8(bytes).map_err(|e| {
        not_text(format!(
            "not UTF-8 text (byte {} is not; a binary file?)",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// The single YAML mapping of a calibration file. OpenCV writes `%YAML:1.0` as its
/// first line, which YAML 1.2 does not accept: it is read as `%YAML 1.2`'s absence.
fn yaml_document(text: &str) -> Result<Yaml, String> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let text = match text.strip_prefix("%YAML:") {
        Some(rest) => rest.split_once('\n').map_or("", |(_, rest)| rest),
        None => text,
    };
    let mut documents = YamlLoader::load_from_str(text).map_err(|e| format!("not YAML: {e}"))?;
    match documents.len() {
        1 => {}
        0 => return Err("empty".into()),
        n => return Err(format!("{n} YAML documents where one was expected")),
    }
    let document = documents.remove(0);
    if document.as_hash().is_none() {
        return Err("not a mapping of keys K, D and Xi".into());
    }
    Ok(document)
}

/// The numbers under `key`: a list (flow or block style), an OpenCV matrix (its
/// `data` list) or one number.
fn yaml_numbers(document: &Yaml, key: &str) -> Result<Vec<f64>, String> {
    let value = &document[key];
    let list = match value {
        Yaml::BadValue => return Err(format!("key `{key}` not found")),
        Yaml::Array(list) => list.as_slice(),
        Yaml::Hash(_) => match &value["data"] {
            Yaml::Array(list) => list.as_slice(),
            _ => return Err(format!("`{key}` is a mapping without a `data` list")),
        },
        scalar => std::slice::from_ref(scalar),
    };
    list.iter()
        .map(|item| {
            match item {
                Yaml::Real(_) => item.as_f64(),
                Yaml::Integer(i) => Some(*i as f64),
                _ => None,
            }
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("`{key}`: {} is not a finite number", yaml_shown(item)))
        })
        .collect()
}

/// A YAML value as the message of an error shows it.
fn yaml_shown(value: &Yaml) -> String {
    match value {
        Yaml::Real(s) | Yaml::String(s) => format!("`{s}`"),
        Yaml::Integer(i) => format!("`{i}`"),
        Yaml::Boolean(b) => format!("`{b}`"),
        Yaml::Null => "an empty value".into(),
        Yaml::Array(_) => "a list".into(),
        Yaml::Hash(_) => "a mapping".into(),
        Yaml::Alias(_) | Yaml::BadValue => "an alias".into(),
    }
}
