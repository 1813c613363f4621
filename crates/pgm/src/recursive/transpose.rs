//! Transposes of a window of a plane, for the passes along rows: the caller transposes
//! a plane, filters its columns and transposes it back.

use super::Window;

/// [`transpose`] of `f32` planes: on AVX-512, blocks of 16 × 16 elements transposed
/// in registers (sixteen rows loaded whole, 64 shuffles, sixteen columns stored
/// whole), the window's last rows and columns as [`transpose`] does them; elsewhere
/// [`transpose`]. The same elements moved (tested). Panics if the window is outside
/// the `width × height` planes, or a plane holds fewer than `width × height` elements.
pub fn transpose_f32(src: &[f32], dst: &mut [f32], width: usize, height: usize, window: Window) {
    let ([c0, c1], [r0, r1]) = (window.columns, window.rows);
    assert!(
        c0 <= c1 && c1 <= width && r0 <= r1 && r1 <= height,
        "window {window:?} outside a {width} × {height} plane"
    );
    assert!(
        src.len() >= width * height && dst.len() >= width * height,
        "planes of {} and {} elements for {width} × {height}",
        src.len(),
        dst.len()
    );
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = isa::avx512() {
        // Whole blocks from the window's first row and column.
        let (c_end, r_end) = (c0 + (c1 - c0) / 16 * 16, r0 + (r1 - r0) / 16 * 16);
        pulp::Simd::vectorize(
            simd,
            Blocks16 {
                simd,
                src,
                dst: &mut *dst,
                width,
                height,
                blocks: ([c0, c_end], [r0, r_end]),
            },
        );
        let right = Window {
            columns: [c_end, c1],
            rows: [r0, r1],
        };
        let below = Window {
            columns: [c0, c_end],
            rows: [r_end, r1],
        };
        transpose(src, dst, width, height, right);
        transpose(src, dst, width, height, below);
        return;
    }
    transpose(src, dst, width, height, window);
}

/// The whole 16 × 16 blocks of [`transpose_f32`] on AVX-512.
#[cfg(target_arch = "x86_64")]
struct Blocks16<'a> {
    simd: pulp::x86::V4,
    src: &'a [f32],
    dst: &'a mut [f32],
    width: usize,
    height: usize,
    /// Columns and rows, multiples of 16 apart.
    blocks: ([usize; 2], [usize; 2]),
}

#[cfg(target_arch = "x86_64")]
impl pulp::WithSimd for Blocks16<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Self {
            simd,
            src,
            dst,
            width,
            height,
            blocks: ([c0, c1], [r0, r1]),
        } = self;
        let f = simd.avx512f;
        let zero = f._mm512_setzero_ps();
        for y0 in (r0..r1).step_by(16) {
            for x0 in (c0..c1).step_by(16) {
                // Loops over registers, not closures: a closure the compiler does not
                // inline is compiled without the instruction set.
                let mut rows = [zero; 16];
                for (i, row) in rows.iter_mut().enumerate() {
                    let at = (y0 + i) * width + x0;
                    *row = pulp::cast(*<&[f32; 16]>::try_from(&src[at..at + 16]).expect("16"));
                }
                // Pairs, then quads of rows within each 128-bit lane: `quads[4 g + j]`
                // holds, in lane `L`, column `4 L + j` of rows `4 g .. 4 g + 4`.
                let mut pairs = [zero; 16];
                for k in (0..16).step_by(2) {
                    pairs[k] = f._mm512_unpacklo_ps(rows[k], rows[k + 1]);
                    pairs[k + 1] = f._mm512_unpackhi_ps(rows[k], rows[k + 1]);
                }
                let mut quads = [zero; 16];
                for g in 0..4 {
                    for half in 0..2 {
                        let a = f._mm512_castps_pd(pairs[4 * g + half]);
                        let b = f._mm512_castps_pd(pairs[4 * g + 2 + half]);
                        quads[4 * g + 2 * half] = f._mm512_castpd_ps(f._mm512_unpacklo_pd(a, b));
                        quads[4 * g + 2 * half + 1] =
                            f._mm512_castpd_ps(f._mm512_unpackhi_pd(a, b));
                    }
                }
                // Lanes across the four groups of rows: column `4 L + j` is lane `L`
                // of `quads[j]`, `quads[4 + j]`, `quads[8 + j]`, `quads[12 + j]`.
                for j in 0..4 {
                    let (g0, g1, g2, g3) = (quads[j], quads[4 + j], quads[8 + j], quads[12 + j]);
                    let even01 = f._mm512_shuffle_f32x4::<0x88>(g0, g1);
                    let odd01 = f._mm512_shuffle_f32x4::<0xDD>(g0, g1);
                    let even23 = f._mm512_shuffle_f32x4::<0x88>(g2, g3);
                    let odd23 = f._mm512_shuffle_f32x4::<0xDD>(g2, g3);
                    let columns = [
                        f._mm512_shuffle_f32x4::<0x88>(even01, even23),
                        f._mm512_shuffle_f32x4::<0x88>(odd01, odd23),
                        f._mm512_shuffle_f32x4::<0xDD>(even01, even23),
                        f._mm512_shuffle_f32x4::<0xDD>(odd01, odd23),
                    ];
                    for (l, column) in columns.into_iter().enumerate() {
                        let at = (x0 + 4 * l + j) * height + y0;
                        *<&mut [f32; 16]>::try_from(&mut dst[at..at + 16]).expect("16") =
                            pulp::cast(column);
                    }
                }
            }
        }
    }
}

