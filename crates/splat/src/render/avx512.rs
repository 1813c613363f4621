//! The projection of pass 1 on AVX-512, sixteen points per instruction, where the
//! processor has it (found at run time through [`pulp`], whose wrappers make the
//! intrinsics safe to call once the instruction set is known to be there). The same
//! IEEE operations in the same order as [`super::project::project_point`] and the SSE2
//! kernel (no fused multiply-add; `max` returns its second operand where the first is a
//! NaN, as `maxps` does), hence bit for bit the same splats (tested against both).
//! Sixteen points (8 bytes each) are loaded as two vectors and taken apart with two
//! two-source permutes; the splats' words are transposed back with eight more.

use core::arch::x86_64::{__m512, __m512i, __mmask16};

use pulp::x86::V4;

use super::lanes::{Constants, Pair, Rays, Vectors, rays, splat_words, unpack, words_of_rays};
use super::splat::Splat;
use super::view::View;
use crate::PackedPoint;

/// `_CMP_GT_OQ` and `_CMP_LT_OQ`: ordered comparisons, false where either is a NaN
/// (as SSE's `cmpgtps` / `cmpltps`).
const GT: i32 = 30;
const LT: i32 = 17;

/// Two-source permute indices: lane `k` of the result takes lane `idx[k]` of `a`
/// (below 16) or `idx[k] − 16` of `b`.
const EVENS: [i32; 16] = [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30];
const ODDS: [i32; 16] = [1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31];
const PAIRS_LOW: [i32; 16] = [0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23];
const PAIRS_HIGH: [i32; 16] = [8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31];
const QUADS_LOW: [i32; 16] = [0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23];
const QUADS_HIGH: [i32; 16] = [8, 9, 24, 25, 10, 11, 26, 27, 12, 13, 28, 29, 14, 15, 30, 31];

/// The kernel's registers.
#[derive(Clone, Copy)]
struct Ops(V4);

impl Vectors for Ops {
    type F = __m512;
    type I = __m512i;
    type M = __mmask16;

    #[inline(always)]
    fn splat(self, x: f32) -> __m512 {
        self.0.avx512f._mm512_set1_ps(x)
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> __m512i {
        self.0.avx512f._mm512_set1_epi32(x)
    }
    #[inline(always)]
    fn mask_if(self, set: bool) -> __mmask16 {
        if set { u16::MAX } else { 0 }
    }
    #[inline(always)]
    fn add(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_add_ps(a, b)
    }
    #[inline(always)]
    fn sub(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_sub_ps(a, b)
    }
    #[inline(always)]
    fn mul(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_mul_ps(a, b)
    }
    #[inline(always)]
    fn div(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_div_ps(a, b)
    }
    #[inline(always)]
    fn sqrt(self, a: __m512) -> __m512 {
        self.0.avx512f._mm512_sqrt_ps(a)
    }
    #[inline(always)]
    fn max(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_max_ps(a, b)
    }
    #[inline(always)]
    fn min(self, a: __m512, b: __m512) -> __m512 {
        self.0.avx512f._mm512_min_ps(a, b)
    }
    #[inline(always)]
    fn gt(self, a: __m512, b: __m512) -> __mmask16 {
        self.0.avx512f._mm512_cmp_ps_mask::<GT>(a, b)
    }
    #[inline(always)]
    fn lt(self, a: __m512, b: __m512) -> __mmask16 {
        self.0.avx512f._mm512_cmp_ps_mask::<LT>(a, b)
    }
    #[inline(always)]
    fn gt_i(self, a: __m512i, b: __m512i) -> __mmask16 {
        self.0.avx512f._mm512_cmpgt_epi32_mask(a, b)
    }
    #[inline(always)]
    fn and_m(self, a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }
    #[inline(always)]
    fn or_m(self, a: __mmask16, b: __mmask16) -> __mmask16 {
        a | b
    }
    #[inline(always)]
    fn add_i(self, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_add_epi32(a, b)
    }
    #[inline(always)]
    fn sub_i(self, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_sub_epi32(a, b)
    }
    #[inline(always)]
    fn and_i(self, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_and_si512(a, b)
    }
    #[inline(always)]
    fn or_i(self, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_or_si512(a, b)
    }
    #[inline(always)]
    fn shl16(self, a: __m512i) -> __m512i {
        self.0.avx512f._mm512_slli_epi32::<16>(a)
    }
    #[inline(always)]
    fn shr16(self, a: __m512i) -> __m512i {
        self.0.avx512f._mm512_srli_epi32::<16>(a)
    }
    #[inline(always)]
    fn mul_u16(self, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_mullo_epi32(a, b)
    }
    #[inline(always)]
    fn bits(self, a: __m512) -> __m512i {
        self.0.avx512f._mm512_castps_si512(a)
    }
    #[inline(always)]
    fn to_f32(self, a: __m512i) -> __m512 {
        self.0.avx512f._mm512_cvtepi32_ps(a)
    }
    #[inline(always)]
    fn minus_one_where(self, mask: __mmask16, a: __m512i) -> __m512i {
        let one = self.splat_i(1);
        self.0.avx512f._mm512_mask_sub_epi32(a, mask, a, one)
    }
    #[inline(always)]
    fn plus_one_where(self, mask: __mmask16, a: __m512i) -> __m512i {
        let one = self.splat_i(1);
        self.0.avx512f._mm512_mask_add_epi32(a, mask, a, one)
    }
    #[inline(always)]
    fn select(self, mask: __mmask16, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_mask_blend_epi32(mask, b, a)
    }
}

impl Ops {
    #[inline(always)]
    fn permute_i(self, a: __m512i, idx: [i32; 16], b: __m512i) -> __m512i {
        let idx = pulp::cast(idx);
        self.0.avx512f._mm512_permutex2var_epi32(a, idx, b)
    }

