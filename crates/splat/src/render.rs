//! The CPU splat renderer.
//!
//! Three passes over the visible points (after culling and level of detail):
//!
//! 1. **Depth.** Each point is projected with the camera model and covers a square
//!    splat whose size follows the model's local magnification
//!    (`spacing · α/D · max((ρ + ξZ)/D, 1)` pixels, the larger of the radial and
//!    tangential magnifications of the UCM at the point), so that surfaces close to the
//!    camera stay hole-free: a footprint of `s` pixels covers a square of the odd width
//!    `2 ⌈(s − 1)/2⌉ + 1` centred on the pixel of the projection. Every covered
//!    pixel keeps the minimum of the range's bits
//!    (positive `f32`s order as their bits): exact, and independent of the order in
//!    which points are drawn, so the result does not depend on the thread count
//!    (Schütz, Kerbl, Wimmer 2021). Only the nearest range is needed afterwards (pass 2
//!    averages every sample near it), so the buffer keeps the 32-bit range alone.
//! 2. **Accumulation (anti-aliasing).** Each point adds its intensity to the pixels it
//!    covers where its range is within `depth_band` (relative) of the nearest one.
//!    Sums are fixed-point integers (16-bit intensities), so they too are independent of
//!    the order of addition.
//! 3. **Resolve.** Intensity and range are the means of the accepted samples;
//!    pixels with no sample inside the valid region are sky (`background`, infinite
//!    range), pixels outside it are masked. It clears each row of the buffers as it
//!    reads it, for the next rendering (no pass over the buffers before drawing).
//!
//! **Culling and level of detail.** The buffers cover only the smallest rectangle that
//! holds the camera's valid pixels (the catadioptric disc's box: 71 % of a 640×480
//! image), and splats are clipped to it: what they would draw outside lands on masked
//! pixels, so the frame is the same (tested). Cells of the cloud entirely outside the
//! camera's field (the range of angles off the optical axis that its valid pixels see)
//! are skipped. The others are drawn front to back in batches; between batches, a cell
//! whose every possibly covered pixel (a conservative image rectangle of its bounding
//! sphere, splats included) already holds a range nearer than the cell's nearest point
//! by more than the depth band is skipped (**occlusion culling**). The test is
//! conservative: such a cell could neither lower a depth nor add a sample, so the image
//! is exactly the one drawn without it (tested), and the batches are tested one after
//! the other so that what is skipped does not depend on the thread count either. The
//! rectangle of a cell, for `ξ ≤ 1`, is a disc around its centre's image whose radius
//! bounds the UCM's stretch over the cell's cone of directions (no transcendental
//! function per cell); 8 × 8 tiles of the farthest depth, refreshed on demand once per
//! batch, decide most occluded cells before any pixel is read. Where a cell's points
//! would be denser than `lod_spacing_px` on the image,
//! only a prefix of the cell (a uniform random subsample, see [`crate::PointCloud`]) is
//! drawn, with proportionally larger splats. The subsample size varies with the pose
//! one point at a time, so the rendering stays (almost) continuous in the pose.
//!
//! Precision: `f32` throughout the per-point loop. A point is read as its 16-bit steps
//! from its cell's corner ([`crate::PackedPoint`], 8 bytes: half the memory traffic of
//! `f32` positions), and projected through one transform per cell: the rotation times
//! the step, and the corner in the camera frame, computed in `f64` and rounded once per
//! cell (ranges of at most a few hundred metres).
//!
//! Speed: pass 1 projects the points of a camera without lens distortion 64 at a time
//! (a cell's last points by smaller padded blocks, 256 at most into a buffer that stays
//! in the first level of cache): on AVX-512 or AVX2 where the processor has them (found
//! at run time, sixteen or eight points per instruction, through `pulp`), else in
//! explicit SSE2 on x86-64 (through `safe_arch`, four points per instruction), each
//! splat written whole as four 32-bit words (a single-pixel splat's first word is its
//! pixel's index, so that neither pass unpacks a column and a row); elsewhere with
//! branch-free arithmetic that the compiler vectorises; then it scatters their splats.
//! Every kernel gives the same bits.
//! The points 512 ahead in the draw list are prefetched, a few cache lines per block
//! (cells are drawn front to back, not in memory order). Single-pixel splats (most of
//! them) skip the square loops, and the single-threaded passes take minima and add
//! samples without a branch (whether a point is nearer is unpredictable), on the
//! buffers as plain integers (the threads of a parallel pass share them as atomics):
//! there, on AVX-512, a 3 × 3 splat (most of the others) takes its minima, and adds
//! its samples, a row of three pixels per instruction. Each point's
//! splat is bit for bit the one of the scalar reference (tested, both kernels). A
//! splat whose every pixel already holds a range below its depth band when pass 1
//! reaches it is dropped there (pass 2 would reject it everywhere, since depths only
//! decrease), so pass 2 reads only the splats that may add a sample: about 40 % of
//! those drawn at a street pose. The occlusion test of a cell stops at the first tile,
//! then the first row of its rectangle, that shows it may be visible.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use glam::{DMat3, DVec3, Mat3, Vec3};
use rayon::prelude::*;
use ucm::{Camera, Isometry3};

use frame::{Frame, PixelStatus};

use crate::{PackedPoint, PointCloud, SplatError};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod plain;
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod sse2;

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
    /// neighbouring points on the image (`None`: draw every point). Default `Some(0.65)`,
    /// about 2.4 samples per pixel where a cell is thinned (with the default splat
    /// size: closer to a pixel-integrated reference than 0.5 px with splats of 1.5,
    /// and its PGMs too, with 25 % fewer points; `docs/RESULTS.md`).
    pub lod_spacing_px: Option<f32>,
    /// Splat size factor over the nominal footprint (≥ 1 fills the gaps that the
    /// random jitter of a real sampling leaves). Default 1.25.
    pub splat_scale: f32,
    /// Largest splat half-width, pixels: splats are at most `2 r + 1` pixels wide
    /// (bounds the cost of points very close to the camera). Default 8.
    pub max_splat_radius_px: u32,
    /// Draw with rayon when the pool has more than one thread. The output is the same
    /// either way. Default true.
    pub parallel: bool,
    /// Fill isolated holes: a pixel of the valid region with no sample but at least 6
    /// of its 8 neighbours hit (at the valid region's edge: every valid neighbour, at
    /// least 3) takes their mean intensity and nearest range (the gaps a random
    /// subsample or a jittered sampling leaves). Default true.
    pub fill_holes: bool,
    /// Skip cells hidden behind what is already drawn (exact: the image is the same
    /// with or without it; only the time changes). Cameras with lens distortion are
    /// never culled this way. Default true.
    pub occlusion_culling: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            background: 0.85,
            depth_band: 0.02,
            lod_spacing_px: Some(0.65),
            splat_scale: 1.25,
            max_splat_radius_px: 8,
            parallel: true,
            fill_holes: true,
            occlusion_culling: true,
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
    /// Cells drawn (in the field of view and not occluded).
    pub cells_drawn: usize,
    /// Cells in the field of view skipped as occluded (or as reaching no pixel of the
    /// valid pixels' box).
    pub cells_occluded: usize,
    /// Points drawn (after culling and level of detail).
    pub points_drawn: usize,
    /// Pixels with a rendered point.
    pub pixels_hit: usize,
}

#[derive(Clone, Copy, Debug)]
struct DrawCell {
    start: u32,
    count: u32,
    spacing_m: f32,
    /// The cell's corner in the camera frame ([`View::in_cell`]).
    corner: Vec3,
}

/// A cell in the field of view, before the occlusion test.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    cell: DrawCell,
    /// Centre in the camera frame.
    center: Vec3,
    /// Bounding radius, metres.
    radius: f32,
    /// Lower bound of the range of its points, metres (the drawing order).
    nearest_m: f32,
}

/// The largest singular value of `[[a, s], [0, b]]`.
fn affine_norm(a: f64, b: f64, s: f64) -> f32 {
    let trace = a * a + s * s + b * b;
    let det = a * b;
    ((trace + (trace * trace - 4.0 * det * det).max(0.0).sqrt()) * 0.5).sqrt() as f32
}

/// Side of the tiles of the occlusion test, pixels.
const TILE: usize = 8;

/// Tiles along an image side of `pixels`.
fn tiles(pixels: usize) -> usize {
    pixels.div_ceil(TILE)
}

/// The first batch of points drawn before any occlusion test, and the smallest batch.
const MIN_BATCH_POINTS: usize = 16_384;

/// The per-point constants of a rendering.
#[derive(Clone, Copy)]
struct View {
    undistorted: bool,
    alpha_u: f32,
    alpha_v: f32,
    skew: f32,
    u0: f32,
    v0: f32,
    /// From the cloud's frame to the camera's (cells' centres).
    rotation: Mat3,
    translation: Vec3,
    /// The same in `f64` (cells' corners).
    rotation_f64: DMat3,
    translation_f64: DVec3,
    /// The projection's transform, from a point's steps to the camera frame: the
    /// rotation times the cloud's step ([`PointCloud::step_m`]), and the corner of the
    /// cell being drawn in the camera frame ([`View::in_cell`]).
    point_rotation: Mat3,
    point_translation: Vec3,
    alpha: f32,
    xi: f32,
    /// The first column and row of the [`Region`] (splats' pixels are counted from it).
    origin: [i32; 2],
    /// The [`Region`]'s width and height, pixels.
    width: i32,
    height: i32,
    splat_scale: f32,
    /// Largest splat width, pixels (`2 · max_splat_radius_px + 1`).
    max_width: i32,
    /// Largest singular value of the affine part of the intrinsics
    /// `[[α_u, skew], [0, α_v]]` (how much it can stretch a length).
    affine_norm: f32,
    depth_band: f32,
    /// `1 + depth_band`.
    band_factor: f32,
}

impl View {
    /// The constants of a rendering with `camera` and `options` into `region` from
    /// the pose `rotation`, `translation` (camera from the cloud's frame), of a cloud
    /// whose positions are steps of `step_m` (the projection's transform is then the
    /// one of a cell whose corner is at the cloud's origin).
    fn new(
        camera: &Camera,
        options: &RenderOptions,
        region: Region,
        rotation: DMat3,
        translation: DVec3,
        step_m: f64,
    ) -> Self {
        let i = camera.intrinsics();
        Self {
            undistorted: camera.distortion().is_none(),
            alpha_u: i.alpha_u as f32,
            alpha_v: i.alpha_v as f32,
            skew: i.skew as f32,
            u0: i.u0 as f32,
            v0: i.v0 as f32,
            rotation: rotation.as_mat3(),
            translation: translation.as_vec3(),
            rotation_f64: rotation,
            translation_f64: translation,
            point_rotation: (rotation * step_m).as_mat3(),
            point_translation: translation.as_vec3(),
            alpha: i.alpha_u.max(i.alpha_v) as f32,
            xi: i.xi as f32,
            origin: [region.u0 as i32, region.v0 as i32],
            width: region.width as i32,
            height: region.height as i32,
            splat_scale: options.splat_scale,
            max_width: 2 * options.max_splat_radius_px.min(16_000) as i32 + 1,
            affine_norm: affine_norm(i.alpha_u, i.alpha_v, i.skew),
            depth_band: options.depth_band,
            band_factor: 1.0 + options.depth_band,
        }
    }

