//! The projection of pass 1 on AVX-512, sixteen points per instruction, where the
//! processor has it (found at run time through [`pulp`], whose wrappers make the
//! intrinsics safe to call once the instruction set is known to be there). The same
//! IEEE operations in the same order as [`super::project_point`] and the SSE2 kernel
//! (no fused multiply-add; `max` returns its second operand where the first is a NaN,
//! as `maxps` does), hence bit for bit the same splats (tested against both). Sixteen
//! points are loaded as four vectors and transposed with eight two-source permutes; the
//! splats' words are transposed back with eight more (the SSE2 kernel needs 32 + 32
//! shuffles for as many points).

use core::arch::x86_64::{__m512, __m512i, __mmask16};

use pulp::x86::V4;

use super::{INTENSITY_SCALE, NOT_DRAWN, Splat, View};

/// `_CMP_GT_OQ` and `_CMP_LT_OQ`: ordered comparisons, false where either is a NaN
/// (as SSE's `cmpgtps` / `cmpltps`).
const GT: i32 = 30;
const LT: i32 = 17;

/// Two-source permute indices: lane `k` of the result takes lane `idx[k]` of `a`
/// (below 16) or `idx[k] − 16` of `b`.
const X_Y: [i32; 16] = [0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29];
const Z_G: [i32; 16] = [2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31];
const LOW_EIGHTS: [i32; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23];
const HIGH_EIGHTS: [i32; 16] = [8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31];
const PAIRS_LOW: [i32; 16] = [0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23];
const PAIRS_HIGH: [i32; 16] = [8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31];
const QUADS_LOW: [i32; 16] = [0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23];
const QUADS_HIGH: [i32; 16] = [8, 9, 24, 25, 10, 11, 26, 27, 12, 13, 28, 29, 14, 15, 30, 31];

/// The kernel's vector operations, named as in the SSE2 kernel.
#[derive(Clone, Copy)]
struct Ops(V4);

