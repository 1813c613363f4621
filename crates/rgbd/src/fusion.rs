//! [`Fusion`]: RGB-D frames accumulated in a voxel grid, then a coloured
//! [`splat::PointCloud`].
//!
//! Every measured depth pixel that is not a *flying pixel* (a pixel on a depth
//! discontinuity, whose depth mixes the two surfaces) becomes a point of the depth
//! camera's frame; the colour camera sees it through `color_from_depth` and gives it the
//! bilinear colour of the pixel it falls on, unless a nearer point of the same frame
//! falls there (the two sensors are apart, so the colour camera does not see every
//! point the depth camera sees). The point, in the world (`world_from_depth`), adds its
//! position and colour to its voxel. A voxel becomes one point of the cloud — the mean
//! of its points, with their mean colour — if at least `min_frames` frames saw it.
//!
//! Memory is one voxel entry per occupied voxel (bounded by
//! [`FuseOptions::max_voxels`]), whatever the number of frames; the result does not
//! depend on the order in which voxels were created (the cloud is built from the voxels
//! sorted by their grid coordinates), only on the frames and their order.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::DVec3;
use splat::PointCloud;
use ucm::{Camera, Isometry3};

use crate::error::{check_pose, check_size};
use crate::{ColorImage, DepthImage, RgbdError};

/// The two cameras of an RGB-D sensor and how they sit.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// The colour camera (its pictures' size).
    pub color_camera: Camera,
    /// The depth camera (its pictures' size). Its depth is along its optical axis `Z`.
    pub depth_camera: Camera,
    /// Points of the depth camera's frame into the colour camera's frame (identity for
    /// registered pictures).
    pub color_from_depth: Isometry3,
}

impl Sensor {
    /// A sensor whose depth is registered to its colour pictures (one camera, one
    /// frame).
    pub fn registered(camera: Camera) -> Self {
        Self {
            depth_camera: camera.clone(),
            color_camera: camera,
            color_from_depth: Isometry3::IDENTITY,
        }
    }

    /// `world_from_color` of a frame whose depth camera is at `world_from_depth`.
    pub fn world_from_color(&self, world_from_depth: &Isometry3) -> Isometry3 {
        *world_from_depth * self.color_from_depth.inverse()
    }

    /// `world_from_depth` of a frame whose colour camera is at `world_from_color`.
    pub fn world_from_depth(&self, world_from_color: &Isometry3) -> Isometry3 {
        *world_from_color * self.color_from_depth
    }
}

/// Settings of the fusion.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FuseOptions {
    /// Edge of the voxels, metres: one point of the cloud per occupied voxel. Default
    /// 0.01.
    pub voxel_size_m: f64,
    /// A voxel is kept only if at least this many frames saw it (1: every voxel; more
    /// rejects the noise and the moving things of single frames). Default 2.
    pub min_frames: u32,
    /// Flying pixels: a depth pixel is dropped when one of its 8 neighbours' depths
    /// differs from its own by more than this fraction of it (`None`: keep every
    /// pixel). Default 0.03.
    pub flying_pixel_jump: Option<f32>,
    /// Depths kept, metres `[nearest, farthest]`. Default `[0.2, 6.0]` (a Kinect's
    /// useful range).
    pub depth_range_m: [f32; 2],
    /// The colour camera sees a point if no point of the same frame falls on its pixel
    /// nearer than this fraction of its range. Default 0.03.
    pub occlusion_tolerance: f32,
    /// Most voxels the fusion may hold ([`RgbdError::TooManyVoxels`] beyond): about 70
    /// bytes each. Default 30 000 000.
    pub max_voxels: usize,
}

impl Default for FuseOptions {
    fn default() -> Self {
        Self {
            voxel_size_m: 0.01,
            min_frames: 2,
            flying_pixel_jump: Some(0.03),
            depth_range_m: [0.2, 6.0],
            occlusion_tolerance: 0.03,
            max_voxels: 30_000_000,
        }
    }
}