    /// A cell's corner (relative to the cloud's origin) in the camera frame, rounded
    /// once from `f64`.
    fn corner(&self, corner_m: [f64; 3]) -> Vec3 {
        (self.rotation_f64 * DVec3::from_array(corner_m) + self.translation_f64).as_vec3()
    }

    /// The view whose projection draws the points of the cell whose corner is at
    /// `corner` in the camera frame ([`View::corner`]).
    #[inline(always)]
    fn in_cell(&self, corner: Vec3) -> Self {
        Self {
            point_translation: corner,
            ..*self
        }
    }
}

/// The smallest rectangle of the image that holds every valid pixel of the camera:
/// the renderer's buffers cover it alone, and splats are clipped to it (whatever would
/// be drawn outside it lands on masked pixels, so the frame is the same; at 640×480
/// the catadioptric disc's box holds 71 % of the pixels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Region {
    u0: usize,
    v0: usize,
    width: usize,
    height: usize,
}

impl Region {
    /// The box of `camera`'s valid pixels (one pixel at the origin if none is valid).
    fn of(camera: &Camera) -> Self {
        let w = camera.width() as usize;
        let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
        for (k, _) in camera
            .valid_pixels()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
        {
            let (u, v) = (k % w, k / w);
            (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
        }
        if u0 > u1 {
            return Self {
                u0: 0,
                v0: 0,
                width: 1,
                height: 1,
            };
        }
        Self {
            u0,
            v0,
            width: u1 - u0 + 1,
            height: v1 - v0 + 1,
        }
    }

    fn len(&self) -> usize {
        self.width * self.height
    }
}

/// A renderer for one camera, owning its buffers (no allocation per frame once warm).
#[derive(Debug)]
pub struct Renderer {
    camera: Camera,
    options: RenderOptions,
    /// What the buffers below cover (pixels of the [`Region`], row-major).
    region: Region,
    depth: Vec<AtomicU32>,
    /// Per pixel: `(Σ intensity << 24) | count` and `Σ range`, fixed point,
    /// interleaved so that pass 2 touches one cache line per pixel.
    accum: Vec<[AtomicU64; 2]>,
    candidates: Vec<Candidate>,
    /// The candidates' draw order: range of the nearest point's bits, index.
    order: Vec<u64>,
    draw: Vec<DrawCell>,
    splats: Vec<Splat>,
    status: Vec<PixelStatus>,
    /// Per pixel of the region: all ones where valid, zero where masked. A cleared
    /// key is `EMPTY & valid_bits`: a masked pixel keeps the key 0 (the nearest range)
    /// through every rendering, so that it never keeps a cell from being culled and
    /// no splat is kept for it alone (the resolve masks it whatever it holds).
    valid_bits: Vec<u32>,
    /// Per tile of `TILE × TILE` pixels: the farthest key of its valid pixels (as in
    /// [`Renderer::occluded`]) when `tile_batch` equals the batch being tested, else
    /// stale (recomputed on demand: depths change only while a batch is drawn).
    tile_farthest: Vec<u32>,
    tile_batch: Vec<u32>,
    /// The batch being tested (starts at 1; `tile_batch` starts at 0).
    batch: u32,
    /// Whether `depth` holds only cleared keys and `accum` only zeros (the resolve
    /// clears what it reads, so that a rendering does not write both buffers whole
    /// once more before it draws; false while a rendering runs).
    cleared: bool,
    theta_min: f32,
    theta_max: f32,
}

const EMPTY: u32 = u32::MAX;
const COUNT_BITS: u32 = 24;
const COUNT_MASK: u64 = (1 << COUNT_BITS) - 1;
const INTENSITY_SCALE: f32 = 65535.0;
/// Fixed-point scale of the range sums (1/4096 m).
const RANGE_SCALE: f32 = 4096.0;

impl Renderer {
    /// A renderer for `camera`. Fails on invalid options, or on a camera whose valid
    /// pixels reach too far ([`SplatError::RegionTooLarge`]).
    pub fn new(camera: Camera, options: RenderOptions) -> Result<Self, SplatError> {
        let region = Region::of(&camera);
        Self::with_region(camera, options, region)
    }

    /// [`Renderer::new`] with buffers over `region` (which must hold every valid pixel
    /// of the camera, and lie inside its image).
    fn with_region(
        camera: Camera,
        options: RenderOptions,
        region: Region,
    ) -> Result<Self, SplatError> {
        options.validate()?;
        let (columns, rows) = (region.u0 + region.width, region.v0 + region.height);
        if columns > MAX_EXTENT_PX || rows > MAX_EXTENT_PX {
            return Err(SplatError::RegionTooLarge {
                columns,
                rows,
                max: MAX_EXTENT_PX,
            });
        }
        let n = region.len();
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
        let tile_count = tiles(region.width) * tiles(region.height);
        let valid = camera.valid_pixels();
        let valid_bits: Vec<u32> = (0..n)
            .map(|k| {
                let (u, v) = (region.u0 + k % region.width, region.v0 + k / region.width);
                if valid[v * w + u] { u32::MAX } else { 0 }
            })
            .collect();
        let status = vec![PixelStatus::Sky; camera.pixel_count()];
        Ok(Self {
            camera,
            options,
            region,
            depth: valid_bits
                .iter()
                .map(|&v| AtomicU32::new(EMPTY & v))
                .collect(),
            accum: (0..n)
                .map(|_| [AtomicU64::new(0), AtomicU64::new(0)])
                .collect(),
            candidates: Vec::new(),
            order: Vec::new(),
            draw: Vec::new(),
            splats: Vec::new(),
            status,
            valid_bits,
            tile_farthest: vec![0; tile_count],
            tile_batch: vec![0; tile_count],
            batch: 0,
            cleared: true,
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
        let expected = self.camera.pixel_count();
        for (what, got) in [
            ("intensity", frame.intensity.len()),
            ("range", frame.range_m.len()),
            ("status", frame.status.len()),
        ] {
            if got != expected {
                return Err(SplatError::FrameBuffer {
                    what,
                    got,
                    expected,
                });
            }
        }
        if !camera_from_world.is_finite() {
            return Err(SplatError::NonFinitePose);
        }
        // Points are relative to the cloud's origin: fold it into the translation (f64).
        let translation = camera_from_world.transform_point(cloud.origin());
        let view = View::new(
            &self.camera,
            &self.options,
            self.region,
            camera_from_world.rotation_matrix(),
            translation,
            cloud.step_m(),
        );
        // Compiled for the widest instruction set found at run time (the occlusion
        // tests' scans and the resolve vectorise with it; the same operations, so the
        // same bits).
        Ok(isa::arch().dispatch(RenderView {
            renderer: self,
            cloud,
            view,
            frame,
        }))
    }

    /// The body of [`Renderer::render`], once its arguments are checked.
    #[inline(always)]
    fn render_view(&mut self, cloud: &PointCloud, view: View, frame: &mut Frame) -> RenderStats {
        self.select_cells(cloud, &view);
        let candidate_points: usize = self.candidates.iter().map(|c| c.cell.count as usize).sum();

        // The last resolve cleared the buffers, unless it did not run (a panic): then
        // cleared here, as plain integers (stores the compiler widens, unlike atomic
        // ones).
        if !std::mem::replace(&mut self.cleared, false) {
            for (key, &valid) in plain::depths(&mut self.depth)
                .iter_mut()
                .zip(&self.valid_bits)
            {
                *key = EMPTY & valid;
            }
            plain::sums(&mut self.accum).fill([0; 2]);
        }
        let parallel = self.options.parallel && rayon::current_num_threads() > 1;
        let occlusion = self.options.occlusion_culling && view.undistorted;
        self.splats.resize(candidate_points, Splat::default());
        self.draw.clear();
        let mut points_drawn = 0;
        // Splats that may add a sample, compacted at the front of `self.splats`.
        let mut splats_kept = 0;
        let mut cells_occluded = 0;
        let mut next = 0;
        while next < self.candidates.len() {
            // The next batch, front to back, tested against what is drawn so far.
            let target = MIN_BATCH_POINTS.max(points_drawn / 2);
            // Every tile's farthest key is stale once a batch is drawn.
            self.batch = self.batch.wrapping_add(1);
            if self.batch == 0 {
                self.tile_batch.fill(0);
                self.batch = 1;
            }
            let first = self.draw.len();
            let mut batch_points = 0;
            while next < self.candidates.len() && batch_points < target {
                let candidate = self.candidates[self.order[next] as u32 as usize];
                next += 1;
                if occlusion && points_drawn > 0 && self.occluded(&candidate, &view) {
                    cells_occluded += 1;
                    continue;
                }
                self.draw.push(candidate.cell);
                batch_points += candidate.cell.count as usize;
            }
            let cells = &self.draw[first..];
            let splats = &mut self.splats[splats_kept..splats_kept + batch_points];
            splats_kept += draw_depth(
                cloud.points(),
                cells,
                &view,
                &self.camera,
                &mut self.depth,
                splats,
                parallel,
            );
            points_drawn += batch_points;
        }
        let splats = &self.splats[..splats_kept];
        if parallel {
            splats
                .par_chunks(16_384)
                .for_each(|splats| accumulate(splats, &view, &self.depth, &self.accum));
        } else {
            let depth = plain::depths(&mut self.depth);
            widest_pass_two(splats, &view, depth, plain::sums(&mut self.accum));
        }

        // Resolve: pixels outside the valid pixels' box are masked; inside it, row by
        // row without a branch (whether a pixel is hit is unpredictable at edges).
        let background = self.options.background;
        let valid = self.camera.valid_pixels();
        let image_width = self.camera.width() as usize;
        let Region {
            u0,
            v0,
            width,
            height,
        } = self.region;
        let depth = plain::depths(&mut self.depth);
        let accum = plain::sums(&mut self.accum);
        let mut pixels_hit = 0;
        let mut rows_resolved = 0;
        let rows = frame
            .intensity
            .chunks_exact_mut(image_width)
            .zip(frame.range_m.chunks_exact_mut(image_width))
            .zip(frame.status.chunks_exact_mut(image_width))
            .zip(valid.chunks_exact(image_width));
        for (y, (((intensity, range_m), status), valid)) in rows.enumerate() {
            let inside = if (v0..v0 + height).contains(&y) {
                u0..u0 + width
            } else {
                0..0
            };
            for part in [0..inside.start, inside.end.max(inside.start)..image_width] {
                intensity[part.clone()].fill(0.0);
                range_m[part.clone()].fill(f32::NAN);
                status[part].fill(PixelStatus::Masked);
            }
            if inside.is_empty() {
                continue;
            }
            let r = (y - v0) * width;
            rows_resolved += 1;
            pixels_hit += resolve_row(
                &mut depth[r..r + width],
                &mut accum[r..r + width],
                &valid[inside.clone()],
                background,
                &mut intensity[inside.clone()],
                &mut range_m[inside.clone()],
                &mut status[inside],
            );
        }
        // Every row of the region resolved, hence cleared (`render` checked the frame's
        // buffers, so all of them are).
        self.cleared = rows_resolved == height;
        if self.options.fill_holes {
            pixels_hit += self.fill_holes(frame);
        }
        RenderStats {
            cells_drawn: self.draw.len(),
            cells_occluded,
            points_drawn,
            pixels_hit,
        }
    }

    /// Fill isolated sky pixels surrounded by hits (decided on the statuses before
    /// filling, so the result does not depend on the scan order). Returns the number
    /// of pixels filled.
    #[inline(always)]
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
                let mut masked = 0;
                let mut nearest = f32::INFINITY;
                for dj in [-1isize, 0, 1] {
                    for di in [-1isize, 0, 1] {
                        let n = (k as isize + dj * w as isize + di) as usize;
                        if n != k && self.status[n] == PixelStatus::Hit {
                            sum += frame.intensity[n];
                            nearest = nearest.min(frame.range_m[n]);
                            count += 1;
                        }
                        masked += usize::from(self.status[n] == PixelStatus::Masked);
                    }
                }
                // At the valid region's edge: every valid neighbour (at least 3) hit.
                if count >= 6 || (count >= 3 && count + masked == 8) {
                    frame.intensity[k] = sum / count as f32;
                    frame.range_m[k] = nearest; // the nearest neighbour's mean range
                    frame.status[k] = PixelStatus::Hit;
                    filled += 1;
                }
            }
        }
        filled
    }

