//! The projectors: how pass 1 projects the points of a camera without lens
//! distortion several at a time, and how the single-threaded passes draw a 3 × 3
//! splat, on each instruction set ([`Project`]: [`Baseline`], [`Avx512`], [`Avx2`]).

use crate::PackedPoint;

use super::project::{TAIL, project_block};
use super::splat::Splat;
use super::view::View;
#[cfg(target_arch = "x86_64")]
use super::{avx2, avx512};

/// How pass 1 projects points of a camera without lens distortion, several at a time:
/// every implementation gives bit for bit the splats of
/// [`project_point`](super::project::project_point) (tested). Not closures: a closure
/// is compiled apart from the function that calls it, without the instruction set that
/// function was compiled for.
pub(super) trait Project: Copy {
    /// The splats of `N` points (`N` a multiple of the implementation's width).
    fn lanes<const N: usize>(
        self,
        points: &[PackedPoint; N],
        footprint: f32,
        view: &View,
        out: &mut [Splat; N],
    );

    /// The splats of fewer than [`BLOCK`](super::project::BLOCK) points (a cell's last
    /// ones), as many as `out`.
    fn rest(self, points: &[PackedPoint], footprint: f32, view: &View, out: &mut [Splat]);

    /// `kernel` as a function of its own, compiled for this instruction set: its
    /// registers allocated apart from its caller's (a loop inlined into the projection's
    /// kept its counters on the stack).
    fn apart<K: pulp::WithSimd>(self, kernel: K) -> K::Output;

    /// Pass 1 of a 3 × 3 splat on plain keys (`pass_one::splat_depth`); the plain loop
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

    /// Pass 2 of a 3 × 3 splat on plain sums (`pass_two::accumulate`); the plain loop
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
pub(super) struct Baseline;

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

    fn apart<K: pulp::WithSimd>(self, kernel: K) -> K::Output {
        apart_scalar(kernel)
    }
}

/// [`Project::apart`] on the baseline.
#[inline(never)]
fn apart_scalar<K: pulp::WithSimd>(kernel: K) -> K::Output {
    kernel.with_simd(pulp::Scalar::new())
}

/// Sixteen points per instruction where the processor has AVX-512
/// ([`avx512::project_splats`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx512(pub(super) pulp::x86::V4);

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

    fn apart<K: pulp::WithSimd>(self, kernel: K) -> K::Output {
        pulp::Simd::vectorize(self.0, kernel)
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
pub(super) struct Avx2(pub(super) pulp::x86::V3);

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

    fn apart<K: pulp::WithSimd>(self, kernel: K) -> K::Output {
        pulp::Simd::vectorize(self.0, kernel)
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
        avx2::depth_3x3(self.0, depth, first, width, key, limit)
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
        avx2::accumulate_3x3(
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

#[cfg(test)]
mod tests {
    //! The 3 × 3 kernels of every projector against the per-pixel passes.

    use proptest::prelude::*;

    use super::*;
    use crate::render::EMPTY;

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
        /// AVX-512 and AVX2 kernels (where the processor has them) give the same
        /// buffers, the fourth pixel of each row and every other pixel untouched.
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
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = pulp::x86::V3::try_new() {
                same_3x3(Avx2(simd), &depth, &accum, first, width, key, limit, samples)?;
            }
        }
    }
}