impl FuseOptions {
    /// Check every field against its documented range.
    pub fn validate(&self) -> Result<(), RgbdError> {
        let bad = |name, message: String| Err(RgbdError::Parameter { name, message });
        if !(self.voxel_size_m >= 1e-4 && self.voxel_size_m <= 100.0) {
            return bad(
                "voxel_size_m",
                format!("must be in [1e-4, 100] m, got {}", self.voxel_size_m),
            );
        }
        if self.min_frames == 0 {
            return bad("min_frames", "must be >= 1".into());
        }
        if let Some(jump) = self.flying_pixel_jump
            && !(jump > 0.0 && jump.is_finite())
        {
            return bad("flying_pixel_jump", format!("must be > 0, got {jump}"));
        }
        let [near, far] = self.depth_range_m;
        if !(near >= 0.0 && far > near && far.is_finite()) {
            return bad(
                "depth_range_m",
                format!(
                    "must be [nearest, farthest] with 0 <= nearest < farthest, got {near}, {far}"
                ),
            );
        }
        if !(self.occlusion_tolerance >= 0.0 && self.occlusion_tolerance.is_finite()) {
            return bad(
                "occlusion_tolerance",
                format!("must be >= 0, got {}", self.occlusion_tolerance),
            );
        }
        if self.max_voxels == 0 {
            return bad("max_voxels", "must be >= 1".into());
        }
        Ok(())
    }
}

/// What one frame gave.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Depth pixels with a measurement in the depth range.
    pub measured: usize,
    /// Of those, dropped as flying pixels.
    pub flying: usize,
    /// Dropped as outside the colour picture (or behind the colour camera).
    pub outside_color: usize,
    /// Dropped as hidden from the colour camera by a nearer point.
    pub occluded: usize,
    /// Added to the voxels.
    pub fused: usize,
}

/// One voxel's sums.
#[derive(Clone, Copy, Debug, Default)]
struct Voxel {
    position_sum: DVec3,
    color_sum: [f32; 3],
    points: u32,
    frames: u32,
    /// The last frame that added a point (frame numbers start at 1).
    last_frame: u32,
}

/// A multiplicative hash of the voxel's three coordinates: fixed (no random seed), fast
/// on keys that are small integers.
#[derive(Default)]
struct VoxelHasher(u64);

impl Hasher for VoxelHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, value: u64) {
        self.0 = (self.0.rotate_left(21) ^ value).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }

    fn write_i32(&mut self, value: i32) {
        self.write_u64(u64::from(value as u32));
    }
}

type VoxelMap = HashMap<[i32; 3], Voxel, BuildHasherDefault<VoxelHasher>>;

/// The per-pixel rays of the depth camera (`(X/Z, Y/Z)`, NaN where the pixel does not
/// unproject in front of the camera) and per-frame buffers.
#[derive(Debug)]
struct Buffers {
    rays: Vec<[f32; 2]>,
    /// Per depth pixel: its point in the colour camera's frame and its colour pixel
    /// (row-major index), or `u32::MAX` when dropped.
    projected: Vec<(u32, [f32; 2], f32)>,
    /// Per colour pixel: the nearest range that falls on it in this frame.
    nearest: Vec<f32>,
}

/// The voxel grid being filled, frame after frame.
#[derive(Debug)]
pub struct Fusion {
    sensor: Sensor,
    options: FuseOptions,
    voxels: VoxelMap,
    frames: u32,
    buffers: Buffers,
}

impl std::fmt::Debug for VoxelHasher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("VoxelHasher")
    }
}

