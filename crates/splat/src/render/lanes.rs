//! The arithmetic of the vector projection kernels, written once for every register
//! width: the same IEEE operations in the same order as
//! [`super::project::project_point`], on four (SSE2), eight (AVX2) or sixteen (AVX-512)
//! points at a time. Each kernel implements [`Vectors`] for its registers and does its
//! own loads and transposes.

use super::splat::NOT_DRAWN;
use super::view::View;

/// The operations the projection needs on one register width: `F` holds floats, `I`
/// 32-bit integers, `M` a lane mask (a register of all-ones lanes on SSE2 and AVX2, a
/// mask register on AVX-512). Comparisons are ordered (false where either is a NaN);
/// `max` and `min` return their second operand where the first is a NaN (`maxps`).
pub(super) trait Vectors: Copy {
    /// A register of floats.
    type F: Copy;
    /// A register of 32-bit integers.
    type I: Copy;
    /// A lane mask.
    type M: Copy;

    fn splat(self, x: f32) -> Self::F;
    fn splat_i(self, x: i32) -> Self::I;
    /// Every lane set if `set`, none otherwise.
    fn mask_if(self, set: bool) -> Self::M;
    fn add(self, a: Self::F, b: Self::F) -> Self::F;
    fn sub(self, a: Self::F, b: Self::F) -> Self::F;
    fn mul(self, a: Self::F, b: Self::F) -> Self::F;
    fn div(self, a: Self::F, b: Self::F) -> Self::F;
    fn sqrt(self, a: Self::F) -> Self::F;
    fn max(self, a: Self::F, b: Self::F) -> Self::F;
    fn min(self, a: Self::F, b: Self::F) -> Self::F;
    fn gt(self, a: Self::F, b: Self::F) -> Self::M;
    fn lt(self, a: Self::F, b: Self::F) -> Self::M;
    fn gt_i(self, a: Self::I, b: Self::I) -> Self::M;
    fn and_m(self, a: Self::M, b: Self::M) -> Self::M;
    fn or_m(self, a: Self::M, b: Self::M) -> Self::M;
    fn add_i(self, a: Self::I, b: Self::I) -> Self::I;
    fn sub_i(self, a: Self::I, b: Self::I) -> Self::I;
    fn and_i(self, a: Self::I, b: Self::I) -> Self::I;
    fn or_i(self, a: Self::I, b: Self::I) -> Self::I;
    fn shl16(self, a: Self::I) -> Self::I;
    /// Logical shift right by 16 bits.
    fn shr16(self, a: Self::I) -> Self::I;
    /// `a · b` in the lanes where `0 ≤ a, b < 2^16` (anything elsewhere).
    fn mul_u16(self, a: Self::I, b: Self::I) -> Self::I;
    /// The float's bits.
    fn bits(self, a: Self::F) -> Self::I;
    /// The integer converted to a float.
    fn to_f32(self, a: Self::I) -> Self::F;
    /// `a − 1` where `mask` is set.
    fn minus_one_where(self, mask: Self::M, a: Self::I) -> Self::I;
    /// `a + 1` where `mask` is set.
    fn plus_one_where(self, mask: Self::M, a: Self::I) -> Self::I;
    /// `a` where `mask` is set, `b` elsewhere.
    fn select(self, mask: Self::M, a: Self::I, b: Self::I) -> Self::I;
}

/// [`super::project::floor_small`].
#[inline(always)]
fn floor_small<V: Vectors>(o: V, x: V::F) -> V::I {
    let magic = o.splat(12_582_912.0); // 1.5 · 2^23
    let nearest = o.sub_i(o.bits(o.add(x, magic)), o.bits(magic));
    // One step down where the rounding went up.
    o.minus_one_where(o.gt(o.to_f32(nearest), x), nearest)
}

/// [`super::project::limit`].
#[inline(always)]
fn limit<V: Vectors>(o: V, x: V::F, lo: f32, hi: f32) -> V::F {
    o.min(o.max(x, o.splat(lo)), o.splat(hi))
}

