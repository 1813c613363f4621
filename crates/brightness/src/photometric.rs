//! Every valid pixel's photometric interaction row `L_I = −∇Iᵀ ∂u/∂v`, from the
//! camera's per-pixel factors (the hot loop of the dense features: at 640×480 it reads
//! 48 bytes of factors per pixel).
//!
//! The factors are kept as the two rows `[T_u | R_u]` and `[T_v | R_v]` of each pixel
//! (`T` the translational block times the range, `R` the rotational one;
//! [`ucm::PixelJacobian`]), so that the row of a pixel with gradient `(g_u, g_v)` and
//! inverse range `1/ρ` is, channel by channel, `(g_u F_u + g_v F_v) · S` with
//! `S = (−1/ρ, −1/ρ, −1/ρ, −1, −1, −1)`: the operations of
//! [`ucm::PixelJacobian::photometric`] in the same order (a product commutes and
//! `x · (−1)` is `−x`), hence the same bits. On AVX-512 (found at run time through
//! `pulp`) eight pixels' 48 channels are formed in three registers, the gradients and
//! inverse ranges spread to their channels by permutes (tested against the plain loop).

use ucm::PixelJacobian;

/// A pixel's factors as the rows `[T_u | R_u]` and `[T_v | R_v]`.
pub(crate) fn factor_rows(f: &PixelJacobian) -> ([f32; 6], [f32; 6]) {
    let (t, r) = (&f.translation, &f.rotation);
    (
        [t[0][0], t[0][1], t[0][2], r[0][0], r[0][1], r[0][2]],
        [t[1][0], t[1][1], t[1][2], r[1][0], r[1][1], r[1][2]],
    )
}

/// The pixels of one run: their factors' rows `u` and `v` ([`factor_rows`]), masked
/// gradients and inverse ranges, and their photometric rows (written).
pub(crate) struct Run<'a> {
    pub(crate) u: &'a [[f32; 6]],
    pub(crate) v: &'a [[f32; 6]],
    pub(crate) gradient: &'a [[f32; 2]],
    pub(crate) inverse_range: &'a [f32],
    pub(crate) out: &'a mut [[f32; 6]],
}

impl Run<'_> {
    /// The run's first `n` pixels, and the rest.
    fn split(self, n: usize) -> (Self, Self) {
        let (u, u_rest) = self.u.split_at(n);
        let (v, v_rest) = self.v.split_at(n);
        let (gradient, gradient_rest) = self.gradient.split_at(n);
        let (inverse_range, inverse_range_rest) = self.inverse_range.split_at(n);
        let (out, out_rest) = self.out.split_at_mut(n);
        (
            Run {
                u,
                v,
                gradient,
                inverse_range,
                out,
            },
            Run {
                u: u_rest,
                v: v_rest,
                gradient: gradient_rest,
                inverse_range: inverse_range_rest,
                out: out_rest,
            },
        )
    }
}

/// Write the photometric row of every pixel of `run`.
///
/// # Panics
/// If the run's slices differ in length.
pub(crate) fn rows(run: Run<'_>) {
    let n = run.out.len();
    assert!(
        run.u.len() == n
            && run.v.len() == n
            && run.gradient.len() == n
            && run.inverse_range.len() == n
    );
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = isa::avx512() {
        let (blocks, tail) = run.split(n / avx512::PIXELS * avx512::PIXELS);
        pulp::Simd::vectorize(simd, avx512::Rows { simd, run: blocks });
        scalar(tail);
        return;
    }
    // Elsewhere the plain loop, compiled for AVX2 where the processor has it (the same
    // operations: the same bits).
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        pulp::Simd::vectorize(simd, Plain(run));
        return;
    }
    scalar(run);
}

/// [`scalar`] as a `pulp` kernel (only what is inlined into `with_simd` is compiled for
/// its instruction set).
struct Plain<'a>(Run<'a>);

impl pulp::WithSimd for Plain<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        scalar(self.0);
    }
}

