//! [`RgbdDataset`]: a folder of RGB-D frames described by a TOML file — where the
//! pictures and the poses are, the sensor's cameras and how they sit.
//!
//! ```toml
//! frames = [0, 999]                        # first and last frame number
//! color = "frame-{:06}.color.jpg"          # {} or {:0N}: the frame number
//! depth = "frame-{:06}.depth.png"          # 16-bit grey PNG or binary PGM
//! depth_scale_m = 0.001                    # metres per depth unit
//! invalid_depth = [65535]                  # samples that mean "no measurement" (0 always does)
//! color_camera = "kinect-color.toml"       # camera TOML files, relative to this file
//! depth_camera = "kinect-depth.toml"       # optional: the colour camera's (registered)
//! # optional: points of the depth camera into the colour camera (3 rows of 4, metres)
//! color_from_depth = [[1, 0, 0, -0.025], [0, 1, 0, 0], [0, 0, 1, 0]]
//!
//! [poses]
//! kind = "matrix"                          # 4×4 (or 3×4) row-major world_from_camera
//! path = "frame-{:06}.pose.txt"            # one file per frame, or one file of them all
//! of = "depth"                             # the camera the poses place: "color" or "depth"
//! # kind = "lines": one line per frame from `frames`' first, `tx ty tz qx qy qz qw`
//! # (or TUM's `timestamp tx ty tz qx qy qz qw`); `#` starts a comment
//! # kind = "colmap": COLMAP's `images.txt` layout, `NAME qw qx qy qz tx ty tz ...`
//! # placing the world in the camera (`camera_from_world`); lines are matched to
//! # frames by `name = "seq-01/frame-{:06}.color.png"`, others are skipped; an
//! # optional `scale` (metres per unit of the file, default 1) scales the
//! # translations, for poses from structure from motion
//! # kind = "timestamped": `timestamp tx ty tz qx qy qz qw` lines at their own rate
//! # (TUM RGB-D's groundtruth.txt: motion capture at 100 Hz), interpolated
//! # (linearly, rotations by slerp) between the two poses around each frame's colour
//! # timestamp for its colour camera and around its depth timestamp for its depth
//! # camera, at most `max_gap_s` apart (default 0.05); needs `associations`
//! ```
//!
//! Frames named by timestamps (TUM RGB-D's layout) are listed by an association file
//! instead of the `color` and `depth` patterns; the frame numbers are its lines
//! (from 0, comments and empty lines skipped):
//!
//! ```toml
//! frames = [0, 693]
//! associations = "associations.txt"  # `t_color color/t.png t_depth depth/t.png` lines,
//!                                    # as TUM's associate.py writes from rgb.txt, depth.txt
//! depth_scale_m = 0.0002
//! color_camera = "tum-freiburg1-color.toml"
//!
//! [poses]
//! kind = "timestamped"
//! path = "groundtruth.txt"
//! of = "color"
//! ```
//!
//! The pictures and pose files are relative to the data folder given to
//! [`RgbdDataset::load`] (data are not kept beside their description).
//! Rotations are re-orthonormalised (poses are often written to 4–6 digits); a matrix
//! farther than 0.05 from a rotation is an error.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use serde::Deserialize;
use ucm::{Camera, Isometry3};

use crate::error::check_size;
use crate::{ColorImage, DepthImage, FrameStats, FuseOptions, Fusion, RgbdError, Sensor};

/// Which camera a dataset's poses place.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseOf {
    /// `world_from_color`.
    Color,
    /// `world_from_depth`.
    Depth,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DatasetFile {
    frames: [u64; 2],
    #[serde(default)]
    color: Option<String>,
    #[serde(default)]
    depth: Option<String>,
    #[serde(default)]
    associations: Option<String>,
    depth_scale_m: f64,
    #[serde(default)]
    invalid_depth: Vec<u16>,
    color_camera: PathBuf,
    #[serde(default)]
    depth_camera: Option<PathBuf>,
    #[serde(default)]
    color_from_depth: Option<[[f64; 4]; 3]>,
    poses: PosesFile,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "snake_case")]