impl Fusion {
    /// An empty fusion of `sensor`'s frames.
    pub fn new(sensor: Sensor, options: FuseOptions) -> Result<Self, RgbdError> {
        options.validate()?;
        let depth = &sensor.depth_camera;
        let (w, h) = (depth.width() as usize, depth.height() as usize);
        let rays = (0..w * h)
            .map(|k| {
                let pixel = [(k % w) as f64, (k / w) as f64];
                match depth.unproject(pixel) {
                    Ok([x, y, z]) if z > 1e-9 => [(x / z) as f32, (y / z) as f32],
                    _ => [f32::NAN; 2],
                }
            })
            .collect();
        let color_pixels = sensor.color_camera.pixel_count();
        Ok(Self {
            buffers: Buffers {
                rays,
                projected: Vec::with_capacity(w * h),
                nearest: vec![f32::INFINITY; color_pixels],
            },
            sensor,
            options,
            voxels: VoxelMap::default(),
            frames: 0,
        })
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// Frames added so far.
    pub fn frame_count(&self) -> u32 {
        self.frames
    }

    /// Voxels occupied so far (by any number of frames).
    pub fn voxel_count(&self) -> usize {
        self.voxels.len()
    }

    /// Add a frame: its depth and colour pictures (of the sensor's cameras' sizes) and
    /// where its depth camera was (`world_from_depth`); the colour camera is where the
    /// sensor's `color_from_depth` puts it.
    pub fn add(
        &mut self,
        depth: &DepthImage,
        color: &ColorImage,
        world_from_depth: &Isometry3,
    ) -> Result<FrameStats, RgbdError> {
        let color_from_depth = self.sensor.color_from_depth;
        self.add_seen_from(depth, color, world_from_depth, color_from_depth)
    }

    /// As [`Fusion::add`], with the colour picture taken from `world_from_color`
    /// rather than through the sensor's `color_from_depth`: a moving camera whose depth
    /// and colour pictures are not simultaneous (TUM RGB-D's are up to 20 ms apart, a
    /// degree and more at its speeds). The depth camera's rays stay the sensor's.
    pub fn add_at(
        &mut self,
        depth: &DepthImage,
        color: &ColorImage,
        world_from_depth: &Isometry3,
        world_from_color: &Isometry3,
    ) -> Result<FrameStats, RgbdError> {
        check_pose("world_from_color", world_from_color)?;
        let color_from_depth = world_from_color.inverse() * *world_from_depth;
        self.add_seen_from(depth, color, world_from_depth, color_from_depth)
    }

    fn add_seen_from(
        &mut self,
        depth: &DepthImage,
        color: &ColorImage,
        world_from_depth: &Isometry3,
        color_from_depth: Isometry3,
    ) -> Result<FrameStats, RgbdError> {
        check_size(
            "depth picture",
            "<memory>".into(),
            (depth.width(), depth.height()),
            &self.sensor.depth_camera,
        )?;
        check_size(
            "colour picture",
            "<memory>".into(),
            (color.width(), color.height()),
            &self.sensor.color_camera,
        )?;
        // A value per pixel (the buffers are public fields, which a caller may resize).
        for (what, got, pixels) in [
            (
                "depth_m",
                depth.depth_m.len(),
                (depth.width(), depth.height()),
            ),
            ("rgb", color.rgb.len(), (color.width(), color.height())),
        ] {
            let expected = pixels.0 as usize * pixels.1 as usize;
            if got != expected {
                return Err(RgbdError::Length {
                    what,
                    got,
                    expected,
                });
            }
        }
        check_pose("world_from_depth", world_from_depth)?;
        let mut stats = FrameStats::default();
        let (w, h) = (depth.width() as usize, depth.height() as usize);
        let [near, far] = self.options.depth_range_m;
        let jump = self.options.flying_pixel_jump;
        let color_camera = &self.sensor.color_camera;
        let registered = color_from_depth == Isometry3::IDENTITY
            && self.sensor.depth_camera == self.sensor.color_camera;
        let (rotation, translation) = color_from_depth.to_f32();
        let Buffers {
            rays,
            projected,
            nearest,
        } = &mut self.buffers;
        projected.clear();
        let d = &depth.depth_m;
        for y in 0..h {
            for x in 0..w {
                let k = y * w + x;
                let z = d[k];
                if !(z >= near && z <= far) || z == 0.0 {
                    continue;
                }
                stats.measured += 1;
                if let Some(jump) = jump {
                    let limit = jump * z;
                    let mut flying = false;
                    for ny in y.saturating_sub(1)..(y + 2).min(h) {
                        for nx in x.saturating_sub(1)..(x + 2).min(w) {
                            let n = d[ny * w + nx];
                            if n > 0.0 && (n - z).abs() > limit {
                                flying = true;
                            }
                        }
                    }
                    if flying {
                        stats.flying += 1;
                        continue;
                    }
                }
                let [rx, ry] = rays[k];
                if rx.is_nan() {
                    stats.outside_color += 1;
                    continue;
                }
                let point = glam::Vec3::new(rx * z, ry * z, z);
                if registered {
                    if !color_camera.valid_pixels()[k] {
                        stats.outside_color += 1;
                        continue;
                    }
                    projected.push((k as u32, [x as f32, y as f32], point.length()));
                    continue;
                }
                let in_color = rotation * point + translation;
                match color_camera.project([in_color.x, in_color.y, in_color.z]) {
                    Ok(pixel) => {
                        let range = in_color.length();
                        let index = color_camera
                            .pixel_index(pixel)
                            .expect("a projection inside the region is inside the image");
                        if range < nearest[index] {
                            nearest[index] = range;
                        }
                        projected.push((k as u32, pixel, range));
                    }
                    Err(_) => stats.outside_color += 1,
                }
            }
        }
        self.frames += 1;
        let frame = self.frames;
        let size_m = self.options.voxel_size_m;
        let tolerance = 1.0 + self.options.occlusion_tolerance;
        let limit = self.options.max_voxels;
        for &(k, pixel, range) in projected.iter() {
            if !registered {
                let index = color_camera
                    .pixel_index(pixel)
                    .expect("kept projections are inside the image");
                if range > nearest[index] * tolerance {
                    stats.occluded += 1;
                    continue;
                }
            }
            let Some(rgb) = color.bilinear(pixel[0], pixel[1]) else {
                stats.outside_color += 1;
                continue;
            };
            let k = k as usize;
            let [rx, ry] = rays[k];
            let z = f64::from(d[k]);
            let in_depth = DVec3::new(f64::from(rx) * z, f64::from(ry) * z, z);
            let world = world_from_depth.transform_point(in_depth);
            let cell = (world / size_m).floor();
            if !(cell.abs().max_element() < f64::from(i32::MAX)) {
                return Err(RgbdError::Parameter {
                    name: "world_from_depth",
                    message: format!(
                        "frame {frame} puts a point at {world:?}, beyond the voxel grid's reach"
                    ),
                });
            }
            let key = [cell.x as i32, cell.y as i32, cell.z as i32];
            let full = self.voxels.len() >= limit;
            let voxel = match self.voxels.get_mut(&key) {
                Some(v) => v,
                None if full => return Err(RgbdError::TooManyVoxels { limit }),
                None => self.voxels.entry(key).or_default(),
            };
            voxel.position_sum += world;
            for (s, c) in voxel.color_sum.iter_mut().zip(rgb) {
                *s += c;
            }
            voxel.points += 1;
            if voxel.last_frame != frame {
                voxel.last_frame = frame;
                voxel.frames += 1;
            }
            stats.fused += 1;
        }
        if !registered {
            for &(_, pixel, _) in projected.iter() {
                if let Some(index) = color_camera.pixel_index(pixel) {
                    nearest[index] = f32::INFINITY;
                }
            }
        }
        Ok(stats)
    }

    /// The coloured cloud of the voxels seen by at least `min_frames` frames: per voxel
    /// the mean of its points and their mean colour (the intensity its luminance), the
    /// points spaced by a voxel.
    pub fn cloud(&self) -> Result<PointCloud, RgbdError> {
        let min_frames = self.options.min_frames;
        let mut kept: Vec<(&[i32; 3], &Voxel)> = self
            .voxels
            .iter()
            .filter(|(_, v)| v.frames >= min_frames)
            .collect();
        if kept.is_empty() {
            return Err(RgbdError::Empty {
                min_frames,
                voxels: self.voxels.len(),
            });
        }
        kept.sort_unstable_by_key(|(key, _)| **key);
        let positions: Vec<DVec3> = kept
            .iter()
            .map(|(_, v)| v.position_sum / f64::from(v.points))
            .collect();
        let colors: Vec<[u8; 3]> = kept
            .iter()
            .map(|(_, v)| {
                v.color_sum
                    .map(|s| (s / v.points as f32).round().clamp(0.0, 255.0) as u8)
            })
            .collect();
        let intensities: Vec<f32> = kept
            .iter()
            .map(|(_, v)| {
                let [r, g, b] = v.color_sum.map(|s| s / v.points as f32);
                (0.2126 * r + 0.7152 * g + 0.0722 * b) / 255.0
            })
            .collect();
        let origin = positions
            .iter()
            .fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p))
            .floor();
        Ok(PointCloud::from_points(
            origin,
            &positions,
            &intensities,
            Some(colors),
            Some(self.options.voxel_size_m as f32),
        )?)
    }
}
