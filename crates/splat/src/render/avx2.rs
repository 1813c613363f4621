//! The projection of pass 1 on AVX2, eight points per instruction, where the processor
//! has it but not AVX-512 (found at run time through [`pulp`], whose wrappers make the
//! intrinsics safe to call once the instruction set is known to be there): the SSE2
//! kernel on both 128-bit halves of each register at once, the same IEEE operations in
//! the same order, hence bit for bit the same splats (tested). Eight points (8 bytes
//! each) are loaded as two registers and their words taken apart so that points 0, 2,
//! 4, 6 are in the lower half and 1, 3, 5, 7 in the upper one; a transposition of the
//! splats' words within each half puts them back in order.

use core::arch::x86_64::{__m256, __m256i};

use pulp::x86::V3;

use super::avx512::{GE, NLT, four};
use super::lanes::{Constants, Pair, Rays, Vectors, rays, splat_words, unpack, words_of_rays};
use super::splat::Splat;
use super::view::View;
use crate::PackedPoint;

/// `_CMP_GT_OQ` and `_CMP_LT_OQ`: ordered comparisons, false where either is a NaN
/// (as SSE's `cmpgtps` / `cmpltps`).
const GT: i32 = 30;
const LT: i32 = 17;

/// The kernel's registers (a lane mask is a register of all-ones lanes).
#[derive(Clone, Copy)]
struct Ops(V3);

impl Vectors for Ops {
    type F = __m256;
    type I = __m256i;
    type M = __m256i;

    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        self.0.avx._mm256_set1_ps(x)
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> __m256i {
        self.0.avx._mm256_set1_epi32(x)
    }
    #[inline(always)]
    fn mask_if(self, set: bool) -> __m256i {
        self.splat_i(-i32::from(set))
    }
    #[inline(always)]
    fn add(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_add_ps(a, b)
    }
    #[inline(always)]
    fn sub(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_sub_ps(a, b)
    }
    #[inline(always)]
    fn mul(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_mul_ps(a, b)
    }
    #[inline(always)]
    fn div(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_div_ps(a, b)
    }
    #[inline(always)]
    fn sqrt(self, a: __m256) -> __m256 {
        self.0.avx._mm256_sqrt_ps(a)
    }
    #[inline(always)]
    fn max(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_max_ps(a, b)
    }
    #[inline(always)]
    fn min(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_min_ps(a, b)
    }
    #[inline(always)]
    fn gt(self, a: __m256, b: __m256) -> __m256i {
        self.bits(self.0.avx._mm256_cmp_ps::<GT>(a, b))
    }
    #[inline(always)]
    fn lt(self, a: __m256, b: __m256) -> __m256i {
        self.bits(self.0.avx._mm256_cmp_ps::<LT>(a, b))
    }
    #[inline(always)]
    fn gt_i(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_cmpgt_epi32(a, b)
    }
    #[inline(always)]
    fn and_m(self, a: __m256i, b: __m256i) -> __m256i {
        self.and_i(a, b)
    }
    #[inline(always)]
    fn or_m(self, a: __m256i, b: __m256i) -> __m256i {
        self.or_i(a, b)
    }
    #[inline(always)]
    fn add_i(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_add_epi32(a, b)
    }
    #[inline(always)]
    fn sub_i(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_sub_epi32(a, b)
    }
    #[inline(always)]
    fn and_i(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_and_si256(a, b)
    }
    #[inline(always)]
    fn or_i(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_or_si256(a, b)
    }
    #[inline(always)]
    fn shl16(self, a: __m256i) -> __m256i {
        self.0.avx2._mm256_slli_epi32::<16>(a)
    }
    #[inline(always)]
    fn shr16(self, a: __m256i) -> __m256i {
        self.0.avx2._mm256_srli_epi32::<16>(a)
    }
    #[inline(always)]
    fn mul_u16(self, a: __m256i, b: __m256i) -> __m256i {
        self.0.avx2._mm256_mullo_epi32(a, b)
    }
    #[inline(always)]
    fn bits(self, a: __m256) -> __m256i {
        self.0.avx._mm256_castps_si256(a)
    }
    #[inline(always)]
    fn to_f32(self, a: __m256i) -> __m256 {
        self.0.avx._mm256_cvtepi32_ps(a)
    }
    /// A true lane is −1: added, it subtracts one.
    #[inline(always)]
    fn minus_one_where(self, mask: __m256i, a: __m256i) -> __m256i {
        self.add_i(a, mask)
    }
    #[inline(always)]
    fn plus_one_where(self, mask: __m256i, a: __m256i) -> __m256i {
        self.sub_i(a, mask)
    }
    #[inline(always)]
    fn select(self, mask: __m256i, a: __m256i, b: __m256i) -> __m256i {
        self.or_i(
            self.and_i(mask, a),
            self.0.avx2._mm256_andnot_si256(mask, b),
        )
    }
}