enum PosesFile {
    Matrix {
        path: String,
        of: PoseOf,
    },
    Lines {
        path: String,
        of: PoseOf,
    },
    Colmap {
        path: String,
        of: PoseOf,
        name: String,
        #[serde(default = "unit_scale")]
        scale: f64,
    },
    Timestamped {
        path: String,
        of: PoseOf,
        #[serde(default = "default_max_gap_s")]
        max_gap_s: f64,
    },
}

fn unit_scale() -> f64 {
    1.0
}

fn default_max_gap_s() -> f64 {
    0.05
}

/// Where a dataset's pictures are.
#[derive(Clone, Debug)]
enum Pictures {
    /// Named by the frame number (`frame_path`).
    Patterns { color: String, depth: String },
    /// Listed by an association file, one line per frame from the first.
    Listed {
        color: Vec<String>,
        depth: Vec<String>,
    },
}

/// The lines of an association file: colour timestamp and file, depth timestamp and
/// file (TUM's associate.py).
struct Associations {
    color_time_s: Vec<f64>,
    depth_time_s: Vec<f64>,
    color: Vec<String>,
    depth: Vec<String>,
}

fn read_associations(path: &Path) -> Result<Associations, RgbdError> {
    let text = read_text(path)?;
    let mut out = Associations {
        color_time_s: Vec::new(),
        depth_time_s: Vec::new(),
        color: Vec::new(),
        depth: Vec::new(),
    };
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.is_empty() {
            continue;
        }
        let bad = |message: String| RgbdError::Pose {
            path: path.to_owned(),
            line: i + 1,
            message,
        };
        let [t_color, color, t_depth, depth] = words[..] else {
            return Err(bad(format!(
                "{} words, expected `t_color color_file t_depth depth_file`",
                words.len()
            )));
        };
        let time = |w: &str| {
            w.parse::<f64>()
                .ok()
                .filter(|t| t.is_finite())
                .ok_or_else(|| bad(format!("`{w}` is not a timestamp")))
        };
        let t = time(t_color)?;
        let t_depth = time(t_depth)?;
        if out.color_time_s.last().is_some_and(|&last| t < last) {
            return Err(bad("the colour timestamps go back in time".into()));
        }
        out.color_time_s.push(t);
        out.depth_time_s.push(t_depth);
        out.color.push(color.to_owned());
        out.depth.push(depth.to_owned());
    }
    Ok(out)
}

/// The poses of timestamped lines (`t tx ty tz qx qy qz qw`, `world_from_camera`)
/// interpolated at `times_s` (linearly, rotations by slerp) between the two lines
/// around each, at most `max_gap_s` apart; a frame without one gets the reason (a
/// motion-capture system loses the camera now and then: an error when the frame is
/// used, not when the dataset is read).
fn interpolate_poses(
    stamped: &[(f64, Isometry3)],
    times_s: &[f64],
    max_gap_s: f64,
) -> Vec<Result<Isometry3, String>> {
    times_s
        .iter()
        .map(|&time| {
            let after = stamped.partition_point(|(t, _)| *t < time);
            if let Some((t, pose)) = stamped.get(after)
                && *t == time
            {
                return Ok(*pose);
            }
            let (Some((t0, p0)), Some((t1, p1))) = (
                after.checked_sub(1).and_then(|i| stamped.get(i)),
                stamped.get(after),
            ) else {
                return Err(format!("no pose on both sides of its time {time:.6} s"));
            };
            if t1 - t0 > max_gap_s {
                return Err(format!(
                    "the poses around its time {time:.6} s are {:.3} s apart (max_gap_s = {max_gap_s})",
                    t1 - t0
                ));
            }
            let a = (time - t0) / (t1 - t0);
            let translation = p0.translation.lerp(p1.translation, a);
            let rotation = p0.rotation.slerp(p1.rotation, a).normalize();
            Ok(Isometry3::from_rotation_translation(rotation, translation))
        })
        .collect()
}