    /// Field-of-view culling and level of detail: fill `self.candidates`, nearest
    /// first.
    #[inline(always)]
    fn select_cells(&mut self, cloud: &PointCloud, view: &View) {
        self.candidates.clear();
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
            self.candidates.push(Candidate {
                cell: DrawCell {
                    start: cell.start,
                    count,
                    spacing_m,
                    corner: view.corner(cell.corner_m),
                },
                center: c,
                radius: cell.radius,
                nearest_m: (d - cell.radius).max(0.0),
            });
        }
        // Front to back; ties by position in the cloud, so the order is total. Sorted
        // as integers: a non-negative range orders as its bits (a `-0.0` would come
        // last, which only the time could notice: the image does not depend on the
        // order in which cells are drawn).
        self.order.clear();
        self.order.extend(
            self.candidates
                .iter()
                .enumerate()
                .map(|(i, c)| (u64::from(c.nearest_m.to_bits()) << 32) | i as u64),
        );
        self.order.sort_unstable();
    }

    /// Whether every pixel that a point of `candidate` could cover already holds a
    /// range nearer than the cell by more than the depth band (then the cell can
    /// change nothing). Conservative: `false` whenever in doubt. Takes the depth
    /// buffer mutably (no other thread draws meanwhile) so that its rows are read as
    /// plain integers, several at a time.
    #[inline(always)]
    fn occluded(&mut self, candidate: &Candidate, view: &View) -> bool {
        let Some([u0, u1, v0, v1]) = self.image_rect(candidate, view) else {
            return false;
        };
        if u0 > u1 || v0 > v1 {
            return true; // entirely outside the region: nothing would be drawn there
        }
        let w = self.region.width;
        // Margins cover the f32 rounding of the points' ranges and of the band test.
        let nearest = candidate.nearest_m * (1.0 - 1e-4) - 1e-3;
        // Whether every pixel is nearer than the cell by more than the band, given the
        // farthest range seen so far (an empty pixel's key is a NaN: false).
        let hides = |farthest: u32| {
            f32::from_bits(farthest) * (1.0 + view.depth_band) * (1.0 + 1e-4) < nearest
        };
        // First the tiles holding the rectangle (each tile's farthest key bounds its
        // pixels'): most occluded cells are decided there, without reading every pixel.
        let tiles_wide = tiles(self.region.width);
        let mut hidden_by_tiles = true;
        'tiles: for tv in v0 / TILE..=v1 / TILE {
            for tu in u0 / TILE..=u1 / TILE {
                if !hides(self.tile_farthest(tv * tiles_wide + tu, tu, tv)) {
                    hidden_by_tiles = false;
                    break 'tiles;
                }
            }
        }
        if hidden_by_tiles {
            return true;
        }
        // Masked pixels hold the key 0: they never raise the farthest.
        let mut farthest = 0u32;
        for row in v0..=v1 {
            let depth = &mut self.depth[row * w + u0..=row * w + u1];
            farthest = depth.iter_mut().fold(farthest, |f, d| f.max(*d.get_mut()));
            // The farthest range only grows: stop at the first row that decides.
            if !hides(farthest) {
                return false;
            }
        }
        true
    }

    /// The farthest key of the valid pixels of tile `index` (column `tu`, row `tv`),
    /// recomputed if a batch was drawn since.
    #[inline(always)]
    fn tile_farthest(&mut self, index: usize, tu: usize, tv: usize) -> u32 {
        if self.tile_batch[index] != self.batch {
            let (w, h) = (self.region.width, self.region.height);
            let (u0, u1) = (tu * TILE, ((tu + 1) * TILE).min(w));
            let mut farthest = 0u32;
            for row in tv * TILE..((tv + 1) * TILE).min(h) {
                let depth = &mut self.depth[row * w + u0..row * w + u1];
                farthest = depth.iter_mut().fold(farthest, |f, d| f.max(*d.get_mut()));
            }
            self.tile_farthest[index] = farthest;
            self.tile_batch[index] = self.batch;
        }
        self.tile_farthest[index]
    }

    /// A pixel rectangle `[u0, u1, v0, v1]` (inclusive, clipped to the image; empty if
    /// outside it) holding every pixel that a splat of a point of the candidate's
    /// bounding sphere can cover, or `None` if it cannot be bounded (the sphere holds
    /// the centre, or reaches the edge of the model's domain).
    ///
    /// The sphere's directions form a cone of half-angle `β = asin(R/d)` around the
    /// centre's, at angle `θc` off the axis. For `ξ ≤ 1` (no transcendental function):
    /// the UCM's projection of the unit sphere onto the normalised plane stretches
    /// lengths by at most `max(r'(θ), r(θ)/sin θ)` at angle `θ`, with
    /// `r(θ) = sin θ / (cos θ + ξ)`; both factors increase with `θ` there, so every
    /// direction of the cone lands within `tan β · max(r'(θc + β), r(θc + β)/sin(θc + β))`
    /// of the centre's image (a geodesic of length at most `β ≤ tan β` joins them
    /// inside the cone), and the affine intrinsics stretch that disc by at most their
    /// largest singular value. For `ξ > 1`, see [`Renderer::sector_box`].
    #[inline(always)]
    fn image_rect(&self, candidate: &Candidate, view: &View) -> Option<[usize; 4]> {
        let c = candidate.center;
        let d = c.length();
        if !(d > candidate.radius * 1.01 + 1e-3) {
            return None;
        }
        let xi = view.xi;
        if xi > 1.0 {
            let [u_lo, u_hi, v_lo, v_hi] = self.sector_box(candidate, view)?;
            return clip_rect([u_lo, u_hi, v_lo, v_hi], view.max_width as f32 * 0.5, view);
        }
        // The cone, widened for rounding: sin β, cos β; the centre's cos θc, sin θc.
        let sin_b = (candidate.radius / d * 1.001 + 1e-4).min(1.0);
        let cos_b = (1.0 - sin_b * sin_b).max(0.0).sqrt();
        let cos_c = (c.z / d).clamp(-1.0, 1.0);
        let sin_c = (1.0 - cos_c * cos_c).max(0.0).sqrt();
        // θc + β < π, and cos(θc + β) inside the domain (cos θ + ξ > 0) by a margin.
        let cos_hi = cos_c * cos_b - sin_c * sin_b;
        if !(cos_b > -cos_c) || !(cos_hi + xi > 1e-3) || !(cos_b > 0.0) {
            return None;
        }
        let denominator = cos_hi + xi;
        let radial = (1.0 + xi * cos_hi) / (denominator * denominator);
        let tangential = 1.0 / denominator;
        let radius = sin_b / cos_b * radial.max(tangential) * view.affine_norm * 1.001 + 1e-3;
        // The centre's image.
        let dd = c.z + xi * d;
        let (x, y) = (c.x / dd, c.y / dd);
        let u = view.alpha_u * x + view.skew * y + view.u0;
        let v = view.alpha_v * y + view.v0;
        // Splat half-width: size = spacing · scale · M(θ) / ρ, M increasing in θ for
        // ξ ≤ 1 (see `magnification`).
        let magnification = view.alpha * radial.max(tangential);
        let size = candidate.cell.spacing_m * view.splat_scale * magnification
            / (d - candidate.radius).max(1e-3);
        let half = (size * 0.5 + 1.0).min(view.max_width as f32 * 0.5);
        clip_rect([u - radius, u + radius, v - radius, v + radius], half, view)
    }

    /// The image box `[u_lo, u_hi, v_lo, v_hi]` of the directions of the candidate's
    /// bounding sphere, for any `ξ`: the UCM maps a direction at angle `θ` off the axis
    /// and azimuth `φ` to the normalised point `r(θ) (cos φ, sin φ)` with
    /// `r(θ) = sin θ / (cos θ + ξ)`, increasing over the drawable domain; the cone of
    /// half-angle `β` gives `θ ∈ [θc − β, θc + β]` and `|φ − φc| ≤ asin(sin β / sin θc)`:
    /// an annular sector, whose bounding box the affine intrinsics map to the image.
    /// `None` where the cone reaches the domain's edge.
    fn sector_box(&self, candidate: &Candidate, view: &View) -> Option<[f32; 4]> {
        let c = candidate.center;
        let d = c.length();
        let xi = view.xi;
        let theta_c = (c.z / d).clamp(-1.0, 1.0).acos();
        let beta = (candidate.radius / d).asin() * 1.001 + 1e-4;
        let theta_hi = theta_c + beta;
        // The domain's edge: cos θ + ξ > 0 (ξ ≤ 1), or 1 + ξ cos θ > 0 (ξ > 1).
        let cos_limit = if xi > 1.0 { -1.0 / xi } else { -xi };
        if theta_hi >= std::f32::consts::PI || theta_hi.cos() <= cos_limit + 1e-3 {
            return None;
        }
        let r = |theta: f32| theta.sin() / (theta.cos() + xi);
        let r_hi = r(theta_hi);
        let (mut x0, mut x1, mut y0, mut y1);
        if theta_c <= beta {
            // The cone holds the axis: a disc.
            (x0, x1, y0, y1) = (-r_hi, r_hi, -r_hi, r_hi);
        } else {
            let r_lo = r(theta_c - beta).max(0.0);
            let phi_c = c.y.atan2(c.x);
            let dphi = (beta.sin() / theta_c.sin()).min(1.0).asin();
            let (a0, a1) = (phi_c - dphi, phi_c + dphi);
            (x0, x1, y0, y1) = (
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
            );
            let mut include = |x: f32, y: f32| {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            };
            for a in [a0, a1] {
                let (sin, cos) = a.sin_cos();
                include(r_lo * cos, r_lo * sin);
                include(r_hi * cos, r_hi * sin);
            }
            // Axis directions inside the angular range reach the outer radius.
            for k in -4..=4 {
                let a = k as f32 * std::f32::consts::FRAC_PI_2;
                if a > a0 && a < a1 {
                    let (sin, cos) = a.sin_cos();
                    include(r_hi * cos, r_hi * sin);
                }
            }
        }
        // Image of the box under the affine intrinsics.
        let mut u_lo = f32::INFINITY;
        let mut u_hi = f32::NEG_INFINITY;
        for (x, y) in [(x0, y0), (x0, y1), (x1, y0), (x1, y1)] {
            let u = view.alpha_u * x + view.skew * y + view.u0;
            u_lo = u_lo.min(u);
            u_hi = u_hi.max(u);
        }
        Some([
            u_lo,
            u_hi,
            view.alpha_v * y0 + view.v0,
            view.alpha_v * y1 + view.v0,
        ])
    }
}