/// `project::first_px`: `round(x) − half`.
#[inline(always)]
fn first_px<V: Vectors>(o: V, x: V::F, half: V::I) -> V::I {
    o.sub_i(
        floor_small(o, o.add(limit(o, x, -30_000.0, 30_000.0), o.splat(0.5))),
        half,
    )
}

/// The half-width `(width − 1)/2` of `project::splat_width`.
#[inline(always)]
fn splat_half<V: Vectors>(o: V, size: V::F, max_half: V::I) -> V::I {
    let h = limit(
        o,
        o.mul(o.sub(size, o.splat(1.0)), o.splat(0.5)),
        0.0,
        1000.0,
    );
    let t = floor_small(o, h);
    let up = o.plus_one_where(o.lt(o.to_f32(t), h), t);
    o.select(o.gt_i(up, max_half), max_half, up)
}

/// The per-view constants of the projection, in registers.
pub(super) struct Constants<V: Vectors> {
    rotation: [[V::F; 3]; 3],
    translation: [V::F; 3],
    xi: V::F,
    /// `xi <= 1`: every point is then in the domain where `dd > 0`.
    xi_small: V::M,
    zero: V::F,
    one: V::F,
    alpha_u: V::F,
    alpha_v: V::F,
    skew: V::F,
    u0: V::F,
    v0: V::F,
    footprint: V::F,
    max_half: V::I,
    zero_i: V::I,
    one_i: V::I,
    origin_u: V::I,
    origin_v: V::I,
    width: V::I,
    height: V::I,
    not_drawn: V::I,
    low_half: V::I,
    band_factor: V::F,
}

impl<V: Vectors> Constants<V> {
    #[inline(always)]
    pub(super) fn new(o: V, view: &View, footprint: f32) -> Self {
        let r = view.point_rotation;
        let t = view.point_translation;
        Self {
            rotation: [
                [
                    o.splat(r.x_axis.x),
                    o.splat(r.y_axis.x),
                    o.splat(r.z_axis.x),
                ],
                [
                    o.splat(r.x_axis.y),
                    o.splat(r.y_axis.y),
                    o.splat(r.z_axis.y),
                ],
                [
                    o.splat(r.x_axis.z),
                    o.splat(r.y_axis.z),
                    o.splat(r.z_axis.z),
                ],
            ],
            translation: [o.splat(t.x), o.splat(t.y), o.splat(t.z)],
            xi: o.splat(view.xi),
            xi_small: o.mask_if(view.xi <= 1.0),
            zero: o.splat(0.0),
            one: o.splat(1.0),
            alpha_u: o.splat(view.alpha_u),
            alpha_v: o.splat(view.alpha_v),
            skew: o.splat(view.skew),
            u0: o.splat(view.u0),
            v0: o.splat(view.v0),
            footprint: o.splat(footprint),
            max_half: o.splat_i((view.max_width - 1) >> 1),
            zero_i: o.splat_i(0),
            one_i: o.splat_i(1),
            origin_u: o.splat_i(view.origin[0]),
            origin_v: o.splat_i(view.origin[1]),
            width: o.splat_i(view.width),
            height: o.splat_i(view.height),
            not_drawn: o.splat_i(i32::from(NOT_DRAWN)),
            low_half: o.splat_i(0xFFFF),
            band_factor: o.splat(view.band_factor),
        }
    }
}

/// A register of packed points ([`crate::PackedPoint`]) as two registers of 32-bit
/// words, `xy` (`x | y << 16`, the points' first words) and `zi` (`z | intensity <<
/// 16`), taken apart: their steps as floats (exact) and their intensities.
#[inline(always)]
pub(super) fn unpack<V: Vectors>(o: V, c: &Constants<V>, xy: V::I, zi: V::I) -> ([V::F; 3], V::I) {
    (
        [
            o.to_f32(o.and_i(xy, c.low_half)),
            o.to_f32(o.shr16(xy)),
            o.to_f32(o.and_i(zi, c.low_half)),
        ],
        o.shr16(zi),
    )
}