/// Timestamped lines `t tx ty tz qx qy qz qw` (`world_from_camera`), in increasing time.
fn read_stamped_poses(path: &Path) -> Result<Vec<(f64, Isometry3)>, RgbdError> {
    let mut stamped: Vec<(f64, Isometry3)> = Vec::new();
    for (line, n) in number_lines(path)? {
        if n.len() != 8 {
            return Err(RgbdError::Pose {
                path: path.to_owned(),
                line,
                message: format!("{} numbers, expected `t tx ty tz qx qy qz qw`", n.len()),
            });
        }
        let q = DQuat::from_xyzw(n[4], n[5], n[6], n[7]);
        let t = DVec3::new(n[1], n[2], n[3]);
        let norm = q.length();
        if !(n[0].is_finite() && t.is_finite() && norm.is_finite() && (norm - 1.0).abs() < 0.05) {
            return Err(RgbdError::Pose {
                path: path.to_owned(),
                line,
                message: format!("not a timestamped pose (quaternion norm {norm})"),
            });
        }
        if stamped.last().is_some_and(|(last, _)| n[0] <= *last) {
            return Err(RgbdError::Pose {
                path: path.to_owned(),
                line,
                message: "the timestamps do not increase".into(),
            });
        }
        stamped.push((n[0], Isometry3::from_rotation_translation(q.normalize(), t)));
    }
    Ok(stamped)
}

/// A described folder of RGB-D frames.
#[derive(Clone, Debug)]
pub struct RgbdDataset {
    root: PathBuf,
    first: u64,
    last: u64,
    pictures: Pictures,
    depth_scale_m: f64,
    invalid_depth: Vec<u16>,
    sensor: Sensor,
    /// `world_from_depth` of every frame, `first..=last`, or why a frame has none.
    world_from_depth: Vec<Result<Isometry3, String>>,
    /// `world_from_color` of every frame when the colour pictures were not taken with
    /// the depth pictures (timestamped poses), else `None`: through the sensor.
    world_from_color: Option<Vec<Result<Isometry3, String>>>,
    /// The pose file (in errors).
    poses_path: PathBuf,
}

/// Most frames a dataset may list.
pub const MAX_FRAMES: u64 = 1_000_000;

/// `pattern` with its `{}` or `{:0N}` replaced by `number`.
pub fn frame_path(pattern: &str, number: u64) -> Result<String, RgbdError> {
    let bad = || RgbdError::Parameter {
        name: "pattern",
        message: format!("`{pattern}` needs one `{{}}` or `{{:0N}}` for the frame number"),
    };
    let open = pattern.find('{').ok_or_else(bad)?;
    let close = open + pattern[open..].find('}').ok_or_else(bad)?;
    let spec = &pattern[open + 1..close];
    let text = match spec {
        "" => number.to_string(),
        _ => {
            let width: usize = spec
                .strip_prefix(":0")
                .and_then(|w| w.parse().ok())
                .filter(|&w| w <= 20)
                .ok_or_else(bad)?;
            format!("{number:0width$}")
        }
    };
    Ok(format!(
        "{}{text}{}",
        &pattern[..open],
        &pattern[close + 1..]
    ))
}

/// The rotation nearest to `m` (its polar factor, by Newton's iteration), or `None` if
/// `m` is farther than `tolerance` (largest element of `mᵀm − I`) from a rotation.
pub fn nearest_rotation(m: DMat3, tolerance: f64) -> Option<DMat3> {
    let gram = m.transpose() * m - DMat3::IDENTITY;
    let off = gram
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    if !(off <= tolerance) || !(m.determinant() > 0.0) {
        return None;
    }
    let mut r = m;
    for _ in 0..20 {
        let next = 0.5 * (r + r.inverse().transpose());
        let change = (next - r)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()));
        r = next;
        if change < 1e-15 {
            break;
        }
    }
    Some(r)
}