impl Ops {
    #[inline(always)]
    fn splat(self, x: f32) -> __m512 {
        self.0.avx512f._mm512_set1_ps(x)
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> __m512i {
        self.0.avx512f._mm512_set1_epi32(x)
    }
    #[inline(always)]
    fn indices(self, idx: [i32; 16]) -> __m512i {
        pulp::cast(idx)
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
    fn bits(self, a: __m512) -> __m512i {
        self.0.avx512f._mm512_castps_si512(a)
    }
    #[inline(always)]
    fn to_f32(self, a: __m512i) -> __m512 {
        self.0.avx512f._mm512_cvtepi32_ps(a)
    }
    /// `a − 1` where `k` is set (the SSE2 kernel adds the comparison's −1).
    #[inline(always)]
    fn minus_one_where(self, k: __mmask16, a: __m512i) -> __m512i {
        self.0
            .avx512f
            ._mm512_mask_sub_epi32(a, k, a, self.splat_i(1))
    }
    /// `a` where `k` is set, `b` elsewhere.
    #[inline(always)]
    fn select(self, k: __mmask16, a: __m512i, b: __m512i) -> __m512i {
        self.0.avx512f._mm512_mask_blend_epi32(k, b, a)
    }
    #[inline(always)]
    fn permute(self, a: __m512, idx: [i32; 16], b: __m512) -> __m512 {
        self.0
            .avx512f
            ._mm512_permutex2var_ps(a, self.indices(idx), b)
    }
    #[inline(always)]
    fn permute_i(self, a: __m512i, idx: [i32; 16], b: __m512i) -> __m512i {
        self.0
            .avx512f
            ._mm512_permutex2var_epi32(a, self.indices(idx), b)
    }

    /// [`super::floor_small`].
    #[inline(always)]
    fn floor_small(self, x: __m512) -> __m512i {
        let magic = self.splat(12_582_912.0); // 1.5 · 2^23
        let nearest = self.sub_i(self.bits(self.add(x, magic)), self.bits(magic));
        // One step down where the rounding went up.
        self.minus_one_where(self.gt(self.to_f32(nearest), x), nearest)
    }

    /// [`super::limit`].
    #[inline(always)]
    fn limit(self, x: __m512, lo: f32, hi: f32) -> __m512 {
        self.min(self.max(x, self.splat(lo)), self.splat(hi))
    }

    /// [`super::first_px`].
    #[inline(always)]
    fn first_px(self, x: __m512, half: __m512i) -> __m512i {
        self.sub_i(
            self.floor_small(self.add(self.limit(x, -30_000.0, 30_000.0), self.splat(0.5))),
            half,
        )
    }

    /// The half-width `(width − 1)/2` of [`super::splat_width`].
    #[inline(always)]
    fn splat_half(self, size: __m512, max_half: __m512i) -> __m512i {
        let h = self.limit(
            self.mul(self.sub(size, self.splat(1.0)), self.splat(0.5)),
            0.0,
            1000.0,
        );
        let t = self.floor_small(h);
        // One step up where the floor is below `h` (the SSE2 kernel subtracts −1).
        let up =
            self.0
                .avx512f
                ._mm512_mask_add_epi32(t, self.lt(self.to_f32(t), h), t, self.splat_i(1));
        self.select(self.gt_i(up, max_half), max_half, up)
    }
}

/// The splats of [`super::project_block`], sixteen points at a time (the lengths are
/// equal multiples of sixteen).
#[inline(always)]
pub(super) fn project_splats(
    simd: V4,
    points: &[[f32; 4]],
    footprint: f32,
    view: &View,
    out: &mut [Splat],
) {
    let o = Ops(simd);
    let r = view.rotation;
    let t = view.translation;
    let (r00, r01, r02) = (
        o.splat(r.x_axis.x),
        o.splat(r.y_axis.x),
        o.splat(r.z_axis.x),
    );
    let (r10, r11, r12) = (
        o.splat(r.x_axis.y),
        o.splat(r.y_axis.y),
        o.splat(r.z_axis.y),
    );
    let (r20, r21, r22) = (
        o.splat(r.x_axis.z),
        o.splat(r.y_axis.z),
        o.splat(r.z_axis.z),
    );
    let (tx, ty, tz) = (o.splat(t.x), o.splat(t.y), o.splat(t.z));
    let xi = o.splat(view.xi);
    // `xi <= 1`: every point is then in the domain where `dd > 0`.
    let xi_small: __mmask16 = if view.xi <= 1.0 { u16::MAX } else { 0 };
    let zero = o.splat(0.0);
    let one = o.splat(1.0);
    let (alpha_u, alpha_v, skew) = (
        o.splat(view.alpha_u),
        o.splat(view.alpha_v),
        o.splat(view.skew),
    );
    let (u0, v0) = (o.splat(view.u0), o.splat(view.v0));
    let footprint = o.splat(footprint);
    let max_half = o.splat_i((view.max_width - 1) >> 1);
    let (zero_i, one_i) = (o.splat_i(0), o.splat_i(1));
    let (width, height) = (o.splat_i(view.width), o.splat_i(view.height));
    let not_drawn = o.splat_i(i32::from(NOT_DRAWN));
    let low_half = o.splat_i(0xFFFF);
    let band_factor = o.splat(view.band_factor);
    let (points, _) = points.as_chunks::<16>();
    let (out, _) = out.as_chunks_mut::<16>();
    for (points, out) in points.iter().zip(out) {
        // Sixteen points [x, y, z, grey] transposed into x, y, z and grey.
        let [a, b, c, d]: [__m512; 4] = pulp::cast(*points);
        let (ab_xy, ab_zg) = (o.permute(a, X_Y, b), o.permute(a, Z_G, b));
        let (cd_xy, cd_zg) = (o.permute(c, X_Y, d), o.permute(c, Z_G, d));
        let x = o.permute(ab_xy, LOW_EIGHTS, cd_xy);
        let y = o.permute(ab_xy, HIGH_EIGHTS, cd_xy);
        let z = o.permute(ab_zg, LOW_EIGHTS, cd_zg);
        let grey = o.permute(ab_zg, HIGH_EIGHTS, cd_zg);

        let pcx = o.add(
            o.add(o.add(o.mul(r00, x), o.mul(r01, y)), o.mul(r02, z)),
            tx,
        );
        let pcy = o.add(
            o.add(o.add(o.mul(r10, x), o.mul(r11, y)), o.mul(r12, z)),
            ty,
        );
        let pcz = o.add(
            o.add(o.add(o.mul(r20, x), o.mul(r21, y)), o.mul(r22, z)),
            tz,
        );
        let rho = simd
            .avx512f
            ._mm512_sqrt_ps(o.add(o.add(o.mul(pcx, pcx), o.mul(pcy, pcy)), o.mul(pcz, pcz)));
        let dd = o.add(pcz, o.mul(xi, rho));
        let in_domain = o.gt(dd, zero) & (xi_small | o.gt(o.add(o.mul(xi, pcz), rho), zero));
        let inv_d = o.div(one, dd);
        let u = o.add(
            o.add(
                o.mul(alpha_u, o.mul(pcx, inv_d)),
                o.mul(skew, o.mul(pcy, inv_d)),
            ),
            u0,
        );
        let v = o.add(o.mul(alpha_v, o.mul(pcy, inv_d)), v0);
        let size = o.mul(
            o.mul(footprint, inv_d),
            o.max(o.mul(o.add(rho, o.mul(xi, pcz)), inv_d), one),
        );
        let half = o.splat_half(size, max_half);
        let n = o.add_i(o.add_i(half, half), one_i);
        let (pu, pv) = (o.first_px(u, half), o.first_px(v, half));
        let in_image = o.gt_i(o.add_i(pu, n), zero_i)
            & o.gt_i(o.add_i(pv, n), zero_i)
            & o.gt_i(width, pu)
            & o.gt_i(height, pv);
        let seen = in_domain & in_image;
        let intensity = o.floor_small(o.limit(
            o.add(o.mul(grey, o.splat(INTENSITY_SCALE)), o.splat(0.5)),
            0.0,
            65535.0,
        ));
        // The splats' words, one vector per word, transposed to four words per point.
        let w0 = o.or_i(o.and_i(pu, low_half), o.shl16(pv));
        let w1 = o.or_i(
            o.and_i(o.select(seen, n, not_drawn), low_half),
            o.shl16(intensity),
        );
        let w2 = o.bits(rho);
        let w3 = o.bits(o.div(rho, band_factor));
        let (w01_lo, w01_hi) = (
            o.permute_i(w0, PAIRS_LOW, w1),
            o.permute_i(w0, PAIRS_HIGH, w1),
        );
        let (w23_lo, w23_hi) = (
            o.permute_i(w2, PAIRS_LOW, w3),
            o.permute_i(w2, PAIRS_HIGH, w3),
        );
        let quads = [
            o.permute_i(w01_lo, QUADS_LOW, w23_lo),
            o.permute_i(w01_lo, QUADS_HIGH, w23_lo),
            o.permute_i(w01_hi, QUADS_LOW, w23_hi),
            o.permute_i(w01_hi, QUADS_HIGH, w23_hi),
        ];
        for (quad, out) in quads.iter().zip(out.chunks_exact_mut(4)) {
            let words: [[u32; 4]; 4] = pulp::cast(*quad);
            for (word, out) in words.iter().zip(out) {
                *out = Splat(*word);
            }
        }
    }
}