impl Ops {
    /// The 4 × 4 transposition of 32-bit lanes within each 128-bit half.
    #[inline(always)]
    fn transpose_halves(self, [a, b, c, d]: [__m256i; 4]) -> [__m256i; 4] {
        let avx2 = self.0.avx2;
        let (ab_lo, cd_lo) = (
            avx2._mm256_unpacklo_epi32(a, b),
            avx2._mm256_unpacklo_epi32(c, d),
        );
        let (ab_hi, cd_hi) = (
            avx2._mm256_unpackhi_epi32(a, b),
            avx2._mm256_unpackhi_epi32(c, d),
        );
        [
            avx2._mm256_unpacklo_epi64(ab_lo, cd_lo),
            avx2._mm256_unpackhi_epi64(ab_lo, cd_lo),
            avx2._mm256_unpacklo_epi64(ab_hi, cd_hi),
            avx2._mm256_unpackhi_epi64(ab_hi, cd_hi),
        ]
    }

    /// Eight points of two 32-bit words each (8 bytes): their first words, then their
    /// second words, each register in the lanes' order of [`Ops::transpose_halves`]
    /// (points 0, 2, 4, 6 | 1, 3, 5, 7).
    #[inline(always)]
    fn words_of_eight(self, points: &[PackedPoint; 8]) -> [__m256i; 2] {
        let (avx, avx2) = (self.0.avx, self.0.avx2);
        let [a, b]: [__m256i; 2] = pulp::cast(*points);
        let (a, b) = (avx._mm256_castsi256_ps(a), avx._mm256_castsi256_ps(b));
        // Within each half: points 0, 1, 4, 5 | 2, 3, 6, 7.
        let first = avx._mm256_castps_si256(avx._mm256_shuffle_ps::<0b10_00_10_00>(a, b));
        let second = avx._mm256_castps_si256(avx._mm256_shuffle_ps::<0b11_01_11_01>(a, b));
        let order: __m256i = pulp::cast([0i32, 4, 2, 6, 1, 5, 3, 7]);
        [
            avx2._mm256_permutevar8x32_epi32(first, order),
            avx2._mm256_permutevar8x32_epi32(second, order),
        ]
    }

    /// Eight splats from one register per word (in the lanes' order of
    /// [`Ops::words_of_eight`]), transposed back to four words per point.
    #[inline(always)]
    fn store_splats(self, words: [__m256i; 4], out: &mut [Splat; 8]) {
        let words: [[u32; 4]; 8] = pulp::cast(self.transpose_halves(words));
        for (out, word) in out.iter_mut().zip(&words) {
            *out = Splat(*word);
        }
    }
}

/// The splats of [`super::project::project_block`]: blocks of 64 points as four pairs
/// of registers ([`Pair`]), in two phases (the four pairs' [`Rays`], then their
/// splats), then eight points at a time (the lengths are equal multiples of eight).
/// The projection is a long chain of dependent operations (a square root, two
/// divisions) that one register at a time leaves the processor waiting on: pairs run
/// two chains side by side, and each phase's chain is half as long, so that more of
/// them overlap.
#[inline(always)]
pub(super) fn project_splats(
    simd: V3,
    points: &[PackedPoint],
    footprint: f32,
    view: &View,
    out: &mut [Splat],
) {
    let o = Ops(simd);
    let pair = Pair(o);
    let constants = Constants::new(pair, view, footprint);
    let (points, rest) = points.as_chunks::<64>();
    let (out, out_rest) = out.as_chunks_mut::<64>();
    for (points, out) in points.iter().zip(out) {
        let points = points.as_chunks::<16>().0;
        // Not `array::from_fn`: its closure would be compiled without AVX2.
        let r: [Rays<Pair<Ops>>; 4] = [
            pair_rays(o, &constants, &points[0]),
            pair_rays(o, &constants, &points[1]),
            pair_rays(o, &constants, &points[2]),
            pair_rays(o, &constants, &points[3]),
        ];
        for (r, out) in r.into_iter().zip(out.as_chunks_mut::<16>().0) {
            store_pair(o, &constants, r, out);
        }
    }
    let constants = Constants::new(o, view, footprint);
    let (points, _) = rest.as_chunks::<8>();
    let (out, _) = out_rest.as_chunks_mut::<8>();
    for (points, out) in points.iter().zip(out) {
        // Eight points of 8 bytes, their words taken apart: points 0, 2, 4, 6 |
        // 1, 3, 5, 7.
        let [xy, zi] = o.words_of_eight(points);
        let (steps, intensity) = unpack(o, &constants, xy, zi);
        o.store_splats(splat_words(o, &constants, steps, intensity), out);
    }
}