/// A rigid transform from 3 rows of `[R | t]`, the rotation re-orthonormalised.
pub fn isometry_from_rows(rows: [[f64; 4]; 3]) -> Option<Isometry3> {
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let m = DMat3::from_cols_array_2d(&[
        [rows[0][0], rows[1][0], rows[2][0]],
        [rows[0][1], rows[1][1], rows[2][1]],
        [rows[0][2], rows[1][2], rows[2][2]],
    ]);
    let r = nearest_rotation(m, 0.05)?;
    Some(Isometry3::from_rotation_translation(
        DQuat::from_mat3(&r),
        DVec3::new(rows[0][3], rows[1][3], rows[2][3]),
    ))
}

/// The numbers of a text file, line by line (`#` starts a comment), with their line
/// numbers; empty lines skipped.
fn number_lines(path: &Path) -> Result<Vec<(usize, Vec<f64>)>, RgbdError> {
    let text = read_text(path)?;
    let mut lines = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let numbers: Result<Vec<f64>, _> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(str::parse::<f64>)
            .collect();
        let numbers = numbers.map_err(|e| RgbdError::Pose {
            path: path.to_owned(),
            line: i + 1,
            message: format!("not a number ({e})"),
        })?;
        if !numbers.is_empty() {
            lines.push((i + 1, numbers));
        }
    }
    Ok(lines)
}

/// A text file of at most 64 MiB.
fn read_text(path: &Path) -> Result<String, RgbdError> {
    let io = |source| RgbdError::Io {
        path: path.to_owned(),
        source,
    };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > 64 << 20 {
        return Err(RgbdError::Pose {
            path: path.to_owned(),
            line: 0,
            message: format!("{size} bytes is too large for a pose file"),
        });
    }
    std::fs::read_to_string(path).map_err(io)
}

/// The `world_from_camera` matrices (16 or 12 numbers each, row-major) of one file.
fn read_matrices(path: &Path) -> Result<Vec<Isometry3>, RgbdError> {
    let numbers: Vec<f64> = number_lines(path)?
        .into_iter()
        .flat_map(|(_, n)| n)
        .collect();
    let per = if numbers.len().is_multiple_of(16) {
        16
    } else {
        12
    };
    if numbers.is_empty() || !numbers.len().is_multiple_of(per) {
        return Err(RgbdError::Pose {
            path: path.to_owned(),
            line: 0,
            message: format!(
                "{} numbers: not a whole number of 4×4 (or 3×4) matrices",
                numbers.len()
            ),
        });
    }
    numbers
        .chunks_exact(per)
        .enumerate()
        .map(|(i, m)| {
            if per == 16 && m[12..16] != [0.0, 0.0, 0.0, 1.0] {
                return Err(RgbdError::Pose {
                    path: path.to_owned(),
                    line: 0,
                    message: format!("matrix {i}'s last row is not 0 0 0 1"),
                });
            }
            let row = |r: usize| [m[4 * r], m[4 * r + 1], m[4 * r + 2], m[4 * r + 3]];
            isometry_from_rows([row(0), row(1), row(2)]).ok_or_else(|| RgbdError::Pose {
                path: path.to_owned(),
                line: 0,
                message: format!("matrix {i} is not a rigid transform (or not finite)"),
            })
        })
        .collect()
}