/// The four words of the splats of one register of points (given as their steps
/// `x`, `y`, `z` from the corner of the view's cell, and their intensities), one
/// register per word: the pixel's index in the region for a single-pixel splat, else
/// `iu | iv << 16`; `width | intensity << 16`; the range's bits; its band limit's bits.
#[inline(always)]
pub(super) fn splat_words<V: Vectors>(
    o: V,
    c: &Constants<V>,
    steps: [V::F; 3],
    intensity: V::I,
) -> [V::I; 4] {
    words_of_rays(o, c, rays(o, c, steps, intensity))
}

/// The first half of [`splat_words`]: the points in the camera frame, their ranges and
/// the model's denominators (up to the square root and the division, the chain's
/// slowest operations), for [`words_of_rays`].
pub(super) struct Rays<V: Vectors> {
    pcx: V::F,
    pcy: V::F,
    pcz: V::F,
    rho: V::F,
    inv_d: V::F,
    in_domain: V::M,
    intensity: V::I,
}

impl<V: Vectors> Clone for Rays<V> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<V: Vectors> Copy for Rays<V> {}

/// [`Rays`] of a register of points.
#[inline(always)]
pub(super) fn rays<V: Vectors>(
    o: V,
    c: &Constants<V>,
    [x, y, z]: [V::F; 3],
    intensity: V::I,
) -> Rays<V> {
    let [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]] = c.rotation;
    let [tx, ty, tz] = c.translation;
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
    let rho = o.sqrt(o.add(o.add(o.mul(pcx, pcx), o.mul(pcy, pcy)), o.mul(pcz, pcz)));
    let xi = c.xi;
    let dd = o.add(pcz, o.mul(xi, rho));
    let in_domain = o.and_m(
        o.gt(dd, c.zero),
        o.or_m(c.xi_small, o.gt(o.add(o.mul(xi, pcz), rho), c.zero)),
    );
    let inv_d = o.div(c.one, dd);
    Rays {
        pcx,
        pcy,
        pcz,
        rho,
        inv_d,
        in_domain,
        intensity,
    }
}

/// The second half of [`splat_words`].
#[inline(always)]
pub(super) fn words_of_rays<V: Vectors>(o: V, c: &Constants<V>, r: Rays<V>) -> [V::I; 4] {
    let Rays {
        pcx,
        pcy,
        pcz,
        rho,
        inv_d,
        in_domain,
        intensity,
    } = r;
    let xi = c.xi;
    let u = o.add(
        o.add(
            o.mul(c.alpha_u, o.mul(pcx, inv_d)),
            o.mul(c.skew, o.mul(pcy, inv_d)),
        ),
        c.u0,
    );
    let v = o.add(o.mul(c.alpha_v, o.mul(pcy, inv_d)), c.v0);
    let size = o.mul(
        o.mul(c.footprint, inv_d),
        o.max(o.mul(o.add(rho, o.mul(xi, pcz)), inv_d), c.one),
    );
    let half = splat_half(o, size, c.max_half);
    let n = o.add_i(o.add_i(half, half), c.one_i);
    let (pu, pv) = (
        o.sub_i(first_px(o, u, half), c.origin_u),
        o.sub_i(first_px(o, v, half), c.origin_v),
    );
    let in_image = o.and_m(
        o.and_m(
            o.gt_i(o.add_i(pu, n), c.zero_i),
            o.gt_i(o.add_i(pv, n), c.zero_i),
        ),
        o.and_m(o.gt_i(c.width, pu), o.gt_i(c.height, pv)),
    );
    let seen = o.and_m(in_domain, in_image);
    // A single-pixel splat (half-width 0) that is seen lies inside the region: its
    // pixel's index; a wider one, its first column and row.
    let at = o.select(
        o.gt_i(c.one_i, half),
        o.add_i(o.mul_u16(pv, c.width), pu),
        o.or_i(o.and_i(pu, c.low_half), o.shl16(pv)),
    );
    [
        at,
        o.or_i(
            o.and_i(o.select(seen, n, c.not_drawn), c.low_half),
            o.shl16(intensity),
        ),
        o.bits(rho),
        o.bits(o.div(rho, c.band_factor)),
    ]
}

