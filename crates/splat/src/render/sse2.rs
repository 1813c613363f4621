//! The projection of pass 1 in explicit SSE2 (part of every x86-64 processor), through
//! `safe_arch`'s safe wrappers of the intrinsics: four points per instruction, the
//! same IEEE operations in the same order as [`super::project_point`], hence bit for
//! bit the same splats (tested against it). The compiler's own vectorisation of the
//! portable kernel gathered each coordinate of each point with its own load; here four
//! points are loaded whole and transposed with eight shuffles.

use safe_arch::*;

use super::{INTENSITY_SCALE, NOT_DRAWN, Splat, View};

#[inline(always)]
fn splat(x: f32) -> m128 {
    set_splat_m128(x)
}

/// The four 32-bit lanes as a splat's words.
#[inline(always)]
fn splat_words(v: m128i) -> Splat {
    let lanes: [i32; 4] = v.into();
    Splat(lanes.map(|x| x as u32))
}

/// [`super::floor_small`] of four values.
#[inline(always)]
fn floor_small(x: m128) -> m128i {
    let magic = splat(12_582_912.0); // 1.5 · 2^23
    let nearest = sub_i32_m128i(
        cast_to_m128i_from_m128(add_m128(x, magic)),
        cast_to_m128i_from_m128(magic),
    );
    // One step down where the rounding went up (a true comparison is −1).
    add_i32_m128i(
        nearest,
        cast_to_m128i_from_m128(cmp_gt_mask_m128(convert_to_m128_from_i32_m128i(nearest), x)),
    )
}

/// [`super::limit`]: `maxps` returns its second operand where the first is a NaN, as
/// `f32::max` returns the number.
#[inline(always)]
fn limit(x: m128, lo: f32, hi: f32) -> m128 {
    min_m128(max_m128(x, splat(lo)), splat(hi))
}

/// [`super::first_px`]: `round(x) − half`, with `half = (width − 1)/2`.
#[inline(always)]
fn first_px(x: m128, half: m128i) -> m128i {
    sub_i32_m128i(
        floor_small(add_m128(limit(x, -30_000.0, 30_000.0), splat(0.5))),
        half,
    )
}

/// `a` where `mask` is set, `b` elsewhere.
#[inline(always)]
fn select(mask: m128i, a: m128i, b: m128i) -> m128i {
    bitor_m128i(bitand_m128i(mask, a), bitandnot_m128i(mask, b))
}

/// The half-width `(width − 1)/2` of [`super::splat_width`].
#[inline(always)]
fn splat_half(size: m128, max_half: m128i) -> m128i {
    let h = limit(
        mul_m128(sub_m128(size, splat(1.0)), splat(0.5)),
        0.0,
        1000.0,
    );
    let t = floor_small(h);
    let up = sub_i32_m128i(
        t,
        cast_to_m128i_from_m128(cmp_lt_mask_m128(convert_to_m128_from_i32_m128i(t), h)),
    );
    select(cmp_gt_mask_i32_m128i(up, max_half), max_half, up)
}