/// [`Renderer::render_view`] as a `pulp` kernel (a struct with an inlined method, not a
/// closure: only what is inlined into `with_simd` is compiled for its instruction set).
struct RenderView<'a> {
    renderer: &'a mut Renderer,
    cloud: &'a PointCloud,
    view: View,
    frame: &'a mut Frame,
}

impl pulp::WithSimd for RenderView<'_> {
    type Output = RenderStats;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> RenderStats {
        self.renderer.render_view(self.cloud, self.view, self.frame)
    }
}

/// The pixel rectangle of an image box `[u_lo, u_hi, v_lo, v_hi]` of projections,
/// widened by splats of half-width `half` (and 2 pixels of margin), clipped to the
/// region and counted from its first pixel (empty if outside it); `None` if the box is
/// not finite.
#[inline(always)]
fn clip_rect(image_box: [f32; 4], half: f32, view: &View) -> Option<[usize; 4]> {
    if !image_box.iter().all(|x| x.is_finite()) {
        return None;
    }
    let [u_lo, u_hi, v_lo, v_hi] = image_box;
    let pad = half + 2.0;
    let clip = |lo: f32, hi: f32, origin: i32, n: i32| -> (usize, usize) {
        // Limited to just outside the region first, so that floor_small applies.
        let (first, last) = (origin as f32 - 2.0, (origin + n) as f32 + 1.0);
        let lo = (floor_small(limit(lo - pad, first, last)) - origin).max(0);
        let hi = -floor_small(-limit(hi + pad, first, last)) - origin;
        let hi = hi.min(n - 1);
        if lo > hi {
            (1, 0)
        } else {
            (lo as usize, hi as usize)
        }
    };
    let [origin_u, origin_v] = view.origin;
    let (u0, u1) = clip(u_lo, u_hi, origin_u, view.width);
    let (v0, v1) = clip(v_lo, v_hi, origin_v, view.height);
    Some([u0, u1, v0, v1])
}

/// Pass 1 over a batch of cells, on rayon's threads if `parallel`: chunks of cells of
/// similar work, each with its own run of splat slots; atomics make the result
/// independent of the order. Returns the number of slots of `splats` that pass 2 must
/// read (on one thread, the splats that may add a sample are moved to the front; on
/// several, the others are marked [`NOT_DRAWN`]).
fn draw_depth(
    points: &[PackedPoint],
    cells: &[DrawCell],
    view: &View,
    camera: &Camera,
    depth: &mut [AtomicU32],
    splats: &mut [Splat],
    parallel: bool,
) -> usize {
    if !parallel {
        let depth = plain::depths(depth);
        return widest_pass_one(points, cells, view, camera, depth, splats);
    }
    let depth = &*depth;
    let total = splats.len();
    let chunks = chunk_cells(cells, 16_384);
    let mut slices = Vec::with_capacity(chunks.len());
    let mut rest = splats;
    for cells in &chunks {
        let n: usize = cells.iter().map(|c| c.count as usize).sum();
        let (head, tail) = rest.split_at_mut(n);
        slices.push((*cells, head));
        rest = tail;
    }
    slices.par_iter_mut().for_each(|(cells, splats)| {
        let kept = widest_pass_one(points, cells, view, camera, depth, splats);
        for s in &mut splats[kept..] {
            *s = Splat::not_drawn();
        }
    });
    total
}

/// A projected point, written by pass 1 and read by pass 2: four 32-bit words
/// `[where, width | intensity << 16, range, band limit]` (16 bytes, so that the vector
/// kernel writes it whole and a copy is one move). `where` is, for a single-pixel
/// splat (most of them), the index of its pixel in the region, row by row (the passes
/// read it without unpacking a column and a row and multiplying), and for a wider
/// splat `first column | first row << 16` of its top-left pixel (16-bit two's
/// complement each: it may start left of or above the region). The width is
/// [`NOT_DRAWN`] if the point is not seen (then the other fields are meaningless); the
/// intensity is in 16-bit fixed point; the range and its [`band_limit`] in metres, as
/// `f32` bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(align(16))]
struct Splat([u32; 4]);

impl Splat {
    /// The splat whose top-left pixel is at column `iu` and row `iv` of a region
    /// `region_width` pixels wide.
    #[inline(always)]
    fn new(
        [iu, iv, region_width]: [i32; 3],
        width: i32,
        intensity: i32,
        range_m: f32,
        limit_m: f32,
    ) -> Self {
        // Wrapping: a point that is not seen may have any column and row (its word is
        // then meaningless).
        let at = if width == 1 {
            iv.wrapping_mul(region_width).wrapping_add(iu) as u32
        } else {
            (iu as u32 & 0xFFFF) | ((iv as u32) << 16)
        };
        Self([
            at,
            (width as u32 & 0xFFFF) | ((intensity as u32) << 16),
            range_m.to_bits(),
            limit_m.to_bits(),
        ])
    }

    /// A point that is not seen.
    fn not_drawn() -> Self {
        Self::new([0, 0, 0], i32::from(NOT_DRAWN), 0, 0.0, 0.0)
    }

    /// The first column (of a splat wider than a pixel).
    #[inline(always)]
    fn iu(&self) -> i32 {
        i32::from(self.0[0] as u16 as i16)
    }

    /// The first row (of a splat wider than a pixel).
    #[inline(always)]
    fn iv(&self) -> i32 {
        i32::from((self.0[0] >> 16) as u16 as i16)
    }

    #[inline(always)]
    fn width(&self) -> u16 {
        self.0[1] as u16
    }

    #[inline(always)]
    fn drawn(&self) -> bool {
        self.width() != NOT_DRAWN
    }

    #[inline(always)]
    fn intensity(&self) -> u16 {
        (self.0[1] >> 16) as u16
    }

    #[inline(always)]
    fn range_m(&self) -> f32 {
        f32::from_bits(self.0[2])
    }

    /// [`band_limit`] of the range.
    #[inline(always)]
    fn limit_m(&self) -> f32 {
        f32::from_bits(self.0[3])
    }
}

const NOT_DRAWN: u16 = u16::MAX;

/// The most columns and rows of a camera's image that the renderer draws: a splat's
/// first column and row are 16-bit signed integers ([`Splat`]), projections are
/// clamped to ±30 000 pixels before rounding ([`first_px`]), and splats are at most
/// about 2000 pixels wide; 16 384 keeps clear of all three.
const MAX_EXTENT_PX: usize = 16_384;

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

/// `floor(x)` for `|x| < 2²²`, exactly, with float and integer operations that
/// vectorise (no libm call: `floor` is not an instruction on baseline x86-64, and a
/// saturating `as i32` is not vectorised). Adding 1.5·2²³ rounds `x` to the nearest
/// integer into the low mantissa bits; one step down where that rounded up.
#[inline(always)]
fn floor_small(x: f32) -> i32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 · 2^23
    let nearest = (x + MAGIC).to_bits() as i32 - MAGIC.to_bits() as i32;
    nearest - i32::from(nearest as f32 > x)
}

/// `x` limited to `[lo, hi]`, NaN sent to `lo` (`f32::clamp` keeps NaN, which a
/// saturating conversion would then have to handle).
#[inline(always)]
#[allow(clippy::manual_clamp)]
fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    x.max(lo).min(hi)
}

/// The first pixel (column or row) of a splat of odd `width` centred on the pixel
/// that holds the coordinate `x`: `round(x) − (width − 1)/2` (halves up; `x` is limited
/// to the range of pixel coordinates first).
#[inline(always)]
fn first_px(x: f32, width: i32) -> i32 {
    // Limit first: the projection of points near the domain's edge can be huge.
    floor_small(limit(x, -30_000.0, 30_000.0) + 0.5) - ((width - 1) >> 1)
}

/// The splat of one point, or `None` if it is not seen (behind the viewpoint, outside
/// the model's domain, or entirely outside the image). The reference for
/// [`project_block`], and the path of cameras with lens distortion.
#[inline(always)]
fn project_point(p: &PackedPoint, footprint: f32, view: &View, camera: &Camera) -> Option<Splat> {
    let [x, y, z] = p.steps.map(f32::from);
    project_steps(Vec3::new(x, y, z), p.intensity, footprint, view, camera)
}

/// [`project_point`] of a point at `steps` (as floats: exact below 2²⁴) from the
/// corner of the view's cell.
#[inline(always)]
fn project_steps(
    steps: Vec3,
    intensity: u16,
    footprint: f32,
    view: &View,
    camera: &Camera,
) -> Option<Splat> {
    let pc = view.point_rotation * steps + view.point_translation;
    let rho = pc.length();
    let dd = pc.z + view.xi * rho;
    if !(dd > 0.0) || (view.xi > 1.0 && !(view.xi * pc.z + rho > 0.0)) {
        return None;
    }
    let inv_d = 1.0 / dd;
    let [u, v] = if view.undistorted {
        let (x, y) = (pc.x * inv_d, pc.y * inv_d);
        [
            view.alpha_u * x + view.skew * y + view.u0,
            view.alpha_v * y + view.v0,
        ]
    } else {
        camera.project_unbounded(pc.to_array()).ok()?
    };
    // Footprint in pixels: spacing · α/D · max((ρ + ξZ)/D, 1).
    let size = footprint * inv_d * ((rho + view.xi * pc.z) * inv_d).max(1.0);
    let width = splat_width(size, view.max_width);
    let iu = first_px(u, width) - view.origin[0];
    let iv = first_px(v, width) - view.origin[1];
    if iu + width <= 0 || iv + width <= 0 || iu >= view.width || iv >= view.height {
        return None;
    }
    Some(Splat::new(
        [iu, iv, view.width],
        width,
        i32::from(intensity),
        rho,
        band_limit(rho, view),
    ))
}

/// Width of the square splat of a footprint of `size` pixels: the odd width
/// `2 ⌈(size − 1)/2⌉ + 1`, at most `max_width` (no libm call, no branch). Odd, so that
/// a splat grows by a ring of pixels around the one holding the projection. (`⌈size⌉`,
/// even widths included, was tried: closer to a pixel-integrated reference, but
/// a rendering less smooth in the pose — the whole-pipeline finite differences of the
/// PGM's Jacobian along the optical axis fell from 0.87 to 0.84 in cosine — and every
/// run of the convergence protocols it changed ended worse; `docs/RESULTS.md`.)
#[inline(always)]
fn splat_width(size: f32, max_width: i32) -> i32 {
    let h = limit((size - 1.0) * 0.5, 0.0, 1000.0);
    let t = floor_small(h);
    2 * (t + i32::from((t as f32) < h)).min((max_width - 1) >> 1) + 1
}

/// Points projected into a buffer of the first level of cache before their depth
/// pass (a multiple of [`BLOCK`]).
const STAGE: usize = 256;

/// How many points ahead of the one being drawn [`Warm`] asks for (in draw order).
const WARM_AHEAD: usize = 512;

/// Points in a 64-byte cache line.
const POINTS_PER_LINE: usize = 64 / size_of::<PackedPoint>();

/// Points projected at a time by [`project_block`].
const BLOCK: usize = 64;
/// Points projected at a time at the end of a cell (fewer wasted on padding: level of
/// detail leaves most cells with a count that is not a multiple of [`BLOCK`]).
const TAIL: usize = 8;