/// Two registers of `V` as one: every operation on both, the first's before the
/// second's. The projection's arithmetic is a chain of dependent operations (a square
/// root, two divisions) longer than a processor's window of instructions can overlap
/// from one block of points to the next; two independent chains side by side keep its
/// units busy. The same operations on every lane, hence the same bits.
#[derive(Clone, Copy)]
pub(super) struct Pair<V>(pub(super) V);

/// The methods of [`Vectors`] for [`Pair`] that take registers: each on both halves,
/// the first's before the second's (no closures: a closure that is not inlined is
/// compiled without the caller's instruction set).
macro_rules! on_both {
    ($(fn $name:ident(self, $($arg:ident: $ty:ty),*) -> $ret:ty;)*) => {
        $(
            #[inline(always)]
            fn $name(self, $($arg: $ty),*) -> $ret {
                [self.0.$name($($arg[0]),*), self.0.$name($($arg[1]),*)]
            }
        )*
    };
}

impl<V: Vectors> Vectors for Pair<V> {
    type F = [V::F; 2];
    type I = [V::I; 2];
    type M = [V::M; 2];

    #[inline(always)]
    fn splat(self, x: f32) -> Self::F {
        let v = self.0.splat(x);
        [v, v]
    }
    #[inline(always)]
    fn splat_i(self, x: i32) -> Self::I {
        let v = self.0.splat_i(x);
        [v, v]
    }
    #[inline(always)]
    fn mask_if(self, set: bool) -> Self::M {
        let m = self.0.mask_if(set);
        [m, m]
    }
    on_both! {
        fn add(self, a: Self::F, b: Self::F) -> Self::F;
        fn sub(self, a: Self::F, b: Self::F) -> Self::F;
        fn mul(self, a: Self::F, b: Self::F) -> Self::F;
        fn div(self, a: Self::F, b: Self::F) -> Self::F;
        fn sqrt(self, a: Self::F) -> Self::F;
        fn max(self, a: Self::F, b: Self::F) -> Self::F;
        fn min(self, a: Self::F, b: Self::F) -> Self::F;
        fn gt(self, a: Self::F, b: Self::F) -> Self::M;
        fn lt(self, a: Self::F, b: Self::F) -> Self::M;
        fn gt_i(self, a: Self::I, b: Self::I) -> Self::M;
        fn and_m(self, a: Self::M, b: Self::M) -> Self::M;
        fn or_m(self, a: Self::M, b: Self::M) -> Self::M;
        fn add_i(self, a: Self::I, b: Self::I) -> Self::I;
        fn sub_i(self, a: Self::I, b: Self::I) -> Self::I;
        fn and_i(self, a: Self::I, b: Self::I) -> Self::I;
        fn or_i(self, a: Self::I, b: Self::I) -> Self::I;
        fn shl16(self, a: Self::I) -> Self::I;
        fn shr16(self, a: Self::I) -> Self::I;
        fn mul_u16(self, a: Self::I, b: Self::I) -> Self::I;
        fn bits(self, a: Self::F) -> Self::I;
        fn to_f32(self, a: Self::I) -> Self::F;
        fn minus_one_where(self, mask: Self::M, a: Self::I) -> Self::I;
        fn plus_one_where(self, mask: Self::M, a: Self::I) -> Self::I;
        fn select(self, mask: Self::M, a: Self::I, b: Self::I) -> Self::I;
    }
}