    /// Sixteen points of two 32-bit words each: their first words, then their second
    /// words, gathered by two two-source permutes.
    #[inline(always)]
    fn words_of_sixteen(self, points: &[PackedPoint; 16]) -> [__m512i; 2] {
        let [a, b]: [__m512i; 2] = pulp::cast(*points);
        [self.permute_i(a, EVENS, b), self.permute_i(a, ODDS, b)]
    }

    /// Sixteen splats from one register per word, transposed to four words per point.
    #[inline(always)]
    fn store_splats(self, [w0, w1, w2, w3]: [__m512i; 4], out: &mut [Splat; 16]) {
        let (w01_lo, w01_hi) = (
            self.permute_i(w0, PAIRS_LOW, w1),
            self.permute_i(w0, PAIRS_HIGH, w1),
        );
        let (w23_lo, w23_hi) = (
            self.permute_i(w2, PAIRS_LOW, w3),
            self.permute_i(w2, PAIRS_HIGH, w3),
        );
        let quads = [
            self.permute_i(w01_lo, QUADS_LOW, w23_lo),
            self.permute_i(w01_lo, QUADS_HIGH, w23_lo),
            self.permute_i(w01_hi, QUADS_LOW, w23_hi),
            self.permute_i(w01_hi, QUADS_HIGH, w23_hi),
        ];
        let words: [[u32; 4]; 16] = pulp::cast(quads);
        for (out, word) in out.iter_mut().zip(&words) {
            *out = Splat(*word);
        }
    }
}

/// The splats of [`super::project::project_block`]: blocks of 64 points as two pairs
/// of registers ([`Pair`]) in two phases, as [`super::avx2::project_splats`], then
/// sixteen points at a time (the lengths are equal multiples of sixteen).
#[inline(always)]
pub(super) fn project_splats(
    simd: V4,
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
        let (points, out) = (points.as_chunks::<32>().0, out.as_chunks_mut::<32>().0);
        let r = [
            pair_rays(o, &constants, &points[0]),
            pair_rays(o, &constants, &points[1]),
        ];
        for (r, out) in r.into_iter().zip(out) {
            store_pair(o, &constants, r, out);
        }
    }
    let constants = Constants::new(o, view, footprint);
    let (points, _) = rest.as_chunks::<16>();
    let (out, _) = out_rest.as_chunks_mut::<16>();
    for (points, out) in points.iter().zip(out) {
        let [xy, zi] = o.words_of_sixteen(points);
        let (steps, intensity) = unpack(o, &constants, xy, zi);
        o.store_splats(splat_words(o, &constants, steps, intensity), out);
    }
}

