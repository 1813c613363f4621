//! The CPU splat renderer.
//!
//! Three passes over the visible points (after culling and level of detail):
//!
//! 1. **Depth.** Each point is projected with the camera model and covers a square
//!    splat whose size follows the model's local magnification
//!    (`spacing · α/D · max((ρ + ξZ)/D, 1)` pixels, the larger of the radial and
//!    tangential magnifications of the UCM at the point), so that surfaces close to the
//!    camera stay hole-free. Every covered pixel keeps the minimum of the 64-bit key
//!    `(range bits << 32) | point index`: exact, and independent of the order in
//!    which points are drawn, so the result does not depend on the thread count
//!    (Schütz, Kerbl, Wimmer 2021).
//! 2. **Accumulation (anti-aliasing).** Each point adds its intensity to the pixels it
//!    covers where its range is within `depth_band` (relative) of the nearest one.
//!    Sums are fixed-point integers (16-bit intensities), so they too are independent of
//!    the order of addition.
//! 3. **Resolve.** Intensity and range are the means of the accepted samples;
//!    pixels with no sample inside the valid region are sky (`background`, infinite
//!    range), pixels outside it are masked.
//!
//! **Culling and level of detail.** Cells of the cloud entirely outside the camera's
//! field (the range of angles off the optical axis that its valid pixels see) are
//! skipped. Where a cell's points would be denser than `lod_spacing_px` on the image,
//! only a prefix of the cell (a uniform random subsample, see [`crate::PointCloud`]) is
//! drawn, with proportionally larger splats. The subsample size varies with the pose
//! one point at a time, so the rendering stays (almost) continuous in the pose.
//!
//! Precision: `f32` throughout the per-point loop (positions relative to the cloud's
//! origin, ranges of at most a few hundred metres).

use std::sync::atomic::{AtomicU64, Ordering};

use glam::{Mat3, Vec3};
use rayon::prelude::*;
use ucm::{Camera, Isometry3};

use crate::{Frame, PixelStatus, PointCloud, SplatError};

/// Renderer settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Intensity of pixels of the valid region where no point is seen (the sky), in
    /// `[0, 1]`. Default 0.85: a bright, overcast sky.
    pub background: f32,
    /// Relative depth band of the anti-aliasing: samples within `(1 + depth_band)` of
    /// the nearest range of a pixel are averaged. Default 0.02.
    pub depth_band: f32,
    /// Level of detail: draw cells no denser than this many pixels between
    /// neighbouring points on the image (`None`: draw every point). Default `Some(0.5)`,
    /// about four samples per pixel.
    pub lod_spacing_px: Option<f32>,
    /// Splat size factor over the nominal footprint (≥ 1 fills the gaps that the
    /// random jitter of a real sampling leaves). Default 1.5.
    pub splat_scale: f32,
    /// Largest splat half-width, pixels (bounds the cost of points very close to the
    /// camera). Default 8.
    pub max_splat_radius_px: u32,
    /// Draw with rayon when the pool has more than one thread. The output is the same
    /// either way. Default true.
    pub parallel: bool,
    /// Fill isolated holes: a pixel of the valid region with no sample but at least 6
    /// of its 8 neighbours hit takes their mean intensity and nearest range (the gaps a
    /// random subsample or a jittered sampling leaves). Default true.
    pub fill_holes: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            background: 0.85,
            depth_band: 0.02,
            lod_spacing_px: Some(0.5),
            splat_scale: 1.5,
            max_splat_radius_px: 8,
            parallel: true,
            fill_holes: true,
        }
    }
}

impl RenderOptions {
    fn validate(&self) -> Result<(), SplatError> {
        let bad = |name, message: String| Err(SplatError::Parameter { name, message });
        if !(0.0..=1.0).contains(&self.background) {
            return bad(
                "background",
                format!("must be in [0, 1], got {}", self.background),
            );
        }
        if !(self.depth_band >= 0.0 && self.depth_band.is_finite()) {
            return bad(
                "depth_band",
                format!("must be >= 0, got {}", self.depth_band),
            );
        }
        if let Some(s) = self.lod_spacing_px
            && !(s > 0.0 && s.is_finite())
        {
            return bad("lod_spacing_px", format!("must be > 0, got {s}"));
        }
        if !(self.splat_scale > 0.0 && self.splat_scale.is_finite()) {
            return bad(
                "splat_scale",
                format!("must be > 0, got {}", self.splat_scale),
            );
        }
        Ok(())
    }
}

/// What one rendering did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Cells that passed culling.
    pub cells_drawn: usize,
    /// Points drawn (after level of detail).
    pub points_drawn: usize,
    /// Pixels with a rendered point.
    pub pixels_hit: usize,
}