/// The splats of [`super::project_block`], four points at a time (`N` is a multiple
/// of four).
#[inline(always)]
pub(super) fn project_splats<const N: usize>(
    points: &[[f32; 4]; N],
    footprint: f32,
    view: &View,
    out: &mut [Splat; N],
) {
    const { assert!(N.is_multiple_of(4)) };
    let (add, mul) = (add_m128, mul_m128);
    let r = view.rotation;
    let t = view.translation;
    let (r00, r01, r02) = (splat(r.x_axis.x), splat(r.y_axis.x), splat(r.z_axis.x));
    let (r10, r11, r12) = (splat(r.x_axis.y), splat(r.y_axis.y), splat(r.z_axis.y));
    let (r20, r21, r22) = (splat(r.x_axis.z), splat(r.y_axis.z), splat(r.z_axis.z));
    let (tx, ty, tz) = (splat(t.x), splat(t.y), splat(t.z));
    let xi = splat(view.xi);
    // `xi <= 1` as a mask: every point is then in the domain where `dd > 0`.
    let xi_small = cast_to_m128_from_m128i(set_splat_i32_m128i(-i32::from(view.xi <= 1.0)));
    let zero = zeroed_m128();
    let one = splat(1.0);
    let (alpha_u, alpha_v, skew) = (splat(view.alpha_u), splat(view.alpha_v), splat(view.skew));
    let (u0, v0) = (splat(view.u0), splat(view.v0));
    let footprint = splat(footprint);
    let max_half = set_splat_i32_m128i((view.max_width - 1) >> 1);
    let (zero_i, one_i) = (zeroed_m128i(), set_splat_i32_m128i(1));
    let (width, height) = (
        set_splat_i32_m128i(view.width),
        set_splat_i32_m128i(view.height),
    );
    let not_drawn = set_splat_i32_m128i(i32::from(NOT_DRAWN));
    let low_half = set_splat_i32_m128i(0xFFFF);
    let band_factor = splat(view.band_factor);
    for base in (0..N).step_by(4) {
        // Four points [x, y, z, grey] transposed into x, y, z and grey of four points.
        let a = m128::from_array(points[base]);
        let b = m128::from_array(points[base + 1]);
        let c = m128::from_array(points[base + 2]);
        let d = m128::from_array(points[base + 3]);
        let (ab_lo, cd_lo) = (unpack_low_m128(a, b), unpack_low_m128(c, d));
        let (ab_hi, cd_hi) = (unpack_high_m128(a, b), unpack_high_m128(c, d));
        let x = move_low_high_m128(ab_lo, cd_lo);
        let y = move_high_low_m128(cd_lo, ab_lo);
        let z = move_low_high_m128(ab_hi, cd_hi);
        let grey = move_high_low_m128(cd_hi, ab_hi);

        let pcx = add(add(add(mul(r00, x), mul(r01, y)), mul(r02, z)), tx);
        let pcy = add(add(add(mul(r10, x), mul(r11, y)), mul(r12, z)), ty);
        let pcz = add(add(add(mul(r20, x), mul(r21, y)), mul(r22, z)), tz);
        let rho = sqrt_m128(add(add(mul(pcx, pcx), mul(pcy, pcy)), mul(pcz, pcz)));
        let dd = add(pcz, mul(xi, rho));
        let in_domain = bitand_m128(
            cmp_gt_mask_m128(dd, zero),
            bitor_m128(xi_small, cmp_gt_mask_m128(add(mul(xi, pcz), rho), zero)),
        );
        let inv_d = div_m128(one, dd);
        let u = add(
            add(mul(alpha_u, mul(pcx, inv_d)), mul(skew, mul(pcy, inv_d))),
            u0,
        );
        let v = add(mul(alpha_v, mul(pcy, inv_d)), v0);
        let size = mul(
            mul(footprint, inv_d),
            max_m128(mul(add(rho, mul(xi, pcz)), inv_d), one),
        );
        let half = splat_half(size, max_half);
        let n = add_i32_m128i(add_i32_m128i(half, half), one_i);
        let (pu, pv) = (first_px(u, half), first_px(v, half));
        let in_image = bitand_m128i(
            bitand_m128i(
                cmp_gt_mask_i32_m128i(add_i32_m128i(pu, n), zero_i),
                cmp_gt_mask_i32_m128i(add_i32_m128i(pv, n), zero_i),
            ),
            bitand_m128i(
                cmp_gt_mask_i32_m128i(width, pu),
                cmp_gt_mask_i32_m128i(height, pv),
            ),
        );
        let seen = bitand_m128i(cast_to_m128i_from_m128(in_domain), in_image);
        let intensity = floor_small(limit(
            add(mul(grey, splat(INTENSITY_SCALE)), splat(0.5)),
            0.0,
            65535.0,
        ));
        // The splats' words, [iu | iv << 16, width | intensity << 16, range, limit] per
        // point, transposed from one vector per word to one per point.
        let words = [
            bitor_m128i(bitand_m128i(pu, low_half), shl_imm_u32_m128i::<16>(pv)),
            bitor_m128i(
                bitand_m128i(select(seen, n, not_drawn), low_half),
                shl_imm_u32_m128i::<16>(intensity),
            ),
            cast_to_m128i_from_m128(rho),
            cast_to_m128i_from_m128(div_m128(rho, band_factor)),
        ];
        let (w01_lo, w23_lo) = (
            unpack_low_i32_m128i(words[0], words[1]),
            unpack_low_i32_m128i(words[2], words[3]),
        );
        let (w01_hi, w23_hi) = (
            unpack_high_i32_m128i(words[0], words[1]),
            unpack_high_i32_m128i(words[2], words[3]),
        );
        out[base] = splat_words(unpack_low_i64_m128i(w01_lo, w23_lo));
        out[base + 1] = splat_words(unpack_high_i64_m128i(w01_lo, w23_lo));
        out[base + 2] = splat_words(unpack_low_i64_m128i(w01_hi, w23_hi));
        out[base + 3] = splat_words(unpack_high_i64_m128i(w01_hi, w23_hi));
    }
}
