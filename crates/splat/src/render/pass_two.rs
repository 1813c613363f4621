//! Pass 2 (accumulation, the anti-aliasing): add each kept splat's intensity and
//! range to the pixels it covers where it lies within the depth band of the nearest.

#[cfg(target_arch = "x86_64")]
use super::projector::{Avx2, Avx512};
use super::projector::{Baseline, Project};
use super::splat::Splat;
use super::view::View;
use super::{COUNT_BITS, RANGE_SCALE};

/// A splat's two samples: its intensity (16-bit fixed point, above a count of one)
/// and its range (fixed point).
#[inline(always)]
fn samples(s: &Splat) -> (u64, u64) {
    let sample = (u64::from(s.intensity()) << COUNT_BITS) | 1;
    // Through i64: the same for any range below 2^51 m, and cheaper than to u64.
    let range_sample = (s.range_m() * RANGE_SCALE + 0.5) as i64 as u64;
    (sample, range_sample)
}

/// Pass 2 on one thread, on plain keys and sums (a parallel rendering gives each
/// thread its own sums, `super::slots`): 3 × 3 splats whole rows at a
/// time where the instruction set allows ([`Project::accumulate_3x3`]), the others
/// without a branch (whether a sample is within the band is unpredictable).
#[inline(always)]
fn accumulate(
    splats: &[Splat],
    view: &View,
    depth: &[u32],
    accum: &mut [[u64; 2]],
    projector: impl Project,
) {
    // Into the caches before the scattered additions.
    super::cache::read_in(accum);
    for s in splats.iter().filter(|s| s.drawn()) {
        let (sample, range_sample) = samples(s);
        let limit = s.limit_m();
        if s.width() == 1 {
            let k = s.single_pixel();
            // `f32::from_bits(depth[k]) >= limit` on the bits: pass 1 left the pixel a
            // range at most the splat's (never the empty key), and non-negative ranges
            // order as their bits.
            debug_assert!(depth[k] != super::EMPTY);
            let keep = 0u64.wrapping_sub(u64::from(depth[k] >= s.0[3]));
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

/// The arguments of [`accumulate`] with a projector (its instruction set), to run
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
        accumulate(
            self.splats,
            self.view,
            self.depth,
            self.accum,
            self.projector,
        );
    }
}

/// [`accumulate`] on the widest instruction set found at run time.
pub(super) fn widest_pass_two(
    splats: &[Splat],
    view: &View,
    depth: &[u32],
    accum: &mut [[u64; 2]],
) {
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
    accumulate(splats, view, depth, accum, Baseline);
}