/// Poses written one per line, `tx ty tz qx qy qz qw` (or TUM's with a timestamp first).
fn read_pose_lines(path: &Path) -> Result<Vec<Isometry3>, RgbdError> {
    number_lines(path)?
        .into_iter()
        .map(|(line, n)| {
            let v = match n.len() {
                7 => &n[..],
                8 => &n[1..],
                k => {
                    return Err(RgbdError::Pose {
                        path: path.to_owned(),
                        line,
                        message: format!(
                            "{k} numbers, expected `tx ty tz qx qy qz qw` (7) or a timestamp and those (8)"
                        ),
                    });
                }
            };
            let q = DQuat::from_xyzw(v[3], v[4], v[5], v[6]);
            let t = DVec3::new(v[0], v[1], v[2]);
            let norm = q.length();
            if !(t.is_finite() && norm.is_finite() && (norm - 1.0).abs() < 0.05) {
                return Err(RgbdError::Pose {
                    path: path.to_owned(),
                    line,
                    message: format!("not a pose (quaternion norm {norm})"),
                });
            }
            Ok(Isometry3::from_rotation_translation(q, t))
        })
        .collect()
}

/// Poses every frame has.
fn all_ok(poses: Vec<Isometry3>) -> Vec<Result<Isometry3, String>> {
    poses.into_iter().map(Ok).collect()
}

/// Poses in COLMAP's layout (`NAME qw qx qy qz tx ty tz ...`, `camera_from_world`)
/// of the frames `first..=last`, matched by `name` (a frame pattern); lines of other
/// names are skipped; translations multiplied by `scale`. Returns `world_from_camera`,
/// or the first frame without a line.
fn read_colmap(
    path: &Path,
    name: &str,
    scale: f64,
    first: u64,
    last: u64,
) -> Result<Vec<Isometry3>, RgbdError> {
    let bad = |line: usize, message: String| RgbdError::Pose {
        path: path.to_owned(),
        line,
        message,
    };
    let count = (last - first + 1) as usize;
    let mut by_name = std::collections::HashMap::with_capacity(count);
    for k in first..=last {
        by_name.insert(frame_path(name, k)?, (k - first) as usize);
    }
    let mut poses: Vec<Option<Isometry3>> = vec![None; count];
    let text = read_text(path)?;
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let mut words = line.split_whitespace();
        let Some(slot) = words.next().and_then(|w| by_name.get(w)) else {
            continue;
        };
        let v: Vec<f64> = words
            .take(7)
            .map(str::parse::<f64>)
            .collect::<Result<_, _>>()
            .map_err(|e| bad(i + 1, format!("not a number ({e})")))?;
        if v.len() < 7 {
            return Err(bad(
                i + 1,
                format!(
                    "{} numbers after the name, expected `qw qx qy qz tx ty tz`",
                    v.len()
                ),
            ));
        }
        let q = DQuat::from_xyzw(v[1], v[2], v[3], v[0]);
        let t = DVec3::new(v[4], v[5], v[6]) * scale;
        let norm = q.length();
        if !(t.is_finite() && norm.is_finite() && (norm - 1.0).abs() < 0.05) {
            return Err(bad(i + 1, format!("not a pose (quaternion norm {norm})")));
        }
        if poses[*slot].is_some() {
            return Err(bad(i + 1, "a second pose of the same picture".into()));
        }
        let camera_from_world = Isometry3::from_rotation_translation(q.normalize(), t);
        poses[*slot] = Some(camera_from_world.inverse());
    }
    poses
        .into_iter()
        .enumerate()
        .map(|(k, p)| {
            p.ok_or_else(|| RgbdError::MissingPose {
                frame: first + k as u64,
                path: path.to_owned(),
                available: format!(
                    "no line named `{}`",
                    frame_path(name, first + k as u64).unwrap_or_default()
                ),
            })
        })
        .collect()
}

