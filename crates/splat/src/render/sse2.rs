//! The projection of pass 1 in explicit SSE2 (part of every x86-64 processor), through
//! `safe_arch`'s safe wrappers of the intrinsics: four points per instruction, the same
//! IEEE operations in the same order as [`super::project::project_point`], hence bit
//! for bit the same splats (tested against it). The compiler's own vectorisation of the
//! portable kernel gathered each coordinate of each point with its own load; here four
//! points (8 bytes each) are loaded as two registers and their words taken apart with
//! two shuffles.

use safe_arch::*;

use super::lanes::{Constants, Vectors, splat_words, unpack};
use super::splat::Splat;
use super::view::View;
use crate::PackedPoint;

/// The kernel's registers (a lane mask is a register of all-ones lanes).
#[derive(Clone, Copy)]
struct Ops;

impl Vectors for Ops {
    type F = m128;
    type I = m128i;
    type M = m128i;

    #[inline(always)]
    fn splat(self, x: f32) -> m128 {
        set_splat_m128(x)
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> m128i {
        set_splat_i32_m128i(x)
    }
    #[inline(always)]
    fn mask_if(self, set: bool) -> m128i {
        set_splat_i32_m128i(-i32::from(set))
    }
    #[inline(always)]
    fn add(self, a: m128, b: m128) -> m128 {
        add_m128(a, b)
    }
    #[inline(always)]
    fn sub(self, a: m128, b: m128) -> m128 {
        sub_m128(a, b)
    }
    #[inline(always)]
    fn mul(self, a: m128, b: m128) -> m128 {
        mul_m128(a, b)
    }
    #[inline(always)]
    fn div(self, a: m128, b: m128) -> m128 {
        div_m128(a, b)
    }
    #[inline(always)]
    fn sqrt(self, a: m128) -> m128 {
        sqrt_m128(a)
    }
    /// `maxps` returns its second operand where the first is a NaN, as `f32::max`
    /// returns the number.
    #[inline(always)]
    fn max(self, a: m128, b: m128) -> m128 {
        max_m128(a, b)
    }
    #[inline(always)]
    fn min(self, a: m128, b: m128) -> m128 {
        min_m128(a, b)
    }
    #[inline(always)]
    fn gt(self, a: m128, b: m128) -> m128i {
        cast_to_m128i_from_m128(cmp_gt_mask_m128(a, b))
    }
    #[inline(always)]
    fn lt(self, a: m128, b: m128) -> m128i {
        cast_to_m128i_from_m128(cmp_lt_mask_m128(a, b))
    }
    #[inline(always)]
    fn gt_i(self, a: m128i, b: m128i) -> m128i {
        cmp_gt_mask_i32_m128i(a, b)
    }
    #[inline(always)]
    fn and_m(self, a: m128i, b: m128i) -> m128i {
        bitand_m128i(a, b)
    }
    #[inline(always)]
    fn or_m(self, a: m128i, b: m128i) -> m128i {
        bitor_m128i(a, b)
    }
    #[inline(always)]
    fn add_i(self, a: m128i, b: m128i) -> m128i {
        add_i32_m128i(a, b)
    }
    #[inline(always)]
    fn sub_i(self, a: m128i, b: m128i) -> m128i {
        sub_i32_m128i(a, b)
    }
    #[inline(always)]
    fn and_i(self, a: m128i, b: m128i) -> m128i {
        bitand_m128i(a, b)
    }
    #[inline(always)]
    fn or_i(self, a: m128i, b: m128i) -> m128i {
        bitor_m128i(a, b)
    }
    #[inline(always)]
    fn shl16(self, a: m128i) -> m128i {
        shl_imm_u32_m128i::<16>(a)
    }
    #[inline(always)]
    fn shr16(self, a: m128i) -> m128i {
        shr_imm_u32_m128i::<16>(a)
    }
    #[inline(always)]
    fn mul_u16(self, a: m128i, b: m128i) -> m128i {
        // SSE2 has no 32-bit product: with both factors in the low halves (the high
        // halves zero), the low and high halves of their 16-bit product.
        bitor_m128i(
            mul_i16_keep_low_m128i(a, b),
            shl_imm_u32_m128i::<16>(mul_u16_keep_high_m128i(a, b)),
        )
    }
    #[inline(always)]
    fn bits(self, a: m128) -> m128i {
        cast_to_m128i_from_m128(a)
    }
    #[inline(always)]
    fn to_f32(self, a: m128i) -> m128 {
        convert_to_m128_from_i32_m128i(a)
    }
    /// A true lane is −1: added, it subtracts one.
    #[inline(always)]
    fn minus_one_where(self, mask: m128i, a: m128i) -> m128i {
        add_i32_m128i(a, mask)
    }
    #[inline(always)]
    fn plus_one_where(self, mask: m128i, a: m128i) -> m128i {
        sub_i32_m128i(a, mask)
    }
    #[inline(always)]
    fn select(self, mask: m128i, a: m128i, b: m128i) -> m128i {
        bitor_m128i(bitand_m128i(mask, a), bitandnot_m128i(mask, b))
    }
}

/// The four 32-bit lanes as a splat's words.
#[inline(always)]
fn splat_words_of(v: m128i) -> Splat {
    let lanes: [i32; 4] = v.into();
    Splat(lanes.map(|x| x as u32))
}

/// The splats of [`super::project::project_block`], four points at a time (`N` is a
/// multiple of four).
#[inline(always)]
pub(super) fn project_splats<const N: usize>(
    points: &[PackedPoint; N],
    footprint: f32,
    view: &View,
    out: &mut [Splat; N],
) {
    const { assert!(N.is_multiple_of(4)) };
    let constants = Constants::new(Ops, view, footprint);
    for base in (0..N).step_by(4) {
        // Four points of two 32-bit words each: their first words, their second.
        let [a, b]: [[i32; 4]; 2] = bytemuck::cast([
            points[base],
            points[base + 1],
            points[base + 2],
            points[base + 3],
        ]);
        let (a, b) = (
            cast_to_m128_from_m128i(a.into()),
            cast_to_m128_from_m128i(b.into()),
        );
        let xy = cast_to_m128i_from_m128(shuffle_abi_f32_all_m128::<0b10_00_10_00>(a, b));
        let zi = cast_to_m128i_from_m128(shuffle_abi_f32_all_m128::<0b11_01_11_01>(a, b));
        let (steps, intensity) = unpack(Ops, &constants, xy, zi);
        // The splats' words, one vector per word, transposed to one vector per point.
        let words = splat_words(Ops, &constants, steps, intensity);
        let (w01_lo, w23_lo) = (
            unpack_low_i32_m128i(words[0], words[1]),
            unpack_low_i32_m128i(words[2], words[3]),
        );
        let (w01_hi, w23_hi) = (
            unpack_high_i32_m128i(words[0], words[1]),
            unpack_high_i32_m128i(words[2], words[3]),
        );
        out[base] = splat_words_of(unpack_low_i64_m128i(w01_lo, w23_lo));
        out[base + 1] = splat_words_of(unpack_high_i64_m128i(w01_lo, w23_lo));
        out[base + 2] = splat_words_of(unpack_low_i64_m128i(w01_hi, w23_hi));
        out[base + 3] = splat_words_of(unpack_high_i64_m128i(w01_hi, w23_hi));
    }
}
