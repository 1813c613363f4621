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
//! at run time, sixteen or eight points per instruction, through `pulp`; two registers
//! of points side by side, in two phases, so that the processor overlaps more of the
//! projection's chains of dependent operations, a square root and two divisions long),
//! else in
//! explicit SSE2 on x86-64 (through `safe_arch`, four points per instruction), each
//! splat written whole as four 32-bit words (a single-pixel splat's first word is its
//! pixel's index, so that neither pass unpacks a column and a row); elsewhere with
//! branch-free arithmetic that the compiler vectorises; then it scatters their splats.
//! Every kernel gives the same bits.
//! The points 512 ahead in the draw list are prefetched, a few cache lines per block
//! (cells are drawn front to back, not in memory order). Single-pixel splats (most of
//! them) skip the square loops, and the passes take minima and add samples without a
//! branch (whether a point is nearer is unpredictable), on plain integers (each thread
//! of a parallel rendering on buffers of its own, merged between batches, `slots`):
//! on AVX-512 and on AVX2, a 3 × 3 splat (most of the others) takes its minima, and adds
//! its samples, a row of three pixels per instruction. Each point's
//! splat is bit for bit the one of the scalar reference (tested, both kernels). A
//! splat whose every pixel already holds a range below its depth band when pass 1
//! reaches it is dropped there (pass 2 would reject it everywhere, since depths only
//! decrease), so pass 2 reads only the splats that may add a sample: about 40 % of
//! those drawn at a street pose. The occlusion test of a cell stops at the first tile,
//! then the first row of its rectangle, that shows it may be visible. The buffers that
//! a pass reads at scattered pixels are first read in order (`cache`): a caller's work
//! between two renderings pushes them out of the caches.
//!
//! The modules follow the passes: `options` (the settings and what a rendering did),
//! `view` (a rendering's constants and the buffers' region), `culling` (field of view,
//! level of detail, occlusion), `cache` (buffers read in before the passes), `splat` (a
//! projected point, as pass 1 writes it and pass 2 reads it), `project` (the projection
//! of points into splats: the scalar reference and the baseline block kernel),
//! `projector` (the same on each instruction set; its kernels in `avx512`, `avx2` and
//! `sse2`, their arithmetic written once in `lanes`), `pass_one` (depth), `pass_two`
//! (accumulation) and `resolve` (means, sky, masks, hole filling); `slots` runs both
//! passes on several threads, each on buffers of its own. This file holds the
//! [`Renderer`] and the order of its passes.

use ucm::{Camera, Isometry3};

use frame::{Frame, PixelStatus};

use crate::{PointCloud, SplatError};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod cache;
mod culling;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod options;
mod pass_one;
mod pass_two;
mod project;
mod projector;
mod resolve;
mod slots;
mod splat;
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod sse2;
#[cfg(test)]
mod tests;
mod view;

pub use options::{RenderOptions, RenderStats};

use culling::{Candidate, DrawCell, tiles};
use pass_one::widest_pass_one;
use pass_two::widest_pass_two;
use slots::{MAX_RUNS, Slots};
use splat::Splat;
use view::{Region, View};

/// The first batch of points drawn before any occlusion test, and the smallest batch.
const MIN_BATCH_POINTS: usize = 16_384;

/// A renderer for one camera, owning its buffers (no allocation per frame once warm).
#[derive(Debug)]
pub struct Renderer {
    camera: Camera,
    options: RenderOptions,
    /// What the buffers below cover (pixels of the [`Region`], row-major).
    region: Region,
    depth: Vec<u32>,
    /// Per pixel: `(Σ intensity << 24) | count` and `Σ range`, fixed point,
    /// interleaved so that pass 2 touches one cache line per pixel.
    accum: Vec<[u64; 2]>,
    candidates: Vec<Candidate>,
    /// The candidates' draw order: range of the nearest point's bits, index.
    order: Vec<u64>,
    draw: Vec<DrawCell>,
    splats: Vec<Splat>,
    status: Vec<PixelStatus>,
    /// The hole filling's rows (one byte per column of the image): how many of three
    /// rows' pixels are hits, and which pixels of the middle row are candidates.
    hole_rows: [Vec<u8>; 2],
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
    /// The buffers of a parallel rendering's other threads.
    slots: Slots,
}

const EMPTY: u32 = u32::MAX;
const COUNT_BITS: u32 = 24;
const COUNT_MASK: u64 = (1 << COUNT_BITS) - 1;
const INTENSITY_SCALE: f32 = 65535.0;
/// Fixed-point scale of the range sums (1/4096 m).
const RANGE_SCALE: f32 = 4096.0;

