//! Pass 1 (depth): project every point of the cells drawn, take the minimum range
//! over each splat's pixels, and keep the splats that may add a sample in pass 2.

use ucm::Camera;

use crate::PackedPoint;

use super::culling::DrawCell;
use super::project::{BLOCK, project_point};
#[cfg(target_arch = "x86_64")]
use super::projector::{Avx2, Avx512};
use super::projector::{Baseline, Project};
use super::splat::Splat;
use super::view::View;

/// Points projected into a buffer of the first level of cache before their depth
/// pass (a multiple of [`BLOCK`]).
const STAGE: usize = 256;

/// How many points ahead of the one being drawn [`Warm`] asks for (in draw order).
const WARM_AHEAD: usize = 512;

/// Points in a 64-byte cache line.
const POINTS_PER_LINE: usize = 64 / size_of::<PackedPoint>();

/// The arguments of [`project_and_depth`] but the projector.
struct PassOneArgs<'a> {
    points: &'a [PackedPoint],
    cells: &'a [DrawCell],
    view: &'a View,
    camera: &'a Camera,
    depth: &'a mut [u32],
    splats: &'a mut [Splat],
}

impl PassOneArgs<'_> {
    #[inline(always)]
    fn run(self, projector: impl Project) -> usize {
        let a = self;
        project_and_depth(
            a.points, a.cells, a.view, a.camera, a.depth, a.splats, projector,
        )
    }
}

/// Take the minimum of the splat's range and the depth key of each pixel it covers
/// (plain keys, several pixels at a time; a parallel rendering gives each run its own,
/// `super::slots`). Returns whether the splat may still add a sample in pass 2: not if
/// every pixel already held a range below its band (depths only decrease, so pass 2
/// would reject it everywhere; the test is pass 2's own, on a depth at least the final
/// one).
#[inline(always)]
fn splat_depth(depth: &mut [u32], s: &Splat, view: &View, projector: impl Project) -> bool {
    let (key, limit) = (s.0[2], s.limit_m());
    // Most splats: a single pixel, decided first (before the 3 × 3 test).
    if s.width() == 1 {
        let k = s.single_pixel();
        let before = depth[k];
        depth[k] = key.min(before);
        // `!(f32::from_bits(before) < limit)` on the bits: non-negative ranges order as
        // their bits (up to +∞), and the empty key (`u32::MAX`) above every one, as its
        // NaN compares false (the limit of a drawn splat is non-negative, not a NaN).
        debug_assert!(s.0[3] <= f32::INFINITY.to_bits());
        return before >= s.0[3];
    }
    if let Some(first) = s.whole_3x3(view, depth.len()) {
        return projector.depth_3x3(depth, first, view.width as usize, key, limit);
    }
    let mut hidden = true;
    s.for_each_pixel(view, |k| {
        // Branch-free: whether a point is nearer is unpredictable.
        let before = depth[k];
        depth[k] = key.min(before);
        hidden &= f32::from_bits(before) < limit;
    });
    !hidden
}

/// [`project_and_depth`] with a projector, to run compiled for its instruction set
/// (a struct, not a closure: pulp's `with_simd` is compiled for the instruction set,
/// and only an `#[inline(always)]` method is sure to be inlined into it).
struct PassOne<'a, P>(PassOneArgs<'a>, P);

impl<P: Project> pulp::WithSimd for PassOne<'_, P> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> usize {
        self.0.run(self.1)
    }
}

/// Pass 1 over a batch of cells on one thread ([`project_and_depth`]) on the widest
/// instruction set found at run time (looked up once per call): AVX-512, else AVX2,
/// else the baseline. Returns the number of slots of `splats` that pass 2 must read
/// (the splats that may add a sample, moved to the front).
pub(super) fn widest_pass_one(
    points: &[PackedPoint],
    cells: &[DrawCell],
    view: &View,
    camera: &Camera,
    depth: &mut [u32],
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

/// Pass 1 over the points of some cells: project each point once, take the minimum
/// depth key over its footprint, and keep its splat in `splats` if it may add a sample
/// (in draw order, from the front). Returns the number kept.
#[inline(always)]
fn project_and_depth(
    points: &[PackedPoint],
    cells: &[DrawCell],
    view: &View,
    camera: &Camera,
    depth: &mut [u32],
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
            kept = projector.apart(KeepVisible {
                stage: out,
                depth,
                view,
                splats,
                kept,
                projector,
            });
        }
    }
    warm.finish();
    kept
}

/// The depth pass of a stage of splats: each drawn splat's minima
/// ([`splat_depth`]), kept in `splats` from slot `kept` on if it may add a sample.
/// Returns the new number kept.
struct KeepVisible<'a, P> {
    stage: &'a [Splat],
    depth: &'a mut [u32],
    view: &'a View,
    splats: &'a mut [Splat],
    kept: usize,
    projector: P,
}

impl<P: Project> pulp::WithSimd for KeepVisible<'_, P> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> usize {
        let mut kept = self.kept;
        for s in self.stage.iter().filter(|s| s.drawn()) {
            let visible = splat_depth(self.depth, s, self.view, self.projector);
            self.splats[kept] = *s;
            kept += usize::from(visible);
        }
        kept
    }
}

/// Asks for the cache lines of the points to draw a steady [`WARM_AHEAD`] points
/// ahead of the one being drawn, a few lines per block of points: the cells are drawn
/// front to back, not in memory order, so each starts a new stream that the hardware
/// prefetcher would only follow after a few misses, and a whole cell's lines asked
/// for at once would fill the processor's miss buffers and stall it. A prefetch
/// instruction per line on x86-64; elsewhere a load per line, whose values are xor-ed
/// and kept so that they are not optimised away. Only the time depends on it.
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