#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
/// The splats of `N` points, one array per field: what [`project_block`] computes
/// several points at a time before packing them into [`Splat`]s.
struct Lanes<const N: usize> {
    iu: [i32; N],
    iv: [i32; N],
    /// [`NOT_DRAWN`] where the point is not seen.
    width: [i32; N],
    range: [f32; N],
    limit: [f32; N],
    intensity: [i32; N],
}

#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
impl<const N: usize> Lanes<N> {
    /// The splat of point `k`.
    fn splat(&self, k: usize, view: &View) -> Splat {
        Splat::new(
            [self.iu[k], self.iv[k], view.width],
            self.width[k],
            self.intensity[k],
            self.range[k],
            self.limit[k],
        )
    }

    fn new() -> Self {
        Self {
            iu: [0; N],
            iv: [0; N],
            width: [0; N],
            range: [0.0; N],
            limit: [0.0; N],
            intensity: [0; N],
        }
    }
}

/// How pass 1 projects points of a camera without lens distortion, several at a
/// time: every implementation gives bit for bit the splats of [`project_point`]
/// (tested). Not closures: a closure is compiled apart from the function that calls
/// it, without the instruction set that function was compiled for.
trait Project: Copy {
    /// The splats of `N` points (`N` a multiple of the implementation's width).
    fn lanes<const N: usize>(
        self,
        points: &[PackedPoint; N],
        footprint: f32,
        view: &View,
        out: &mut [Splat; N],
    );

    /// The splats of fewer than [`BLOCK`] points (a cell's last ones), as many as `out`.
    fn rest(self, points: &[PackedPoint], footprint: f32, view: &View, out: &mut [Splat]);

    /// Pass 1 of a 3 × 3 splat on plain keys ([`Depths::splat`]); the plain loop
    /// unless the instruction set does it whole rows at a time.
    #[inline(always)]
    fn depth_3x3(
        self,
        depth: &mut [u32],
        first: usize,
        width: usize,
        key: u32,
        limit: f32,
    ) -> bool {
        let mut hidden = true;
        for row in [first, first + width, first + 2 * width] {
            for before in &mut depth[row..row + 3] {
                hidden &= f32::from_bits(*before) < limit;
                *before = key.min(*before);
            }
        }
        !hidden
    }

    /// Pass 2 of a 3 × 3 splat on plain sums ([`accumulate_own`]); the plain loop
    /// unless the instruction set does it whole rows at a time.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn accumulate_3x3(
        self,
        depth: &[u32],
        accum: &mut [[u64; 2]],
        first: usize,
        width: usize,
        limit: f32,
        sample: u64,
        range_sample: u64,
    ) {
        for row in [first, first + width, first + 2 * width] {
            for k in row..row + 3 {
                let keep = u64::from(f32::from_bits(depth[k]) >= limit);
                accum[k][0] += sample * keep;
                accum[k][1] += range_sample * keep;
            }
        }
    }
}

/// The splats of `points` (as many as `out`) by blocks of `T` points, the last one
/// padded.
#[inline(always)]
fn by_blocks<const T: usize>(
    projector: impl Project,
    points: &[PackedPoint],
    footprint: f32,
    view: &View,
    out: &mut [Splat],
) {
    let (chunks, rest) = points.as_chunks::<T>();
    let (out_chunks, out_rest) = out.as_chunks_mut::<T>();
    for (chunk, out) in chunks.iter().zip(out_chunks) {
        projector.lanes(chunk, footprint, view, out);
    }
    if !rest.is_empty() {
        let mut input = [PackedPoint::default(); T];
        let mut block = [Splat::default(); T];
        input[..rest.len()].copy_from_slice(rest);
        projector.lanes(&input, footprint, view, &mut block);
        out_rest.copy_from_slice(&block[..rest.len()]);
    }
}

/// [`project_block`]: the baseline instruction set.
#[derive(Clone, Copy)]
struct Baseline;

impl Project for Baseline {
    #[inline(always)]
    fn lanes<const N: usize>(
        self,
        points: &[PackedPoint; N],
        footprint: f32,
        view: &View,
        out: &mut [Splat; N],
    ) {
        project_block(points, footprint, view, out);
    }

    #[inline(always)]
    fn rest(self, points: &[PackedPoint], footprint: f32, view: &View, out: &mut [Splat]) {
        by_blocks::<TAIL>(self, points, footprint, view, out);
    }
}

/// Sixteen points per instruction where the processor has AVX-512
/// ([`avx512::project_splats`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Avx512(pulp::x86::V4);

#[cfg(target_arch = "x86_64")]
impl Project for Avx512 {
    #[inline(always)]
    fn lanes<const N: usize>(
        self,
        points: &[PackedPoint; N],
        footprint: f32,
        view: &View,
        out: &mut [Splat; N],
    ) {
        const { assert!(N.is_multiple_of(16)) };
        avx512::project_splats(self.0, points, footprint, view, out);
    }

    #[inline(always)]
    fn rest(self, points: &[PackedPoint], footprint: f32, view: &View, out: &mut [Splat]) {
        by_blocks::<16>(self, points, footprint, view, out);
    }

    #[inline(always)]
    fn depth_3x3(
        self,
        depth: &mut [u32],
        first: usize,
        width: usize,
        key: u32,
        limit: f32,
    ) -> bool {
        avx512::depth_3x3(self.0, depth, first, width, key, limit)
    }

    #[inline(always)]
    fn accumulate_3x3(
        self,
        depth: &[u32],
        accum: &mut [[u64; 2]],
        first: usize,
        width: usize,
        limit: f32,
        sample: u64,
        range_sample: u64,
    ) {
        avx512::accumulate_3x3(
            self.0,
            depth,
            accum,
            first,
            width,
            limit,
            sample,
            range_sample,
        );
    }
}

/// Eight points per instruction where the processor has AVX2 but not AVX-512
/// ([`avx2::project_splats`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Avx2(pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl Project for Avx2 {
    #[inline(always)]
    fn lanes<const N: usize>(
        self,
        points: &[PackedPoint; N],
        footprint: f32,
        view: &View,
        out: &mut [Splat; N],
    ) {
        const { assert!(N.is_multiple_of(8)) };
        avx2::project_splats(self.0, points, footprint, view, out);
    }

    #[inline(always)]
    fn rest(self, points: &[PackedPoint], footprint: f32, view: &View, out: &mut [Splat]) {
        by_blocks::<8>(self, points, footprint, view, out);
    }
}

/// The arguments of [`project_and_depth`] but the projector.
struct PassOneArgs<'a, D> {
    points: &'a [PackedPoint],
    cells: &'a [DrawCell],
    view: &'a View,
    camera: &'a Camera,
    depth: D,
    splats: &'a mut [Splat],
}

impl<D: Depths> PassOneArgs<'_, D> {
    #[inline(always)]
    fn run(self, projector: impl Project) -> usize {
        let a = self;
        project_and_depth(
            a.points, a.cells, a.view, a.camera, a.depth, a.splats, projector,
        )
    }
}

/// The depth buffer as pass 1 writes it ([`Depths::splat`]): shared by the threads of
/// a parallel pass (`&[AtomicU32]`, atomic minima), or held by one thread
/// (`&mut [u32]`, plain keys, several pixels at a time). A trait, so that each pass
/// is compiled for its buffer.
trait Depths {
    /// Take the minimum of the splat's range and the depth of each pixel it covers.
    /// Returns whether the splat may still add a sample in pass 2: not if every pixel
    /// already held a range below its band (depths only decrease, so pass 2 would
    /// reject it everywhere; the test is pass 2's own, on a depth at least the final
    /// one).
    fn splat(&mut self, s: &Splat, view: &View, projector: impl Project) -> bool;
}

impl Depths for &[AtomicU32] {
    #[inline(always)]
    fn splat(&mut self, s: &Splat, view: &View, _: impl Project) -> bool {
        let (key, limit) = (s.0[2], s.limit_m());
        let mut hidden = true;
        s.for_each_pixel(view, |k| {
            let before = self[k].fetch_min(key, Ordering::Relaxed);
            // An empty pixel's key is a NaN: never below the limit.
            hidden &= f32::from_bits(before) < limit;
        });
        !hidden
    }
}

impl Depths for &mut [u32] {
    #[inline(always)]
    fn splat(&mut self, s: &Splat, view: &View, projector: impl Project) -> bool {
        let (key, limit) = (s.0[2], s.limit_m());
        // Most splats: a single pixel, decided first (before the 3 × 3 test).
        if s.width() == 1 {
            let k = s.single_pixel();
            let before = self[k];
            self[k] = key.min(before);
            return !(f32::from_bits(before) < limit);
        }
        if let Some(first) = s.whole_3x3(view, self.len()) {
            return projector.depth_3x3(self, first, view.width as usize, key, limit);
        }
        let mut hidden = true;
        s.for_each_pixel(view, |k| {
            // Branch-free: whether a point is nearer is unpredictable.
            let before = self[k];
            self[k] = key.min(before);
            hidden &= f32::from_bits(before) < limit;
        });
        !hidden
    }
}

/// [`project_and_depth`] with a projector, to run compiled for its instruction set
/// (a struct, not a closure: pulp's `with_simd` is compiled for the instruction set,
/// and only an `#[inline(always)]` method is sure to be inlined into it).
struct PassOne<'a, D, P>(PassOneArgs<'a, D>, P);

impl<D: Depths, P: Project> pulp::WithSimd for PassOne<'_, D, P> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> usize {
        self.0.run(self.1)
    }
}

/// [`project_and_depth`] on the widest instruction set found at run time (looked up
/// once per call, a batch of cells): AVX-512, else AVX2, else the baseline.
fn widest_pass_one(
    points: &[PackedPoint],
    cells: &[DrawCell],
    view: &View,
    camera: &Camera,
    depth: impl Depths,
    splats: &mut [Splat],
) -> usize {
    let args = PassOneArgs {
        points,
        cells,
        view,
        camera,
        depth,
        splats,
    };
    #[cfg(target_arch = "x86_64")]
    {
        // `Simd::vectorize`, not the inherent one (which takes a closure).
        if let Some(simd) = isa::avx512() {
            return pulp::Simd::vectorize(simd, PassOne(args, Avx512(simd)));
        }
        if let Some(simd) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(simd, PassOne(args, Avx2(simd)));
        }
    }
    args.run(Baseline)
}

/// [`project_point`] of `N` points of a camera without lens distortion, with the
/// same operations in the same order (so bit for bit the same splats), several points
/// per instruction: explicit SSE2 on x86-64 ([`sse2::project_splats`]), elsewhere
/// branch-free code that the compiler vectorises ([`project_lanes_portable`]); the
/// [`Baseline`] projector (wider ones: [`Avx512`], [`Avx2`]). Unseen
/// points get the width [`NOT_DRAWN`] (their other fields are then meaningless).
#[inline(always)]
fn project_block<const N: usize>(
    points: &[PackedPoint; N],
    footprint: f32,
    view: &View,
    out: &mut [Splat; N],
) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    sse2::project_splats(points, footprint, view, out);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    {
        let mut lanes = Lanes::<N>::new();
        project_lanes_portable(points, footprint, view, &mut lanes);
        for (k, out) in out.iter_mut().enumerate() {
            *out = lanes.splat(k, view);
        }
    }
}