/// The plain loop (the reference of the vector kernel, and its fallback).
#[inline(always)]
fn scalar(run: Run<'_>) {
    let pixels = run
        .out
        .iter_mut()
        .zip(run.u.iter().zip(run.v))
        .zip(run.gradient.iter().zip(run.inverse_range));
    for ((o, (u, v)), (&[gu, gv], &r)) in pixels {
        let s = -r;
        for c in 0..6 {
            let sum = gu * u[c] + gv * v[c];
            o[c] = if c < 3 { sum * s } else { -sum };
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    //! Eight pixels per step: their 48 channels in three registers of sixteen lanes,
    //! lane `j` of register `k` holding channel `(16k + j) mod 6` of pixel
    //! `(16k + j) div 6`.

    use core::arch::x86_64::{__m256, __m512};

    use pulp::x86::V4;

    use super::Run;

    /// Pixels per step.
    pub(super) const PIXELS: usize = 8;

    /// For each register, the lane of the pixel's `g_u` in `[g_u, g_v]` × 8 (add 1 for
    /// `g_v`), its lane among the 8 inverse ranges, and the mask of the translational
    /// channels.
    const fn spread() -> ([[i32; 16]; 3], [[i32; 16]; 3], [u16; 3]) {
        let mut gradient = [[0; 16]; 3];
        let mut range = [[0; 16]; 3];
        let mut translational = [0u16; 3];
        let mut k = 0;
        while k < 3 {
            let mut j = 0;
            while j < 16 {
                let lane = 16 * k + j;
                let (pixel, channel) = (lane / 6, lane % 6);
                gradient[k][j] = 2 * pixel as i32;
                range[k][j] = pixel as i32;
                if channel < 3 {
                    translational[k] |= 1 << j;
                }
                j += 1;
            }
            k += 1;
        }
        (gradient, range, translational)
    }

    /// The arguments of [`super::rows`] (lengths equal multiples of [`PIXELS`]), run
    /// compiled for AVX-512.
    pub(super) struct Rows<'a> {
        pub(super) simd: V4,
        pub(super) run: Run<'a>,
    }

    impl pulp::WithSimd for Rows<'_> {
        type Output = ();

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) {
            self.run();
        }
    }

    impl Rows<'_> {
        #[inline(always)]
        fn run(self) {
            let (gradient_lanes, range_lanes, translational) = const { spread() };
            let f = self.simd.avx512f;
            let minus_one = f._mm512_set1_ps(-1.0);
            let run = self.run;
            let (u, _) = run.u.as_chunks::<PIXELS>();
            let (v, _) = run.v.as_chunks::<PIXELS>();
            let (gradient, _) = run.gradient.as_chunks::<PIXELS>();
            let (inverse_range, _) = run.inverse_range.as_chunks::<PIXELS>();
            let (out, _) = run.out.as_chunks_mut::<PIXELS>();
            let pixels = out
                .iter_mut()
                .zip(u.iter().zip(v))
                .zip(gradient.iter().zip(inverse_range));
            for ((out, (u, v)), (gradient, inverse_range)) in pixels {
                let u: [__m512; 3] = pulp::cast(*u);
                let v: [__m512; 3] = pulp::cast(*v);
                let g: __m512 = pulp::cast(*gradient);
                let r: __m256 = pulp::cast(*inverse_range);
                // −1/ρ of the eight pixels, in the low half.
                let s = f._mm512_mul_ps(f._mm512_castps256_ps512(r), minus_one);
                let mut rows = [f._mm512_setzero_ps(); 3];
                for k in 0..3 {
                    let gu_index = pulp::cast(gradient_lanes[k]);
                    let gv_index = f._mm512_add_epi32(gu_index, f._mm512_set1_epi32(1));
                    let gu = f._mm512_permutexvar_ps(gu_index, g);
                    let gv = f._mm512_permutexvar_ps(gv_index, g);
                    let scale = f._mm512_mask_permutexvar_ps(
                        minus_one,
                        translational[k],
                        pulp::cast(range_lanes[k]),
                        s,
                    );
                    let sum = f._mm512_add_ps(f._mm512_mul_ps(gu, u[k]), f._mm512_mul_ps(gv, v[k]));
                    rows[k] = f._mm512_mul_ps(sum, scale);
                }
                *out = pulp::cast(rows);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn bits(rows: &[[f32; 6]]) -> Vec<u32> {
        rows.as_flattened().iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        /// Every kernel gives the bits of `PixelJacobian::photometric`, pixel by pixel,
        /// for runs of any length (whole steps of eight and a tail), zero inverse
        /// ranges (sky) and gradients of either sign included.
        #[test]
        fn every_kernel_gives_the_bits_of_the_pixel_jacobian(
            pixels in prop::collection::vec(
                (
                    prop::array::uniform12(-500.0f32..500.0),
                    prop::array::uniform2(-2.0f32..2.0),
                    prop_oneof![Just(0.0f32), 0.001f32..2.0],
                ),
                0..40,
            ),
        ) {
            let jacobians: Vec<PixelJacobian> = pixels
                .iter()
                .map(|(f, _, _)| PixelJacobian {
                    translation: [[f[0], f[1], f[2]], [f[3], f[4], f[5]]],
                    rotation: [[f[6], f[7], f[8]], [f[9], f[10], f[11]]],
                })
                .collect();
            let (u, v): (Vec<[f32; 6]>, Vec<[f32; 6]>) = jacobians.iter().map(factor_rows).unzip();
            let gradient: Vec<[f32; 2]> = pixels.iter().map(|p| p.1).collect();
            let inverse_range: Vec<f32> = pixels.iter().map(|p| p.2).collect();
            let expected: Vec<[f32; 6]> = jacobians
                .iter()
                .zip(&gradient)
                .zip(&inverse_range)
                .map(|((j, &g), &r)| j.photometric(g, r))
                .collect();
            let mut out = vec![[f32::NAN; 6]; pixels.len()];
            rows(Run { u: &u, v: &v, gradient: &gradient, inverse_range: &inverse_range, out: &mut out });
            prop_assert_eq!(bits(&out), bits(&expected));
            let mut plain = vec![[f32::NAN; 6]; pixels.len()];
            scalar(Run { u: &u, v: &v, gradient: &gradient, inverse_range: &inverse_range, out: &mut plain });
            prop_assert_eq!(bits(&plain), bits(&expected));
        }
    }
}