impl RgbdDataset {
    /// Read a dataset description (`description`, TOML) of the frames under
    /// `data_dir`, with every pose (checked now, so that a bad pose file fails before
    /// any work).
    pub fn load(
        description: impl AsRef<Path>,
        data_dir: impl AsRef<Path>,
    ) -> Result<Self, RgbdError> {
        let description = description.as_ref();
        let root = data_dir.as_ref().to_owned();
        let bad = |message: String| RgbdError::Dataset {
            path: description.to_owned(),
            message,
        };
        let text = read_text(description)?;
        let file: DatasetFile = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let [first, last] = file.frames;
        if last < first || last - first >= MAX_FRAMES {
            return Err(bad(format!(
                "frames = [{first}, {last}]: the last must follow the first, at most {MAX_FRAMES} frames"
            )));
        }
        let count = (last - first + 1) as usize;
        let (pictures, times_s) = match (&file.associations, &file.color, &file.depth) {
            (Some(path), None, None) => {
                let listed = read_associations(&root.join(path))?;
                if listed.color.len() < count + first as usize {
                    return Err(bad(format!(
                        "frames = [{first}, {last}] but {path} lists {} frames",
                        listed.color.len()
                    )));
                }
                let range = first as usize..=last as usize;
                (
                    Pictures::Listed {
                        color: listed.color[range.clone()].to_vec(),
                        depth: listed.depth[range.clone()].to_vec(),
                    },
                    Some((
                        listed.color_time_s[range.clone()].to_vec(),
                        listed.depth_time_s[range].to_vec(),
                    )),
                )
            }
            (None, Some(color), Some(depth)) => {
                for pattern in [color, depth] {
                    frame_path(pattern, first).map_err(|e| bad(e.to_string()))?;
                }
                (
                    Pictures::Patterns {
                        color: color.clone(),
                        depth: depth.clone(),
                    },
                    None,
                )
            }
            _ => {
                return Err(bad(
                    "give either `color` and `depth` (patterns) or `associations`".into(),
                ));
            }
        };
        if !(file.depth_scale_m > 0.0 && file.depth_scale_m.is_finite()) {
            return Err(bad(format!(
                "depth_scale_m must be > 0, got {}",
                file.depth_scale_m
            )));
        }
        let here = description.parent().unwrap_or(Path::new("."));
        let color_camera = Camera::load_toml(here.join(&file.color_camera))?;
        let depth_camera = match &file.depth_camera {
            Some(path) => Camera::load_toml(here.join(path))?,
            None => color_camera.clone(),
        };
        let color_from_depth = match file.color_from_depth {
            None => Isometry3::IDENTITY,
            Some(rows) => isometry_from_rows(rows)
                .ok_or_else(|| bad("color_from_depth is not a rigid transform".into()))?,
        };
        let sensor = Sensor {
            color_camera,
            depth_camera,
            color_from_depth,
        };
        let mut world_from_color = None;
        let (poses, of) = match &file.poses {
            PosesFile::Matrix { path, of } => {
                let poses = if path.contains('{') {
                    (first..=last)
                        .map(|k| {
                            let p = root.join(frame_path(path, k)?);
                            let m = read_matrices(&p)?;
                            match m[..] {
                                [one] => Ok(one),
                                _ => Err(RgbdError::Pose {
                                    path: p,
                                    line: 0,
                                    message: format!("{} matrices, expected one", m.len()),
                                }),
                            }
                        })
                        .collect::<Result<Vec<_>, _>>()?
                } else {
                    read_matrices(&root.join(path))?
                };
                (all_ok(poses), *of)
            }
            PosesFile::Lines { path, of } => (all_ok(read_pose_lines(&root.join(path))?), *of),
            PosesFile::Colmap {
                path,
                of,
                name,
                scale,
            } => {
                frame_path(name, first).map_err(|e| bad(e.to_string()))?;
                if !(*scale > 0.0 && scale.is_finite()) {
                    return Err(bad(format!("[poses] scale must be > 0, got {scale}")));
                }
                (
                    all_ok(read_colmap(&root.join(path), name, *scale, first, last)?),
                    *of,
                )
            }
            PosesFile::Timestamped {
                path,
                of,
                max_gap_s,
            } => {
                let Some((color_times, depth_times)) = &times_s else {
                    return Err(bad(
                        "[poses] kind = \"timestamped\" needs the frames' timestamps: give `associations`"
                            .into(),
                    ));
                };
                if !(*max_gap_s > 0.0 && max_gap_s.is_finite()) {
                    return Err(bad(format!(
                        "[poses] max_gap_s must be > 0, got {max_gap_s}"
                    )));
                }
                // The depth camera's poses at the depth pictures' times, the colour
                // camera's at the colour pictures'.
                let stamped = read_stamped_poses(&root.join(path))?;
                let at_depth = interpolate_poses(&stamped, depth_times, *max_gap_s);
                let at_color = interpolate_poses(&stamped, color_times, *max_gap_s);
                let color_camera_poses = at_color
                    .into_iter()
                    .map(|p| {
                        p.map(|p| match of {
                            PoseOf::Color => p,
                            PoseOf::Depth => sensor.world_from_color(&p),
                        })
                    })
                    .collect();
                world_from_color = Some(color_camera_poses);
                (at_depth, *of)
            }
        };
        let path = match &file.poses {
            PosesFile::Matrix { path, .. }
            | PosesFile::Lines { path, .. }
            | PosesFile::Colmap { path, .. }
            | PosesFile::Timestamped { path, .. } => root.join(path),
        };
        if poses.len() < count {
            return Err(RgbdError::MissingPose {
                frame: first + poses.len() as u64,
                path,
                available: format!("{} poses for frames {first}..={last}", poses.len()),
            });
        }
        let world_from_depth = poses
            .into_iter()
            .take(count)
            .map(|p| {
                p.map(|p| match of {
                    PoseOf::Depth => p,
                    PoseOf::Color => sensor.world_from_depth(&p),
                })
            })
            .collect();
        Ok(Self {
            root,
            first,
            last,
            pictures,
            depth_scale_m: file.depth_scale_m,
            invalid_depth: file.invalid_depth,
            sensor,
            world_from_depth,
            world_from_color,
            poses_path: path,
        })
    }