#[derive(Clone, Copy, Debug)]
struct DrawCell {
    start: u32,
    count: u32,
    spacing_m: f32,
}

/// The per-point constants of a rendering.
#[derive(Clone, Copy)]
struct View {
    rotation: Mat3,
    translation: Vec3,
    alpha: f32,
    xi: f32,
    width: i32,
    height: i32,
    splat_scale: f32,
    max_radius: i32,
    depth_band: f32,
}

/// A renderer for one camera, owning its buffers (no allocation per frame once warm).
#[derive(Debug)]
pub struct Renderer {
    camera: Camera,
    options: RenderOptions,
    depth: Vec<AtomicU64>,
    accum: Vec<AtomicU64>,
    range_sum: Vec<AtomicU64>,
    draw: Vec<DrawCell>,
    status: Vec<PixelStatus>,
    theta_min: f32,
    theta_max: f32,
}

const EMPTY: u64 = u64::MAX;
const COUNT_BITS: u32 = 24;
const COUNT_MASK: u64 = (1 << COUNT_BITS) - 1;
const INTENSITY_SCALE: f32 = 65535.0;
/// Fixed-point scale of the range sums (1/4096 m).
const RANGE_SCALE: f32 = 4096.0;

impl Renderer {
    /// A renderer for `camera`. Fails on invalid options.
    pub fn new(camera: Camera, options: RenderOptions) -> Result<Self, SplatError> {
        options.validate()?;
        let n = camera.pixel_count();
        // The range of angles off the optical axis seen by the valid pixels, widened by
        // a pixel's angle.
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let w = camera.width() as usize;
        for (k, _) in camera
            .valid_pixels()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
        {
            let pixel = [(k % w) as f64, (k / w) as f64];
            if let Ok(ray) = camera.unproject(pixel) {
                let theta = ray[2].clamp(-1.0, 1.0).acos();
                lo = lo.min(theta);
                hi = hi.max(theta);
            }
        }
        let i = camera.intrinsics();
        let margin = 2.0 / i.alpha_u.min(i.alpha_v);
        let (theta_min, theta_max) = if lo <= hi {
            (
                (lo - margin).max(0.0) as f32,
                (hi + margin).min(std::f64::consts::PI) as f32,
            )
        } else {
            (0.0, std::f32::consts::PI)
        };
        Ok(Self {
            camera,
            options,
            depth: (0..n).map(|_| AtomicU64::new(EMPTY)).collect(),
            accum: (0..n).map(|_| AtomicU64::new(0)).collect(),
            range_sum: (0..n).map(|_| AtomicU64::new(0)).collect(),
            draw: Vec::new(),
            status: vec![PixelStatus::Sky; n],
            theta_min,
            theta_max,
        })
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The options.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// Magnification (pixels per radian, the larger of radial and tangential) at an
    /// angle `θ` off the optical axis.
    fn magnification(&self, theta: f32) -> f32 {
        let i = self.camera.intrinsics();
        let alpha = i.alpha_u.max(i.alpha_v) as f32;
        let xi = i.xi as f32;
        let c = theta.cos();
        let d = (c + xi).max(1e-3);
        alpha * ((1.0 + xi * c) / (d * d)).max(1.0 / d)
    }

    /// Render `cloud` seen from `camera_from_world` into `frame`.
    pub fn render(
        &mut self,
        cloud: &PointCloud,
        camera_from_world: &Isometry3,
        frame: &mut Frame,
    ) -> Result<RenderStats, SplatError> {
        if frame.width() != self.camera.width() || frame.height() != self.camera.height() {
            return Err(SplatError::FrameSize {
                frame_width: frame.width(),
                frame_height: frame.height(),
                width: self.camera.width(),
                height: self.camera.height(),
            });
        }
        if !camera_from_world.is_finite() {
            return Err(SplatError::NonFinitePose);
        }
        // Points are relative to the cloud's origin: fold it into the translation (f64).
        let translation = camera_from_world.transform_point(cloud.origin());
        let (rotation, _) = camera_from_world.to_f32();
        let i = self.camera.intrinsics();
        let view = View {
            rotation,
            translation: translation.as_vec3(),
            alpha: i.alpha_u.max(i.alpha_v) as f32,
            xi: i.xi as f32,
            width: self.camera.width() as i32,
            height: self.camera.height() as i32,
            splat_scale: self.options.splat_scale,
            max_radius: self.options.max_splat_radius_px as i32,
            depth_band: self.options.depth_band,
        };

        self.select_cells(cloud, &view);
        let points_drawn: usize = self.draw.iter().map(|c| c.count as usize).sum();

        for d in &self.depth {
            d.store(EMPTY, Ordering::Relaxed);
        }
        for a in self.accum.iter().chain(&self.range_sum) {
            a.store(0, Ordering::Relaxed);
        }
        let parallel = self.options.parallel && rayon::current_num_threads() > 1;
        let points = cloud.points();
        let camera = &self.camera;
        let depth = &self.depth[..];
        let accum = Accum {
            sums: &self.accum[..],
            ranges: &self.range_sum[..],
        };
        if parallel {
            // Chunks of cells of similar work; atomics make the result order-free.
            let chunks = chunk_cells(&self.draw, 16_384);
            chunks.par_iter().for_each(|cells| {
                for cell in *cells {
                    draw_cell(
                        points,
                        cell,
                        &view,
                        camera,
                        depth,
                        &accum,
                        Pass::Depth,
                        true,
                    );
                }
            });
            chunks.par_iter().for_each(|cells| {
                for cell in *cells {
                    draw_cell(
                        points,
                        cell,
                        &view,
                        camera,
                        depth,
                        &accum,
                        Pass::Accumulate,
                        true,
                    );
                }
            });
        } else {
            for pass in [Pass::Depth, Pass::Accumulate] {
                for cell in &self.draw {
                    draw_cell(points, cell, &view, camera, depth, &accum, pass, false);
                }
            }
        }

        // Resolve.
        let background = self.options.background;
        let valid = self.camera.valid_pixels();
        let mut pixels_hit = 0;
        for k in 0..valid.len() {
            let key = self.depth[k].load(Ordering::Relaxed);
            let range_sum = self.range_sum[k].load(Ordering::Relaxed);
            let sums = self.accum[k].load(Ordering::Relaxed);
            let count = sums & COUNT_MASK;
            if !valid[k] {
                frame.intensity[k] = 0.0;
                frame.range_m[k] = f32::NAN;
                frame.status[k] = PixelStatus::Masked;
            } else if key == EMPTY || count == 0 {
                frame.intensity[k] = background;
                frame.range_m[k] = f32::INFINITY;
                frame.status[k] = PixelStatus::Sky;
            } else {
                let sum = (sums >> COUNT_BITS) as f64;
                frame.intensity[k] = (sum / (count as f64 * f64::from(INTENSITY_SCALE))) as f32;
                frame.range_m[k] =
                    (range_sum as f64 / (count as f64 * f64::from(RANGE_SCALE))) as f32;
                frame.status[k] = PixelStatus::Hit;
                pixels_hit += 1;
            }
        }
        if self.options.fill_holes {
            pixels_hit += self.fill_holes(frame);
        }
        Ok(RenderStats {
            cells_drawn: self.draw.len(),
            points_drawn,
            pixels_hit,
        })
    }

    /// Fill isolated sky pixels surrounded by hits (decided on the statuses before
    /// filling, so the result does not depend on the scan order). Returns the number
    /// of pixels filled.
    fn fill_holes(&mut self, frame: &mut Frame) -> usize {
        self.status.copy_from_slice(&frame.status);
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let mut filled = 0;
        for j in 1..h.saturating_sub(1) {
            for i in 1..w - 1 {
                let k = j * w + i;
                if self.status[k] != PixelStatus::Sky {
                    continue;
                }
                let mut sum = 0.0f32;
                let mut count = 0;
                let mut nearest = f32::INFINITY;
                for dj in [-1isize, 0, 1] {
                    for di in [-1isize, 0, 1] {
                        let n = (k as isize + dj * w as isize + di) as usize;
                        if n != k && self.status[n] == PixelStatus::Hit {
                            sum += frame.intensity[n];
                            nearest = nearest.min(frame.range_m[n]);
                            count += 1;
                        }
                    }
                }
                if count >= 6 {
                    frame.intensity[k] = sum / count as f32;
                    frame.range_m[k] = nearest; // the nearest neighbour's mean range
                    frame.status[k] = PixelStatus::Hit;
                    filled += 1;
                }
            }
        }
        filled
    }

    /// Culling and level of detail: fill `self.draw`.
    fn select_cells(&mut self, cloud: &PointCloud, view: &View) {
        self.draw.clear();
        let spacing = cloud.spacing_m();
        let lod = self.options.lod_spacing_px;
        for cell in cloud.cells() {
            let c = view.rotation * Vec3::from_array(cell.center) + view.translation;
            let d = c.length();
            let (visible, theta_edge) = if d <= cell.radius {
                (true, self.theta_max)
            } else {
                let theta = (c.z / d).clamp(-1.0, 1.0).acos();
                let beta = (cell.radius / d).min(1.0).asin();
                (
                    theta - beta <= self.theta_max && theta + beta >= self.theta_min,
                    (theta + beta).clamp(self.theta_min, self.theta_max),
                )
            };
            if !visible {
                continue;
            }
            let mut count = cell.len;
            let mut spacing_m = spacing;
            if let Some(target) = lod {
                let nearest = (d - cell.radius).max(1e-3);
                let spacing_px = spacing * self.magnification(theta_edge) / nearest;
                if spacing_px < target {
                    let fraction = (spacing_px / target).powi(2);
                    count = ((cell.len as f32 * fraction).ceil() as u32).clamp(1, cell.len);
                    spacing_m = spacing * (cell.len as f32 / count as f32).sqrt();
                }
            }
            self.draw.push(DrawCell {
                start: cell.start,
                count,
                spacing_m,
            });
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    Depth,
    Accumulate,
}

/// Split the draw list into runs of about `target` points.
fn chunk_cells(cells: &[DrawCell], target: usize) -> Vec<&[DrawCell]> {
    let mut chunks = Vec::new();
    let mut start = 0;
    let mut acc = 0usize;
    for (k, c) in cells.iter().enumerate() {
        acc += c.count as usize;
        if acc >= target {
            chunks.push(&cells[start..=k]);
            start = k + 1;
            acc = 0;
        }
    }
    if start < cells.len() {
        chunks.push(&cells[start..]);
    }
    chunks
}

/// The accumulation buffers of pass 2.
struct Accum<'a> {
    /// `(Σ intensity << 24) | count`, fixed point.
    sums: &'a [AtomicU64],
    /// `Σ range`, fixed point.
    ranges: &'a [AtomicU64],
}

#[inline(always)]
fn draw_cell(
    points: &[[f32; 4]],
    cell: &DrawCell,
    view: &View,
    camera: &Camera,
    depth: &[AtomicU64],
    accum: &Accum<'_>,
    pass: Pass,
    atomic: bool,
) {
    let start = cell.start as usize;
    let footprint = cell.spacing_m * view.alpha * view.splat_scale;
    let w = view.width as usize;
    for (offset, p) in points[start..start + cell.count as usize]
        .iter()
        .enumerate()
    {
        let index = (start + offset) as u32;
        let pc = view.rotation * Vec3::new(p[0], p[1], p[2]) + view.translation;
        let Ok([u, v]) = camera.project_unbounded(pc.to_array()) else {
            continue;
        };
        let rho = pc.length();
        let dd = pc.z + view.xi * rho;
        // Footprint in pixels: spacing · α/D · max((ρ + ξZ)/D, 1).
        let size = footprint / dd * ((rho + view.xi * pc.z) / dd).max(1.0);
        let half = (((size - 1.0) * 0.5).ceil().max(0.0) as i32).min(view.max_radius);
        let iu = (u + 0.5).floor() as i32;
        let iv = (v + 0.5).floor() as i32;
        if iu + half < 0 || iv + half < 0 || iu - half >= view.width || iv - half >= view.height {
            continue;
        }
        let (u0, u1) = (
            (iu - half).max(0) as usize,
            (iu + half).min(view.width - 1) as usize,
        );
        let (v0, v1) = (
            (iv - half).max(0) as usize,
            (iv + half).min(view.height - 1) as usize,
        );
        let range_bits = rho.to_bits();
        match pass {
            Pass::Depth => {
                let key = (u64::from(range_bits) << 32) | u64::from(index);
                for row in v0..=v1 {
                    for slot in &depth[row * w + u0..=row * w + u1] {
                        if atomic {
                            slot.fetch_min(key, Ordering::Relaxed);
                        } else if key < slot.load(Ordering::Relaxed) {
                            slot.store(key, Ordering::Relaxed);
                        }
                    }
                }
            }
            Pass::Accumulate => {
                let sample = (((p[3] * INTENSITY_SCALE).round() as u64) << COUNT_BITS) | 1;
                let range_sample = (rho * RANGE_SCALE).round() as u64;
                let limit = rho / (1.0 + view.depth_band);
                for row in v0..=v1 {
                    let base = row * w;
                    for col in u0..=u1 {
                        let nearest = f32::from_bits(
                            (depth[base + col].load(Ordering::Relaxed) >> 32) as u32,
                        );
                        if nearest >= limit {
                            let (slot, range) =
                                (&accum.sums[base + col], &accum.ranges[base + col]);
                            if atomic {
                                slot.fetch_add(sample, Ordering::Relaxed);
                                range.fetch_add(range_sample, Ordering::Relaxed);
                            } else {
                                slot.store(
                                    slot.load(Ordering::Relaxed) + sample,
                                    Ordering::Relaxed,
                                );
                                range.store(
                                    range.load(Ordering::Relaxed) + range_sample,
                                    Ordering::Relaxed,
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