/// The lanes of [`project_block`] without explicit vector instructions: branch-free,
/// so that the compiler computes several points per instruction where it can.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
#[inline(always)]
fn project_lanes_portable<const N: usize>(
    points: &[PackedPoint; N],
    footprint: f32,
    view: &View,
    out: &mut Lanes<N>,
) {
    let r = view.point_rotation;
    let t = view.point_translation;
    for k in 0..N {
        let [x, y, z] = points[k].steps.map(f32::from);
        // `Mat3 * Vec3 + Vec3` as glam computes it.
        let pcx = r.x_axis.x * x + r.y_axis.x * y + r.z_axis.x * z + t.x;
        let pcy = r.x_axis.y * x + r.y_axis.y * y + r.z_axis.y * z + t.y;
        let pcz = r.x_axis.z * x + r.y_axis.z * y + r.z_axis.z * z + t.z;
        let rho = (pcx * pcx + pcy * pcy + pcz * pcz).sqrt();
        let dd = pcz + view.xi * rho;
        let in_domain = (dd > 0.0) & ((view.xi <= 1.0) | (view.xi * pcz + rho > 0.0));
        let inv_d = 1.0 / dd;
        let u = view.alpha_u * (pcx * inv_d) + view.skew * (pcy * inv_d) + view.u0;
        let v = view.alpha_v * (pcy * inv_d) + view.v0;
        let size = footprint * inv_d * ((rho + view.xi * pcz) * inv_d).max(1.0);
        let n = splat_width(size, view.max_width);
        let (pu, pv) = (
            first_px(u, n) - view.origin[0],
            first_px(v, n) - view.origin[1],
        );
        let in_image = (pu + n > 0) & (pv + n > 0) & (pu < view.width) & (pv < view.height);
        out.iu[k] = pu;
        out.iv[k] = pv;
        out.width[k] = if in_domain & in_image {
            n
        } else {
            i32::from(NOT_DRAWN)
        };
        out.range[k] = rho;
        out.limit[k] = band_limit(rho, view);
        out.intensity[k] = i32::from(points[k].intensity);
    }
}

impl Splat {
    /// The pixel of a single-pixel splat (drawn splats reach the image, and one pixel
    /// wide they are inside it): its index in the region.
    #[inline(always)]
    fn single_pixel(&self) -> usize {
        self.0[0] as usize
    }

    /// The top-left pixel of a 3 × 3 splat inside the image whose rows can be read
    /// four pixels at a time from a buffer of `len` pixels (every 3 × 3 splat but at
    /// the buffer's last pixels).
    #[inline(always)]
    fn whole_3x3(&self, view: &View, len: usize) -> Option<usize> {
        let (iu, iv) = (self.iu(), self.iv());
        let inside = self.width() == 3
            && iu >= 0
            && iv >= 0
            && iu + 3 <= view.width
            && iv + 3 <= view.height;
        if !inside {
            return None;
        }
        let first = iv as usize * view.width as usize + iu as usize;
        (first + 2 * view.width as usize + 4 <= len).then_some(first)
    }

    /// Call `f` with the index of every pixel the splat covers, clipped to the image
    /// (a drawn splat: `width != NOT_DRAWN`, so it reaches the image).
    #[inline(always)]
    fn for_each_pixel(&self, view: &View, mut f: impl FnMut(usize)) {
        let w = view.width as usize;
        let (iu, iv, n) = (self.iu(), self.iv(), i32::from(self.width()));
        if n == 1 {
            // Most splats: a single pixel, inside the image.
            f(self.single_pixel());
            return;
        }
        if n == 3 && iu >= 0 && iv >= 0 && iu + 3 <= view.width && iv + 3 <= view.height {
            // 3 × 3 splats inside the image, without loops (whose exits a processor
            // cannot predict); the results do not depend on the order of the pixels.
            let first = iv as usize * w + iu as usize;
            for row in [first, first + w, first + 2 * w] {
                f(row);
                f(row + 1);
                f(row + 2);
            }
            return;
        }
        let (u0, u1) = (iu.max(0) as usize, (iu + n).min(view.width) as usize);
        let (v0, v1) = (iv.max(0) as usize, (iv + n).min(view.height) as usize);
        for row in v0..v1 {
            for k in row * w + u0..row * w + u1 {
                f(k);
            }
        }
    }
}

/// Pass 2 keeps a sample of range `range_m` at the pixels whose nearest range is at
/// least this (the sample is within the depth band of the nearest).
#[inline(always)]
fn band_limit(range_m: f32, view: &View) -> f32 {
    range_m / view.band_factor
}

/// Pass 1 over the points of some cells: project each point once, take the minimum
/// depth key over its footprint, and keep its splat in `splats` if it may add a sample
/// (in draw order, from the front). Returns the number kept.
#[inline(always)]
fn project_and_depth(
    points: &[PackedPoint],
    cells: &[DrawCell],
    view: &View,
    camera: &Camera,
    mut depth: impl Depths,
    splats: &mut [Splat],
    projector: impl Project,
) -> usize {
    let mut kept = 0;
    // The splats of up to `STAGE` points of a cell, projected here (in the first level
    // of cache) before the visible ones are kept in `splats`.
    let mut stage = [Splat::default(); STAGE];
    let mut warm = Warm::new(points, cells);
    warm.advance(WARM_AHEAD);
    for cell in cells {
        let start = cell.start as usize;
        let footprint = cell.spacing_m * view.alpha * view.splat_scale;
        // The projection of this cell's points (steps from its corner).
        let view = &view.in_cell(cell.corner);
        for cell_points in points[start..start + cell.count as usize].chunks(STAGE) {
            let out = &mut stage[..cell_points.len()];
            if view.undistorted {
                let mut chunks = cell_points.chunks_exact(BLOCK);
                let mut out_chunks = out.chunks_exact_mut(BLOCK);
                for (chunk, out) in (&mut chunks).zip(&mut out_chunks) {
                    warm.advance(BLOCK);
                    let chunk: &[_; BLOCK] = chunk.try_into().expect("chunks of BLOCK points");
                    let out: &mut [_; BLOCK] = out.try_into().expect("BLOCK slots");
                    projector.lanes(chunk, footprint, view, out);
                }
                // The last points in smaller blocks, the last one padded.
                warm.advance(chunks.remainder().len());
                projector.rest(
                    chunks.remainder(),
                    footprint,
                    view,
                    out_chunks.into_remainder(),
                );
            } else {
                warm.advance(cell_points.len());
                for (p, out) in cell_points.iter().zip(out.iter_mut()) {
                    *out =
                        project_point(p, footprint, view, camera).unwrap_or_else(Splat::not_drawn);
                }
            }
            // Keep the splats that may add a sample (`kept` never passes the number of
            // points read, so its slot exists).
            for s in out.iter().filter(|s| s.drawn()) {
                let visible = depth.splat(s, view, projector);
                splats[kept] = *s;
                kept += usize::from(visible);
            }
        }
    }
    warm.finish();
    kept
}

/// Asks for the cache lines of the points to draw a steady [`WARM_AHEAD`] points
/// ahead of the one being drawn, a few lines per block of points: the cells are drawn
/// front to back, not in memory order, so each starts a new stream that the hardware
/// prefetcher would only follow after a few misses, and a whole cell's lines asked
/// for at once would fill the processor's miss buffers and stall it (the cell-at-a-time
/// version spent 15 % of pass 1 on its prefetch instructions). A prefetch instruction
/// per line on x86-64; elsewhere a load per line, whose values are xor-ed and kept so
/// that they are not optimised away. Only the time depends on it.
struct Warm<'a> {
    points: &'a [PackedPoint],
    cells: &'a [DrawCell],
    /// The cell, and the point in it, to ask for next.
    cell: usize,
    point: usize,
    /// The group of points (a cache line's worth) asked for last in this cell.
    last_group: usize,
    loaded: u32,
}

impl<'a> Warm<'a> {
    fn new(points: &'a [PackedPoint], cells: &'a [DrawCell]) -> Self {
        Self {
            points,
            cells,
            cell: 0,
            point: 0,
            last_group: 0,
            loaded: 0,
        }
    }

    /// Ask for the next `n` points of the draw list.
    #[inline(always)]
    fn advance(&mut self, mut n: usize) {
        while n > 0 {
            let Some(cell) = self.cells.get(self.cell) else {
                return;
            };
            let count = cell.count as usize;
            let take = n.min(count - self.point);
            if take > 0 {
                let first = cell.start as usize + self.point;
                let last = first + take - 1;
                // One point per 64-byte line, each line once within a cell.
                let mut group = first / POINTS_PER_LINE;
                if self.point > 0 {
                    group = group.max(self.last_group + 1);
                }
                while group <= last / POINTS_PER_LINE {
                    self.touch((group * POINTS_PER_LINE).max(first));
                    group += 1;
                }
                self.last_group = last / POINTS_PER_LINE;
                n -= take;
                self.point += take;
            }
            if self.point == count {
                self.cell += 1;
                self.point = 0;
            }
        }
    }

    #[inline(always)]
    fn touch(&mut self, index: usize) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
        safe_arch::prefetch_t0(&self.points[index]);
        #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
        {
            self.loaded ^= u32::from(self.points[index].steps[0]);
        }
    }

    /// Keep the loads (an optimiser could drop loads whose value is unused).
    fn finish(self) {
        std::hint::black_box(self.loaded);
    }
}

/// Resolve a row of the valid pixels' box: the mean intensity and range of a pixel's
/// samples if it has some (a hit), the background and an infinite range if it has
/// none (sky), 0 and NaN outside the valid region (masked). Every pixel's means are
/// computed, and kept or not, so that the loop has no branch. Returns the hits. Leaves
/// the row's keys cleared ([`EMPTY`], 0 at masked pixels: `Renderer::valid_bits`) and
/// its sums zero, for the next rendering.
#[inline(always)]
fn resolve_row(
    depth: &mut [u32],
    accum: &mut [[u64; 2]],
    valid: &[bool],
    background: f32,
    intensity: &mut [f32],
    range_m: &mut [f32],
    status: &mut [PixelStatus],
) -> usize {
    let mut hits = 0;
    let pixels = depth
        .iter()
        .zip(accum.iter())
        .zip(valid)
        .zip(intensity.iter_mut())
        .zip(range_m.iter_mut())
        .zip(status.iter_mut());
    for (((((&key, &[sums, range_sum]), &valid), intensity), range_m), status) in pixels {
        let count = sums & COUNT_MASK;
        let hit = key != EMPTY && count != 0;
        let n = count as f64;
        let mean = ((sums >> COUNT_BITS) as f64 / (n * f64::from(INTENSITY_SCALE))) as f32;
        let mean_range = (range_sum as f64 / (n * f64::from(RANGE_SCALE))) as f32;
        (*intensity, *range_m, *status) = match (valid, hit) {
            (false, _) => (0.0, f32::NAN, PixelStatus::Masked),
            (true, true) => (mean, mean_range, PixelStatus::Hit),
            (true, false) => (background, f32::INFINITY, PixelStatus::Sky),
        };
        hits += usize::from(valid && hit);
    }
    // Cleared while the row is in the first level of cache.
    for (key, &valid) in depth.iter_mut().zip(valid) {
        *key = if valid { EMPTY } else { 0 };
    }
    accum.fill([0; 2]);
    hits
}

/// A splat's two samples: its intensity (16-bit fixed point, above a count of one)
/// and its range (fixed point).
#[inline(always)]
fn samples(s: &Splat) -> (u64, u64) {
    let sample = (u64::from(s.intensity()) << COUNT_BITS) | 1;
    // Through i64: the same for any range below 2^51 m, and cheaper than to u64.
    let range_sample = (s.range_m() * RANGE_SCALE + 0.5) as i64 as u64;
    (sample, range_sample)
}