/// `dst[x · height + y] = src[y · width + x]` for the pixels `(x, y)` of `window`
/// (columns and rows of `src`), in blocks of 8 × 8 elements; `dst` is left as it was
/// elsewhere. Panics if the window is outside the `width × height` planes.
pub fn transpose<T: Copy>(src: &[T], dst: &mut [T], width: usize, height: usize, window: Window) {
    const B: usize = 8;
    let ([c0, c1], [r0, r1]) = (window.columns, window.rows);
    assert!(
        c0 <= c1 && c1 <= width && r0 <= r1 && r1 <= height,
        "window {window:?} outside a {width} × {height} plane"
    );
    for y0 in (r0..r1).step_by(B) {
        let y1 = (y0 + B).min(r1);
        for x0 in (c0..c1).step_by(B) {
            for x in x0..(x0 + B).min(c1) {
                let out = &mut dst[x * height + y0..x * height + y1];
                for (o, y) in out.iter_mut().zip(y0..y1) {
                    *o = src[y * width + x];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The register transpose against [`transpose`], windows of every size around
    /// whole blocks, in planes of a few shapes. (Without AVX-512, `transpose_f32` is
    /// `transpose` and the test only checks that.)
    #[test]
    fn blocked_f32_transpose_is_the_plain_one() {
        for (w, h) in [(40usize, 37usize), (33, 50), (16, 16), (70, 49), (5, 70)] {
            let src: Vec<f32> = (0..w * h).map(|k| k as f32).collect();
            for (c0, c1, r0, r1) in [(0, w, 0, h), (1, w - 2, 3, h), (2, w, 0, h - 1)] {
                let window = Window {
                    columns: [c0, c1],
                    rows: [r0, r1],
                };
                let mut want = vec![-1.0; w * h];
                let mut got = vec![-1.0; w * h];
                transpose(&src, &mut want, w, h, window);
                transpose_f32(&src, &mut got, w, h, window);
                assert_eq!(got, want, "{w} × {h}, {window:?}");
            }
        }
    }

    #[test]
    fn transpose_moves_every_element_of_the_window() {
        let (w, h) = (13, 10);
        let src: Vec<u32> = (0..w * h).collect();
        let mut dst = vec![0; (w * h) as usize];
        transpose(
            &src,
            &mut dst,
            w as usize,
            h as usize,
            Window::whole(13, 10),
        );
        for y in 0..h {
            for x in 0..w {
                assert_eq!(dst[(x * h + y) as usize], y * w + x);
            }
        }
        let window = Window {
            columns: [2, 11],
            rows: [1, 10],
        };
        let mut dst = vec![u32::MAX; (w * h) as usize];
        transpose(&src, &mut dst, w as usize, h as usize, window);
        for y in 0..h {
            for x in 0..w {
                let inside = (1..10).contains(&y) && (2..11).contains(&x);
                let want = if inside { y * w + x } else { u32::MAX };
                assert_eq!(dst[(x * h + y) as usize], want);
            }
        }
    }
}