/// [`Rays`] of thirty-two points: points 0–15 in the first register of each pair,
/// 16–31 in the second, each taken apart as in [`project_splats`].
#[inline(always)]
fn pair_rays(
    o: Ops,
    constants: &Constants<Pair<Ops>>,
    points: &[PackedPoint; 32],
) -> Rays<Pair<Ops>> {
    let [first, second]: [[PackedPoint; 16]; 2] = pulp::cast(*points);
    let ([xy0, zi0], [xy1, zi1]) = (o.words_of_sixteen(&first), o.words_of_sixteen(&second));
    let (steps, intensity) = unpack(Pair(o), constants, [xy0, xy1], [zi0, zi1]);
    rays(Pair(o), constants, steps, intensity)
}

/// The splats of thirty-two points from their [`Rays`].
#[inline(always)]
fn store_pair(o: Ops, constants: &Constants<Pair<Ops>>, r: Rays<Pair<Ops>>, out: &mut [Splat; 32]) {
    let [w0, w1, w2, w3] = words_of_rays(Pair(o), constants, r);
    for (h, out) in out.as_chunks_mut::<16>().0.iter_mut().enumerate() {
        o.store_splats([w0[h], w1[h], w2[h], w3[h]], out);
    }
}

/// `_CMP_GE_OQ` (false where either is a NaN, as Rust's `>=`) and `_CMP_NLT_UQ` (true
/// where either is a NaN, as Rust's `!(a < b)`); the AVX2 kernels' too.
pub(super) const GE: i32 = 29;
pub(super) const NLT: i32 = 21;

/// Each of the low four bits of a mask spread over two bits (a pixel's two sums).
const PAIRS: [u8; 8] = [
    0b00, 0b11, 0b1100, 0b1111, 0b11_0000, 0b11_0011, 0b11_1100, 0b11_1111,
];

/// Four keys from `depth` at `k` (the caller checked `k + 4 ≤ len`).
#[inline(always)]
pub(super) fn four(depth: &[u32], k: usize) -> [u32; 4] {
    *<&[u32; 4]>::try_from(&depth[k..k + 4]).expect("four keys")
}

/// Pass 1 of a 3 × 3 splat whose top-left pixel is `first` (rows `width` apart; the
/// caller checked that four pixels from its last row's first are in `depth`): each
/// row's three keys take their minimum with `key` in one instruction (the fourth is
/// written back as it was). Returns whether a pixel held a range not below `limit`
/// before (a NaN, an empty pixel, counts): `pass_one::splat_depth`'s result.
#[inline(always)]
pub(super) fn depth_3x3(
    simd: V4,
    depth: &mut [u32],
    first: usize,
    width: usize,
    key: u32,
    limit: f32,
) -> bool {
    use core::arch::x86_64::{__m128, __m128i};
    let f = simd.avx512f;
    let keys: __m128i = pulp::cast([key; 4]);
    let limits: __m128 = pulp::cast([limit; 4]);
    let mut seen = 0u8;
    for row in [first, first + width, first + 2 * width] {
        let before: __m128i = pulp::cast(four(depth, row));
        let after = f._mm_mask_min_epu32(before, 0b111, before, keys);
        *<&mut [u32; 4]>::try_from(&mut depth[row..row + 4]).expect("four keys") =
            pulp::cast(after);
        seen |= f._mm_cmp_ps_mask::<NLT>(pulp::cast(before), limits);
    }
    seen & 0b111 != 0
}

/// Pass 2 of a 3 × 3 splat (as [`depth_3x3`]): each row's three pixels whose key is
/// at least `limit` add `sample` and `range_sample` to their two sums, in one masked
/// addition of eight 64-bit lanes (the fourth pixel's sums are written back as they
/// were).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn accumulate_3x3(
    simd: V4,
    depth: &[u32],
    accum: &mut [[u64; 2]],
    first: usize,
    width: usize,
    limit: f32,
    sample: u64,
    range_sample: u64,
) {
    use core::arch::x86_64::__m128;
    let f = simd.avx512f;
    let samples: __m512i = pulp::cast([[sample, range_sample]; 4]);
    let limits: __m128 = pulp::cast([limit; 4]);
    for row in [first, first + width, first + 2 * width] {
        let near = f._mm_cmp_ps_mask::<GE>(pulp::cast(four(depth, row)), limits) & 0b111;
        let sums = <&mut [[u64; 2]; 4]>::try_from(&mut accum[row..row + 4]).expect("four");
        let before: __m512i = pulp::cast(*sums);
        *sums = pulp::cast(f._mm512_mask_add_epi64(before, PAIRS[near as usize], before, samples));
    }
}