/// [`Rays`] of sixteen points: points 0–7 in the first register of each pair, 8–15
/// in the second, each taken apart as in [`project_splats`].
#[inline(always)]
fn pair_rays(
    o: Ops,
    constants: &Constants<Pair<Ops>>,
    points: &[PackedPoint; 16],
) -> Rays<Pair<Ops>> {
    let [first, second]: [[PackedPoint; 8]; 2] = pulp::cast(*points);
    let ([xy0, zi0], [xy1, zi1]) = (o.words_of_eight(&first), o.words_of_eight(&second));
    let (steps, intensity) = unpack(Pair(o), constants, [xy0, xy1], [zi0, zi1]);
    rays(Pair(o), constants, steps, intensity)
}

/// The splats of sixteen points from their [`Rays`].
#[inline(always)]
fn store_pair(o: Ops, constants: &Constants<Pair<Ops>>, r: Rays<Pair<Ops>>, out: &mut [Splat; 16]) {
    let [w0, w1, w2, w3] = words_of_rays(Pair(o), constants, r);
    for (h, out) in out.as_chunks_mut::<8>().0.iter_mut().enumerate() {
        o.store_splats([w0[h], w1[h], w2[h], w3[h]], out);
    }
}

/// Pass 1 of a 3 × 3 splat whose top-left pixel is `first` (rows `width` apart; the
/// caller checked that four pixels from its last row's first are in `depth`): each
/// row's three keys take their minimum with `key` in one instruction, the fourth its
/// minimum with the largest key (written back as it was). Returns whether a pixel held
/// a range not below `limit` before (a NaN, an empty pixel, counts):
/// `pass_one::splat_depth`'s result.
#[inline(always)]
pub(super) fn depth_3x3(
    simd: V3,
    depth: &mut [u32],
    first: usize,
    width: usize,
    key: u32,
    limit: f32,
) -> bool {
    use core::arch::x86_64::{__m128, __m128i};
    let (sse41, avx) = (simd.sse4_1, simd.avx);
    let keys: __m128i = pulp::cast([key, key, key, u32::MAX]);
    let limits: __m128 = pulp::cast([limit; 4]);
    let mut seen = 0;
    for row in [first, first + width, first + 2 * width] {
        let before: __m128i = pulp::cast(four(depth, row));
        let after = sse41._mm_min_epu32(before, keys);
        *<&mut [u32; 4]>::try_from(&mut depth[row..row + 4]).expect("four keys") =
            pulp::cast(after);
        seen |= simd
            .sse
            ._mm_movemask_ps(avx._mm_cmp_ps::<NLT>(pulp::cast(before), limits));
    }
    seen & 0b111 != 0
}

/// Pass 2 of a 3 × 3 splat (as [`depth_3x3`]): each row's three pixels whose key is
/// at least `limit` add `sample` and `range_sample` to their two sums, in two additions
/// of four 64-bit lanes whose samples are masked (the fourth pixel adds zero).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn accumulate_3x3(
    simd: V3,
    depth: &[u32],
    accum: &mut [[u64; 2]],
    first: usize,
    width: usize,
    limit: f32,
    sample: u64,
    range_sample: u64,
) {
    use core::arch::x86_64::{__m128, __m128i};
    let (sse2, avx, avx2) = (simd.sse2, simd.avx, simd.avx2);
    let samples: __m256i = pulp::cast([sample, range_sample, sample, range_sample]);
    let limits: __m128 = pulp::cast([limit; 4]);
    let three: __m128i = pulp::cast([-1i32, -1, -1, 0]);
    for row in [first, first + width, first + 2 * width] {
        let near = avx._mm_cmp_ps::<GE>(pulp::cast(four(depth, row)), limits);
        let near = sse2._mm_and_si128(pulp::cast(near), three);
        // Each pixel's mask over its two sums (32-bit lanes sign-extended to 64).
        let low = avx2._mm256_cvtepi32_epi64(sse2._mm_unpacklo_epi32(near, near));
        let high = avx2._mm256_cvtepi32_epi64(sse2._mm_unpackhi_epi32(near, near));
        let sums = <&mut [[u64; 2]; 4]>::try_from(&mut accum[row..row + 4]).expect("four");
        let [a, b]: [__m256i; 2] = pulp::cast(*sums);
        *sums = pulp::cast([
            avx2._mm256_add_epi64(a, avx2._mm256_and_si256(samples, low)),
            avx2._mm256_add_epi64(b, avx2._mm256_and_si256(samples, high)),
        ]);
    }
}