/// Pass 2 over the splats of pass 1, shared by the threads of a parallel pass: add
/// each sample to the pixels it covers where it lies within the depth band of the
/// nearest.
#[inline(always)]
fn accumulate(splats: &[Splat], view: &View, depth: &[AtomicU32], accum: &[[AtomicU64; 2]]) {
    for s in splats.iter().filter(|s| s.drawn()) {
        let (sample, range_sample) = samples(s);
        let limit = s.limit_m();
        s.for_each_pixel(view, |k| {
            if f32::from_bits(depth[k].load(Ordering::Relaxed)) >= limit {
                let [slot, range] = &accum[k];
                slot.fetch_add(sample, Ordering::Relaxed);
                range.fetch_add(range_sample, Ordering::Relaxed);
            }
        });
    }
}

/// [`accumulate`] on one thread, on plain keys and sums: 3 × 3 splats whole rows at a
/// time where the instruction set allows ([`Project::accumulate_3x3`]), the others
/// without a branch (whether a sample is within the band is unpredictable).
#[inline(always)]
fn accumulate_own(
    splats: &[Splat],
    view: &View,
    depth: &[u32],
    accum: &mut [[u64; 2]],
    projector: impl Project,
) {
    for s in splats.iter().filter(|s| s.drawn()) {
        let (sample, range_sample) = samples(s);
        let limit = s.limit_m();
        if s.width() == 1 {
            let k = s.single_pixel();
            let keep = 0u64.wrapping_sub(u64::from(f32::from_bits(depth[k]) >= limit));
            let sums = &mut accum[k];
            *sums = [sums[0] + (sample & keep), sums[1] + (range_sample & keep)];
            continue;
        }
        if let Some(first) = s.whole_3x3(view, depth.len()) {
            let width = view.width as usize;
            projector.accumulate_3x3(depth, accum, first, width, limit, sample, range_sample);
            continue;
        }
        s.for_each_pixel(view, |k| {
            let keep = 0u64.wrapping_sub(u64::from(f32::from_bits(depth[k]) >= limit));
            let sums = &mut accum[k];
            *sums = [sums[0] + (sample & keep), sums[1] + (range_sample & keep)];
        });
    }
}

/// The arguments of [`accumulate_own`] with a projector (its instruction set), to run
/// compiled for it.
struct PassTwo<'a, P> {
    splats: &'a [Splat],
    view: &'a View,
    depth: &'a [u32],
    accum: &'a mut [[u64; 2]],
    projector: P,
}

impl<P: Project> pulp::WithSimd for PassTwo<'_, P> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        accumulate_own(
            self.splats,
            self.view,
            self.depth,
            self.accum,
            self.projector,
        );
    }
}

/// [`accumulate_own`] on the widest instruction set found at run time.
fn widest_pass_two(splats: &[Splat], view: &View, depth: &[u32], accum: &mut [[u64; 2]]) {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(simd) = isa::avx512() {
            let projector = Avx512(simd);
            return pulp::Simd::vectorize(
                simd,
                PassTwo {
                    splats,
                    view,
                    depth,
                    accum,
                    projector,
                },
            );
        }
        if let Some(simd) = pulp::x86::V3::try_new() {
            let projector = Avx2(simd);
            return pulp::Simd::vectorize(
                simd,
                PassTwo {
                    splats,
                    view,
                    depth,
                    accum,
                    projector,
                },
            );
        }
    }
    accumulate_own(splats, view, depth, accum, Baseline);
}

#[cfg(test)]
mod tests {
    //! The vectorised per-point kernels against their scalar references, and the
    //! occlusion test's rectangle against the splats it must hold.

    use glam::Vec3;
    use proptest::prelude::*;
    use ucm::{Camera, Intrinsics, ValidRegion};

    use super::*;

    /// A 320×240 camera without distortion, its principal point at the centre, and
    /// rendering options with the given splats.
    fn test_setup(
        alpha_u: f32,
        aspect: f32,
        skew: f32,
        xi: f32,
        splat_scale: f32,
        max_radius: u32,
    ) -> (Camera, RenderOptions) {
        let camera = Camera::new(
            Intrinsics {
                alpha_u: f64::from(alpha_u),
                alpha_v: f64::from(alpha_u * aspect),
                u0: 159.5,
                v0: 119.5,
                xi: f64::from(xi),
                skew: f64::from(skew),
            },
            None,
            320,
            240,
            ValidRegion::Full,
        )
        .unwrap();
        let options = RenderOptions {
            splat_scale,
            max_splat_radius_px: max_radius,
            ..RenderOptions::default()
        };
        (camera, options)
    }