    /// The first and last frame numbers.
    pub fn frames(&self) -> [u64; 2] {
        [self.first, self.last]
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// The data folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    fn index(&self, frame: u64) -> Result<usize, RgbdError> {
        if frame < self.first || frame > self.last {
            return Err(RgbdError::MissingPose {
                frame,
                path: self.root.clone(),
                available: format!("frames {}..={}", self.first, self.last),
            });
        }
        Ok((frame - self.first) as usize)
    }

    /// `world_from_depth` of a frame (an error for a frame the poses leave out).
    pub fn world_from_depth(&self, frame: u64) -> Result<Isometry3, RgbdError> {
        self.world_from_depth[self.index(frame)?]
            .clone()
            .map_err(|reason| RgbdError::MissingPose {
                frame,
                path: self.poses_path.clone(),
                available: reason,
            })
    }

    /// Whether a frame has its poses (every frame has them but where timestamped poses
    /// leave a gap).
    pub fn has_pose(&self, frame: u64) -> bool {
        self.world_from_depth(frame).is_ok() && self.world_from_color(frame).is_ok()
    }

    /// `world_from_color` of a frame: where its colour picture was taken (with
    /// timestamped poses, at the colour picture's own time).
    pub fn world_from_color(&self, frame: u64) -> Result<Isometry3, RgbdError> {
        match &self.world_from_color {
            None => Ok(self.sensor.world_from_color(&self.world_from_depth(frame)?)),
            Some(poses) => {
                poses[self.index(frame)?]
                    .clone()
                    .map_err(|reason| RgbdError::MissingPose {
                        frame,
                        path: self.poses_path.clone(),
                        available: reason,
                    })
            }
        }
    }