/// The most columns and rows of a camera's image that the renderer draws: a splat's
/// first column and row are 16-bit signed integers ([`Splat`]), projections are
/// clamped to ±30 000 pixels before rounding (`project::first_px`), and splats are at
/// most about 2000 pixels wide; 16 384 keeps clear of all three.
const MAX_EXTENT_PX: usize = 16_384;

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
        let (lo, hi) = theta_range(&camera);
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
        let (valid, w) = (camera.valid_pixels(), camera.width() as usize);
        let valid_bits: Vec<u32> = (0..n)
            .map(|k| {
                let (u, v) = (region.u0 + k % region.width, region.v0 + k / region.width);
                if valid[v * w + u] { u32::MAX } else { 0 }
            })
            .collect();
        let status = vec![PixelStatus::Sky; camera.pixel_count()];
        // A parallel renderer's threads' buffers, for the pool it is made in (grown at
        // a rendering in a larger one).
        let mut slots = Slots::default();
        if options.parallel {
            slots.prepare(rayon::current_num_threads().clamp(1, MAX_RUNS), &valid_bits);
        }
        Ok(Self {
            camera,
            options,
            region,
            depth: valid_bits.iter().map(|&v| EMPTY & v).collect(),
            accum: vec![[0; 2]; n],
            candidates: Vec::new(),
            order: Vec::new(),
            draw: Vec::new(),
            splats: Vec::new(),
            status,
            hole_rows: [vec![0; w], vec![0; w]],
            valid_bits,
            tile_farthest: vec![0; tile_count],
            tile_batch: vec![0; tile_count],
            batch: 0,
            cleared: true,
            theta_min,
            theta_max,
            slots,
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

        // The last resolve cleared the buffers, unless it did not run (a panic): then
        // cleared here.
        if !std::mem::replace(&mut self.cleared, false) {
            for (key, &valid) in self.depth.iter_mut().zip(&self.valid_bits) {
                *key = EMPTY & valid;
            }
            self.accum.fill([0; 2]);
        }
        // Into the caches, for the occlusion tests' and pass 1's scattered reads.
        cache::read_in(&self.depth);
        // The runs a parallel rendering cuts each pass into (`slots`).
        let runs = if self.options.parallel {
            rayon::current_num_threads().clamp(1, MAX_RUNS)
        } else {
            1
        };
        if runs > 1 {
            // A masked pixel's cleared key is 0, a valid one's EMPTY: the valid bits.
            self.slots.prepare(runs, &self.valid_bits);
        }
        let occlusion = self.options.occlusion_culling && view.undistorted;
        // `splats` grows with what a batch may write (the kept splats and the batch's
        // points), not to every candidate point at once: the memory a rendering
        // touches is what it draws.
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
            if self.splats.len() < splats_kept + batch_points {
                self.splats
                    .resize(splats_kept + batch_points, Splat::default());
            }
            let splats = &mut self.splats[splats_kept..splats_kept + batch_points];
            let depth = &mut self.depth[..];
            splats_kept += if runs > 1 {
                self.slots.draw_depth(
                    runs,
                    cloud.points(),
                    cells,
                    &view,
                    &self.camera,
                    depth,
                    splats,
                )
            } else {
                widest_pass_one(cloud.points(), cells, &view, &self.camera, depth, splats)
            };
            points_drawn += batch_points;
        }
        let splats = &self.splats[..splats_kept];
        let (depth, accum) = (&self.depth[..], &mut self.accum[..]);
        if runs > 1 {
            self.slots
                .accumulate(runs, splats, &view, depth, accum, &self.valid_bits);
        } else {
            widest_pass_two(splats, &view, depth, accum);
        }

        let mut pixels_hit = self.resolve(frame);
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
}

/// The least and greatest angles off the optical axis (radians) of the rays of
/// `camera`'s valid pixels that it can unproject (`(∞, −∞)` if none), as a scan of
/// every such pixel computes them. Without lens distortion the angle grows with the
/// normalised radius (the unified model's lift), so only the pixels whose squared
/// radius is within a millionth of the least or the greatest are unprojected: a band
/// far wider than the angle's rounding (`acos` near 1 included, for focal lengths up to
/// about 10⁴ pixels), so the same pixel wins (a proptest compares the bits). A pixel of
/// the band that cannot be unprojected (past the fold of a mirror with `ξ > 1`), and
/// lens distortion, fall back to the scan.
fn theta_range(camera: &Camera) -> (f64, f64) {
    let w = camera.width() as usize;
    let pixel = |k: usize| [(k % w) as f64, (k / w) as f64];
    let valid = || {
        camera
            .valid_pixels()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
            .map(|(k, _)| k)
    };
    let theta = |k: usize| {
        camera
            .unproject(pixel(k))
            .ok()
            .map(|ray| ray[2].clamp(-1.0, 1.0).acos())
    };
    let scan = || {
        valid()
            .filter_map(theta)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
                (lo.min(t), hi.max(t))
            })
    };
    if camera.distortion().is_some() {
        return scan();
    }
    let squared_radius = |k: usize| {
        camera
            .normalized_from_pixel(pixel(k))
            .ok()
            .map(|[x, y]| x * x + y * y)
    };
    let (least, greatest) = valid()
        .filter_map(squared_radius)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r2| {
            (lo.min(r2), hi.max(r2))
        });
    if least > greatest {
        return scan();
    }
    const TIE: f64 = 1e-6;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in valid() {
        let Some(r2) = squared_radius(k) else {
            continue;
        };
        let (near_least, near_greatest) = (
            r2 <= least * (1.0 + TIE) + 1e-300,
            r2 >= greatest * (1.0 - TIE),
        );
        if near_least || near_greatest {
            let Some(t) = theta(k) else {
                return scan();
            };
            if near_least {
                lo = lo.min(t);
            }
            if near_greatest {
                hi = hi.max(t);
            }
        }
    }
    (lo, hi)
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