    /// The splats of `points` by every projector this processor runs, in pass 1's
    /// own instruction set (its first [`BLOCK`] as a block, the rest, 37 points, as a
    /// cell's last ones), each checked to agree with the baseline projector; returns
    /// the baseline's. The AVX-512 and AVX2 projectors are checked where the processor
    /// has them.
    fn with_every_projector(
        points: &[PackedPoint; BLOCK],
        footprint: f32,
        view: &View,
    ) -> Vec<Splat> {
        struct Run<'a, P> {
            points: &'a [PackedPoint; BLOCK],
            footprint: f32,
            view: &'a View,
            projector: P,
        }
        impl<P: Project> pulp::WithSimd for Run<'_, P> {
            type Output = Vec<Splat>;
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _: S) -> Vec<Splat> {
                let mut out = vec![Splat::default(); BLOCK + 37];
                let (block, rest) = out.split_at_mut(BLOCK);
                let block: &mut [Splat; BLOCK] = block.try_into().unwrap();
                self.projector
                    .lanes(self.points, self.footprint, self.view, block);
                self.projector
                    .rest(&self.points[..37], self.footprint, self.view, rest);
                out
            }
        }
        let baseline = pulp::Simd::vectorize(
            pulp::Scalar,
            Run {
                points,
                footprint,
                view,
                projector: Baseline,
            },
        );
        let same = |a: &[Splat], b: &[Splat]| {
            a.iter()
                .zip(b)
                .all(|(a, b)| a.drawn() == b.drawn() && (!a.drawn() || a == b))
        };
        assert!(
            same(&baseline[BLOCK..], &baseline[..37]),
            "a cell's last points differ from the same points in a block"
        );
        #[cfg(target_arch = "x86_64")]
        {
            let check = |wide: Vec<Splat>, name: &str| {
                assert!(
                    same(&wide, &baseline),
                    "{name} and baseline projectors differ"
                );
            };
            if let Some(simd) = pulp::x86::V4::try_new() {
                let projector = Avx512(simd);
                check(
                    pulp::Simd::vectorize(
                        simd,
                        Run {
                            points,
                            footprint,
                            view,
                            projector,
                        },
                    ),
                    "AVX-512",
                );
            }
            if let Some(simd) = pulp::x86::V3::try_new() {
                let projector = Avx2(simd);
                check(
                    pulp::Simd::vectorize(
                        simd,
                        Run {
                            points,
                            footprint,
                            view,
                            projector,
                        },
                    ),
                    "AVX2",
                );
            }
        }
        baseline
    }

    /// 40 000 points in a 40 × 40 × 12 m box around the origin (none within 1 m of
    /// it), random intensities.
    fn scattered_cloud() -> PointCloud {
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut positions = Vec::new();
        let mut intensities = Vec::new();
        while positions.len() < 40_000 {
            let p = DVec3::new(
                rng.unit() * 40.0 - 20.0,
                rng.unit() * 40.0 - 20.0,
                rng.unit() * 12.0 - 4.0,
            );
            if p.length() > 1.0 {
                positions.push(p);
                intensities.push(rng.unit() as f32);
            }
        }
        PointCloud::from_points(DVec3::ZERO, &positions, &intensities, None, Some(0.2)).unwrap()
    }

    /// A rendering that did not reach its resolve (its buffers left with stale keys
    /// and sums, as a panic would leave them) is cleared by the next one, which then
    /// draws a fresh renderer's frame bit for bit; and the test fails if it is not.
    #[test]
    fn a_rendering_left_unfinished_is_cleared_by_the_next() {
        let (camera, options) = test_setup(80.0, 1.0, 0.0, 0.9, 1.25, 8);
        let options = RenderOptions {
            parallel: false,
            ..options
        };
        let cloud = scattered_cloud();
        let pose = Isometry3::from_pose_vector([0.3, -0.2, 0.1, 0.05, -0.1, 0.2]).unwrap();
        let render = |renderer: &mut Renderer| {
            let mut frame = Frame::for_camera(&camera);
            renderer.render(&cloud, &pose, &mut frame).unwrap();
            frame
        };
        let fresh = render(&mut Renderer::new(camera.clone(), options).unwrap());
        assert!(fresh.counts().0 > 1_000);
        let poisoned = |cleared: bool| {
            let mut renderer = Renderer::new(camera.clone(), options).unwrap();
            render(&mut renderer);
            plain::depths(&mut renderer.depth).fill(0);
            plain::sums(&mut renderer.accum).fill([1, 1]);
            renderer.cleared = cleared;
            render(&mut renderer)
        };
        assert!(poisoned(false).bitwise_eq(&fresh));
        // The flag is what clears them: claimed clear, the stale buffers show.
        assert!(!poisoned(true).bitwise_eq(&fresh));
    }

    /// The frame drawn into the box of the valid pixels equals, bit for bit, the one
    /// drawn into the whole image (what the box leaves out lands on masked pixels), on
    /// one thread and on several, with and without occlusion culling.
    #[test]
    fn the_valid_pixels_box_draws_the_frame_of_the_whole_image() {
        let camera = Camera::new(
            Intrinsics {
                alpha_u: 60.0,
                alpha_v: 60.0,
                u0: 159.5,
                v0: 119.5,
                xi: 0.9,
                skew: 0.0,
            },
            None,
            320,
            240,
            ValidRegion::Annulus(ucm::Annulus {
                center_px: [159.5, 119.5],
                inner_radius_px: 25.0,
                outer_radius_px: 100.0,
            }),
        )
        .unwrap();
        let region = Region::of(&camera);
        assert!(region.len() < 320 * 200, "{region:?}");
        // Points all around the camera, many hidden behind others, some seen only
        // outside the annulus.
        let cloud = scattered_cloud();
        let pose = Isometry3::from_pose_vector([0.3, -0.2, 0.1, 0.05, -0.1, 0.2]).unwrap();
        let whole = Region {
            u0: 0,
            v0: 0,
            width: 320,
            height: 240,
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        for (parallel, occlusion_culling) in [(false, true), (true, true), (false, false)] {
            let options = RenderOptions {
                parallel,
                occlusion_culling,
                ..RenderOptions::default()
            };
            let [(full, full_hit), (cropped, hit)] = [whole, region].map(|r| {
                let mut renderer = Renderer::with_region(camera.clone(), options, r).unwrap();
                let mut frame = Frame::for_camera(&camera);
                let stats = pool.install(|| renderer.render(&cloud, &pose, &mut frame).unwrap());
                (frame, stats.pixels_hit)
            });
            assert!(hit > 5_000, "{hit} pixels hit");
            assert_eq!(hit, full_hit);
            assert_eq!(cropped.status, full.status);
            let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&cropped.intensity), bits(&full.intensity));
            assert_eq!(bits(&cropped.range_m), bits(&full.range_m));
        }
    }

    /// Regions of the 320×240 test image: the whole image or a box inside it.
    fn regions() -> impl Strategy<Value = Region> {
        (0usize..60, 0usize..40, 0usize..60, 0usize..40).prop_map(|(u0, v0, du, dv)| Region {
            u0,
            v0,
            width: 320 - u0 - du,
            height: 240 - v0 - dv,
        })
    }

    /// A key for the 3 × 3 kernels' tests: empty (a NaN), or a range in metres whose
    /// bits are near `limit`'s (so that both sides of every comparison occur).
    fn key_near(choice: u8, offset: i32, limit: f32) -> u32 {
        match choice {
            0 => EMPTY,
            _ => (limit.to_bits() as i64 + i64::from(offset)).clamp(0, 0x7F7F_FFFF) as u32,
        }
    }

    /// Both 3 × 3 kernels of a projector against the baseline's plain loops on
    /// copies of the same buffers: the same keys, sums and result.
    #[allow(clippy::too_many_arguments)]
    fn same_3x3(
        projector: impl Project,
        depth: &[u32],
        accum: &[[u64; 2]],
        first: usize,
        width: usize,
        key: u32,
        limit: f32,
        samples: (u64, u64),
    ) -> Result<(), TestCaseError> {
        let (mut fast, mut plain) = (depth.to_vec(), depth.to_vec());
        let seen = projector.depth_3x3(&mut fast, first, width, key, limit);
        let expected = Baseline.depth_3x3(&mut plain, first, width, key, limit);
        prop_assert_eq!(seen, expected);
        prop_assert_eq!(&fast, &plain);
        let (mut fast, mut plain) = (accum.to_vec(), accum.to_vec());
        let (a, b) = samples;
        projector.accumulate_3x3(depth, &mut fast, first, width, limit, a, b);
        Baseline.accumulate_3x3(depth, &mut plain, first, width, limit, a, b);
        prop_assert_eq!(fast, plain);
        Ok(())
    }

    proptest! {
        /// The plain loops of the 3 × 3 kernels are the per-pixel passes: each pixel
        /// takes the minimum key, the splat is seen if a pixel held a key not below the
        /// limit (or none), and each pixel at least the limit adds both samples; the
        /// AVX-512 kernels (where the processor has them) give the same buffers, the
        /// fourth pixel of each row and every other pixel untouched.
        #[test]
        fn kernels_3x3_are_the_per_pixel_passes(
            width in 4usize..24,
            rows in 3usize..8,
            cells in prop::collection::vec((0u8..4, -3i32..4, any::<u16>(), any::<u16>()), 24 * 8),
            at in any::<prop::sample::Index>(),
            key in (0u8..4, -3i32..4),
            limit in 0.5f32..50.0,
            sample in any::<(u32, u32)>(),
        ) {
            let len = width * rows;
            let depth: Vec<u32> = cells[..len].iter().map(|&(c, o, _, _)| key_near(c, o, limit)).collect();
            let accum: Vec<[u64; 2]> = cells[..len]
                .iter()
                .map(|&(_, _, a, b)| [u64::from(a) << 20, u64::from(b) << 8])
                .collect();
            // Any top-left pixel with room for four pixels from its last row's first.
            let first = at.index(len - 2 * width - 3);
            let key = key_near(key.0.max(1), key.1, limit);
            let samples = (u64::from(sample.0), u64::from(sample.1));
            let (mut plain, mut expected) = (depth.clone(), depth.clone());
            let seen = Baseline.depth_3x3(&mut plain, first, width, key, limit);
            let mut hidden = true;
            let mut sums = accum.clone();
            for row in [first, first + width, first + 2 * width] {
                for k in row..row + 3 {
                    hidden &= f32::from_bits(expected[k]) < limit;
                    expected[k] = expected[k].min(key);
                    if f32::from_bits(depth[k]) >= limit {
                        sums[k][0] += samples.0;
                        sums[k][1] += samples.1;
                    }
                }
            }
            prop_assert_eq!(seen, !hidden);
            prop_assert_eq!(&plain, &expected);
            let mut got = accum.clone();
            Baseline.accumulate_3x3(&depth, &mut got, first, width, limit, samples.0, samples.1);
            prop_assert_eq!(&got, &sums);
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = pulp::x86::V4::try_new() {
                same_3x3(Avx512(simd), &depth, &accum, first, width, key, limit, samples)?;
            }
        }

        /// `floor_small` is `floor` over its whole domain, halves and negative values
        /// included.
        #[test]
        fn floor_small_is_floor(x in -4_000_000.0f32..4_000_000.0, halves in -60_000i32..60_000) {
            prop_assert_eq!(floor_small(x), x.floor() as i32);
            let half = halves as f32 * 0.5;
            prop_assert_eq!(floor_small(half), half.floor() as i32);
            prop_assert_eq!(floor_small(-x.abs() * 1e-6), (-x.abs() * 1e-6).floor() as i32);
        }

        /// The occlusion test's rectangle of a cell holds every pixel that a splat of a
        /// point of the cell's bounding sphere covers: the disc bound (ξ ≤ 1) and the
        /// annular sector (ξ > 1), for random intrinsics, spheres and splat sizes.
        #[test]
        fn image_rect_holds_every_splat(
            seed in any::<u64>(),
            alpha_u in 50.0f32..400.0,
            aspect in 0.8f32..1.25,
            skew in -3.0f32..3.0,
            xi in 0.0f32..2.0,
            direction in prop::array::uniform3(-1.0f32..1.0),
            distance_m in 0.5f32..200.0,
            radius_m in 0.02f32..3.0,
            spacing_m in 0.005f32..0.3,
            splat_scale in 0.5f32..3.0,
            max_radius in 0u32..12,
            region in regions(),
        ) {
            let (camera, options) = test_setup(alpha_u, aspect, skew, xi, splat_scale, max_radius);
            let renderer = Renderer::new(camera.clone(), options).unwrap();
            // Steps of a metre from the cloud's origin: points are where they are.
            let view = View::new(&camera, &options, region, DMat3::IDENTITY, DVec3::ZERO, 1.0);
            let center = Vec3::from_array(direction).normalize_or(Vec3::Z) * distance_m;
            let candidate = Candidate {
                cell: DrawCell { start: 0, count: 1, spacing_m, corner: Vec3::ZERO },
                center,
                radius: radius_m,
                nearest_m: (distance_m - radius_m).max(0.0),
            };
            let Some([ru0, ru1, rv0, rv1]) = renderer.image_rect(&candidate, &view) else {
                return Ok(()); // no bound claimed
            };
            let footprint = spacing_m * view.alpha * splat_scale;
            let mut rng = crate::rng::SplitMix64::new(seed);
            for _ in 0..256 {
                // A point of the sphere (its surface included).
                let offset = Vec3::new(
                    rng.unit() as f32 * 2.0 - 1.0,
                    rng.unit() as f32 * 2.0 - 1.0,
                    rng.unit() as f32 * 2.0 - 1.0,
                );
                let offset = offset.clamp_length_max(1.0) * radius_m;
                let p = center + offset;
                let Some(splat) = project_steps(p, 32_768, footprint, &view, &camera) else {
                    continue;
                };
                splat.for_each_pixel(&view, |k| {
                    let (u, v) = (k % region.width, k / region.width);
                    assert!(
                        (ru0..=ru1).contains(&u) && (rv0..=rv1).contains(&v),
                        "pixel ({u}, {v}) of a splat of {p} outside [{ru0}, {ru1}] x [{rv0}, {rv1}]"
                    );
                });
            }
        }

        /// A block of points (of [`BLOCK`], and its first [`TAIL`] as a tail block)
        /// projects to exactly the splats of the scalar kernel: steps of 1 µm to
        /// 10 cm, cells' corners near the viewpoint, metres and kilometres away, points
        /// behind the viewpoint, beyond the model's domain (ξ > 1), off the image, or
        /// at the viewpoint itself included.
        #[test]
        fn project_block_equals_project_point(
            seed in any::<u64>(),
            axis_angle in prop::array::uniform3(-3.2f64..3.2),
            translation in prop::array::uniform3(-5.0f64..5.0),
            alpha_u in 20.0f32..400.0,
            aspect in 0.8f32..1.25,
            skew in -3.0f32..3.0,
            xi in 0.0f32..2.5,
            spacing_m in 0.001f32..0.5,
            splat_scale in 0.5f32..3.0,
            max_radius in 0u32..12,
            region in regions(),
            step_exponent in -6i32..=-1,
            corner_scale in prop::sample::select(vec![0.0f64, 0.3, 3.0, 30.0, 3000.0]),
        ) {
            let (camera, options) = test_setup(alpha_u, aspect, skew, xi, splat_scale, max_radius);
            let axis = DVec3::from_array(axis_angle);
            let view = View::new(
                &camera,
                &options,
                region,
                DMat3::from_axis_angle(axis.normalize_or(DVec3::Z), axis.length()),
                DVec3::from_array(translation),
                10f64.powi(step_exponent),
            );
            let mut rng = crate::rng::SplitMix64::new(seed);
            let corner = [0.0; 3].map(|_: f64| (rng.unit() * 2.0 - 1.0) * corner_scale);
            let mut points = [PackedPoint::default(); BLOCK];
            for (k, p) in points.iter_mut().enumerate() {
                // Near the corner, and across the whole cell.
                let range = [16, 1024, 65_536][k % 3];
                p.steps = [0; 3].map(|_: u16| rng.below(range) as u16);
                p.intensity = rng.below(65_536) as u16;
            }
            // Without a corner scale, the cell's corner at the viewpoint and the first
            // point on it.
            let at_viewpoint = corner_scale == 0.0;
            if at_viewpoint {
                points[0].steps = [0; 3];
            }
            let view = view.in_cell(if at_viewpoint { Vec3::ZERO } else { view.corner(corner) });
            let footprint = spacing_m * view.alpha * splat_scale;
            let mut block = [Splat::default(); BLOCK];
            project_block(&points, footprint, &view, &mut block);
            let mut tail = [Splat::default(); TAIL];
            let first: &[PackedPoint; TAIL] = points[..TAIL].try_into().unwrap();
            project_block(first, footprint, &view, &mut tail);
            for (t, b) in tail.iter().zip(&block) {
                prop_assert_eq!(t, b);
            }
            for (p, got) in points.iter().zip(&block) {
                match project_point(p, footprint, &view, &camera) {
                    Some(want) => prop_assert_eq!(*got, want, "point {:?}", p),
                    None => prop_assert!(!got.drawn(), "point {:?}", p),
                }
            }
            // Every projector, by whole blocks and by a cell's last points.
            for (k, got) in with_every_projector(&points, footprint, &view)[..BLOCK].iter().enumerate() {
                prop_assert_eq!(got.drawn(), block[k].drawn(), "point {:?}", points[k]);
                if got.drawn() {
                    prop_assert_eq!(*got, block[k], "point {:?}", points[k]);
                }
            }
            // The portable kernel (the one of other architectures) too.
            let mut lanes = Lanes::<BLOCK>::new();
            project_lanes_portable(&points, footprint, &view, &mut lanes);
            for (k, got) in block.iter().enumerate() {
                let portable = lanes.splat(k, &view);
                prop_assert_eq!(portable.drawn(), got.drawn());
                if got.drawn() {
                    prop_assert_eq!(portable, *got);
                }
            }
        }
    }
}