    /// The colour picture's file of a frame.
    pub fn color_path(&self, frame: u64) -> Result<PathBuf, RgbdError> {
        let k = self.index(frame)?;
        Ok(self.root.join(match &self.pictures {
            Pictures::Patterns { color, .. } => frame_path(color, frame)?,
            Pictures::Listed { color, .. } => color[k].clone(),
        }))
    }

    /// The depth picture's file of a frame.
    pub fn depth_path(&self, frame: u64) -> Result<PathBuf, RgbdError> {
        let k = self.index(frame)?;
        Ok(self.root.join(match &self.pictures {
            Pictures::Patterns { depth, .. } => frame_path(depth, frame)?,
            Pictures::Listed { depth, .. } => depth[k].clone(),
        }))
    }

    /// Read a frame's depth and colour pictures, checked against the sensor's sizes.
    pub fn read(&self, frame: u64) -> Result<(DepthImage, ColorImage), RgbdError> {
        let depth = self.read_depth(frame)?;
        let color_path = self.color_path(frame)?;
        let color = ColorImage::load(&color_path)?;
        check_size(
            "colour picture",
            color_path,
            (color.width(), color.height()),
            &self.sensor.color_camera,
        )?;
        Ok((depth, color))
    }

    /// Read a frame's depth picture, checked against the depth camera's size.
    pub fn read_depth(&self, frame: u64) -> Result<DepthImage, RgbdError> {
        let depth_path = self.depth_path(frame)?;
        let depth = DepthImage::load(&depth_path, self.depth_scale_m, &self.invalid_depth)?;
        check_size(
            "depth picture",
            depth_path,
            (depth.width(), depth.height()),
            &self.sensor.depth_camera,
        )?;
        Ok(depth)
    }
}

impl RgbdDataset {
    /// Fuse `frames` (frame numbers, in this order) into a coloured cloud with
    /// `options`; `progress(done, total)` is called after each frame. The pictures are
    /// decoded on rayon's threads a few frames ahead; they are added in order, so the
    /// cloud does not depend on the thread count.
    pub fn fuse(
        &self,
        frames: &[u64],
        options: FuseOptions,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<(splat::PointCloud, FuseReport), RgbdError> {
        let mut fusion = Fusion::new(self.sensor.clone(), options)?;
        let mut report = FuseReport::default();
        let batch = 2 * rayon::current_num_threads().max(1);
        let mut done = 0;
        for chunk in frames.chunks(batch) {
            use rayon::prelude::*;
            let pictures: Vec<Result<(DepthImage, ColorImage), RgbdError>> =
                chunk.par_iter().map(|&k| self.read(k)).collect();
            for (&k, read) in chunk.iter().zip(pictures) {
                let (depth, color) = read?;
                let world_from_depth = self.world_from_depth(k)?;
                let stats = match &self.world_from_color {
                    None => fusion.add(&depth, &color, &world_from_depth)?,
                    Some(_) => fusion.add_at(
                        &depth,
                        &color,
                        &world_from_depth,
                        &self.world_from_color(k)?,
                    )?,
                };
                report.add(stats);
                done += 1;
                progress(done, frames.len());
            }
        }
        report.voxels = fusion.voxel_count();
        let cloud = fusion.cloud()?;
        report.points = cloud.len();
        Ok((cloud, report))
    }
}

/// What a whole fusion did: the sums of its frames' [`FrameStats`], the voxels filled
/// and the points kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FuseReport {
    /// Frames fused.
    pub frames: usize,
    /// The frames' statistics, summed.
    pub pixels: FrameStats,
    /// Voxels seen by any frame.
    pub voxels: usize,
    /// Points of the cloud (voxels seen by enough frames).
    pub points: usize,
}

impl FuseReport {
    fn add(&mut self, stats: FrameStats) {
        self.frames += 1;
        let p = &mut self.pixels;
        p.measured += stats.measured;
        p.flying += stats.flying;
        p.outside_color += stats.outside_color;
        p.occluded += stats.occluded;
        p.fused += stats.fused;
    }
}
