//! The projection of pass 1 on AVX2, eight points per instruction, where the processor
//! has it but not AVX-512 (found at run time through [`pulp`], whose wrappers make the
//! intrinsics safe to call once the instruction set is known to be there): the SSE2
//! kernel on both 128-bit halves of each register at once, the same IEEE operations in
//! the same order, hence bit for bit the same splats (tested). Eight points are loaded
//! as four registers and transposed within each half, which puts points 0, 2, 4, 6 in
//! the lower half and 1, 3, 5, 7 in the upper one; the same transposition of the
//! splats' words puts them back in order.

use core::arch::x86_64::{__m256, __m256i};

use pulp::x86::V3;

use super::{INTENSITY_SCALE, NOT_DRAWN, Splat, View};

/// `_CMP_GT_OQ` and `_CMP_LT_OQ`: ordered comparisons, false where either is a NaN
/// (as SSE's `cmpgtps` / `cmpltps`).
const GT: i32 = 30;
const LT: i32 = 17;

/// The kernel's vector operations, named as in the SSE2 kernel.
#[derive(Clone, Copy)]
struct Ops(V3);

impl Ops {
    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        self.0.avx._mm256_set1_ps(x)
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> __m256i {
        self.0.avx._mm256_set1_epi32(x)
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
    fn max(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_max_ps(a, b)
    }
    #[inline(always)]
    fn min(self, a: __m256, b: __m256) -> __m256 {
        self.0.avx._mm256_min_ps(a, b)
    }
    /// All ones where `a > b` (false on a NaN), as 32-bit lanes.
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
    fn floats(self, a: __m256i) -> __m256 {
        self.0.avx._mm256_castsi256_ps(a)
    }
    #[inline(always)]
    fn bits(self, a: __m256) -> __m256i {
        self.0.avx._mm256_castps_si256(a)
    }
    #[inline(always)]
    fn to_f32(self, a: __m256i) -> __m256 {
        self.0.avx._mm256_cvtepi32_ps(a)
    }
    /// `a` where `mask` is set, `b` elsewhere.
    #[inline(always)]
    fn select(self, mask: __m256i, a: __m256i, b: __m256i) -> __m256i {
        self.or_i(
            self.and_i(mask, a),
            self.0.avx2._mm256_andnot_si256(mask, b),
        )
    }

    /// [`super::floor_small`].
    #[inline(always)]
    fn floor_small(self, x: __m256) -> __m256i {
        let magic = self.splat(12_582_912.0); // 1.5 · 2^23
        let nearest = self.sub_i(self.bits(self.add(x, magic)), self.bits(magic));
        // One step down where the rounding went up (a true comparison is −1).
        self.add_i(nearest, self.gt(self.to_f32(nearest), x))
    }

    /// [`super::limit`].
    #[inline(always)]
    fn limit(self, x: __m256, lo: f32, hi: f32) -> __m256 {
        self.min(self.max(x, self.splat(lo)), self.splat(hi))
    }

    /// [`super::first_px`].
    #[inline(always)]
    fn first_px(self, x: __m256, half: __m256i) -> __m256i {
        self.sub_i(
            self.floor_small(self.add(self.limit(x, -30_000.0, 30_000.0), self.splat(0.5))),
            half,
        )
    }

    /// The half-width `(width − 1)/2` of [`super::splat_width`].
    #[inline(always)]
    fn splat_half(self, size: __m256, max_half: __m256i) -> __m256i {
        let h = self.limit(
            self.mul(self.sub(size, self.splat(1.0)), self.splat(0.5)),
            0.0,
            1000.0,
        );
        let t = self.floor_small(h);
        let up = self.sub_i(t, self.lt(self.to_f32(t), h));
        self.select(self.gt_i(up, max_half), max_half, up)
    }

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
}

/// The splats of [`super::project_block`], eight points at a time (the lengths are
/// equal multiples of eight).
#[inline(always)]
pub(super) fn project_splats(
    simd: V3,
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
    // `xi <= 1` as a mask: every point is then in the domain where `dd > 0`.
    let xi_small = o.splat_i(-i32::from(view.xi <= 1.0));
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
    let (points, _) = points.as_chunks::<8>();
    let (out, _) = out.as_chunks_mut::<8>();
    for (points, out) in points.iter().zip(out) {
        // Eight points [x, y, z, grey], two per register, transposed within each
        // half: x, y, z and grey of points 0, 2, 4, 6 | 1, 3, 5, 7.
        let registers: [__m256i; 4] = pulp::cast(*points);
        let [x, y, z, grey] = o.transpose_halves(registers);
        let (x, y, z, grey) = (o.floats(x), o.floats(y), o.floats(z), o.floats(grey));

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
            .avx
            ._mm256_sqrt_ps(o.add(o.add(o.mul(pcx, pcx), o.mul(pcy, pcy)), o.mul(pcz, pcz)));
        let dd = o.add(pcz, o.mul(xi, rho));
        let in_domain = o.and_i(
            o.gt(dd, zero),
            o.or_i(xi_small, o.gt(o.add(o.mul(xi, pcz), rho), zero)),
        );
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
        let in_image = o.and_i(
            o.and_i(
                o.gt_i(o.add_i(pu, n), zero_i),
                o.gt_i(o.add_i(pv, n), zero_i),
            ),
            o.and_i(o.gt_i(width, pu), o.gt_i(height, pv)),
        );
        let seen = o.and_i(in_domain, in_image);
        let intensity = o.floor_small(o.limit(
            o.add(o.mul(grey, o.splat(INTENSITY_SCALE)), o.splat(0.5)),
            0.0,
            65535.0,
        ));
        // The splats' words, one register per word, transposed back to four words per
        // point: points 0 | 1, 2 | 3, 4 | 5, 6 | 7.
        let words = [
            o.or_i(o.and_i(pu, low_half), o.shl16(pv)),
            o.or_i(
                o.and_i(o.select(seen, n, not_drawn), low_half),
                o.shl16(intensity),
            ),
            o.bits(rho),
            o.bits(o.div(rho, band_factor)),
        ];
        let pairs: [[[u32; 4]; 2]; 4] = pulp::cast(o.transpose_halves(words));
        for (out, splat) in out.iter_mut().zip(pairs.as_flattened()) {
            *out = Splat(*splat);
        }
    }
}
