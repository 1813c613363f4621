//! Normal equations of a dense least-squares problem, without materialising `J`.
//!
//! The sums are accumulated in `f32` over blocks of [`BLOCK`] rows, then in `f64`: the
//! blocks keep the inner loop fast, the `f64` sums keep the precision of long sums.
//! On AVX-512 (found at run time through `pulp`) one row's products of the upper
//! triangle of `JᵀJ` and of `Jᵀe` are formed together, sixteen per instruction (each
//! sum in its own lane, the rows added in order): the same operations in the same
//! order as the plain loop, hence the same bits (tested).

/// Rows summed in `f32` before their sums are added in `f64`.
const BLOCK: usize = 256;

/// `(JᵀJ, Jᵀe)` of the rows `j[k]` (N columns each) and residuals `e[k]`, optionally
/// weighted (`w[k]`, e.g. 0 to drop a sample), accumulated in `f64`.
///
/// # Panics
/// If the slices differ in length (callers check).
pub fn normal_equations<const N: usize>(
    rows: &[[f32; N]],
    residuals: &[f32],
    weights: Option<&[f32]>,
) -> ([[f64; N]; N], [f64; N]) {
    assert_eq!(rows.len(), residuals.len());
    if let Some(w) = weights {
        assert_eq!(w.len(), rows.len());
    }
    #[cfg(target_arch = "x86_64")]
    if N <= avx512::MAX_COLUMNS
        && let Some(simd) = pulp::x86::V4::try_new()
    {
        return pulp::Simd::vectorize(
            simd,
            avx512::Normal {
                simd,
                rows,
                residuals,
                weights,
            },
        );
    }
    scalar(rows, residuals, weights)
}

/// The plain loops (the reference of the vector kernel, and its fallback).
fn scalar<const N: usize>(
    rows: &[[f32; N]],
    residuals: &[f32],
    weights: Option<&[f32]>,
) -> ([[f64; N]; N], [f64; N]) {
    let mut sums = Sums::<N>::default();
    for (b, chunk) in rows.chunks(BLOCK).enumerate() {
        let mut block = [[0.0f32; N]; N];
        let mut block_e = [0.0f32; N];
        for (k, row) in chunk.iter().enumerate() {
            let index = b * BLOCK + k;
            let w = weights.map_or(1.0, |w| w[index]);
            if w == 0.0 {
                continue;
            }
            let e = residuals[index] * w;
            for r in 0..N {
                let wr = row[r] * w;
                block_e[r] += row[r] * e;
                for c in r..N {
                    block[r][c] += wr * row[c];
                }
            }
        }
        sums.add_block(&block, &block_e);
    }
    sums.finish()
}

/// The `f64` sums of the blocks.
struct Sums<const N: usize> {
    jtj: [[f64; N]; N],
    jte: [f64; N],
}

impl<const N: usize> Default for Sums<N> {
    fn default() -> Self {
        Self {
            jtj: [[0.0; N]; N],
            jte: [0.0; N],
        }
    }
}

impl<const N: usize> Sums<N> {
    /// Add a block's `f32` sums (upper triangle of `block`).
    #[inline(always)]
    fn add_block(&mut self, block: &[[f32; N]; N], block_e: &[f32; N]) {
        for r in 0..N {
            self.jte[r] += f64::from(block_e[r]);
            for c in r..N {
                self.jtj[r][c] += f64::from(block[r][c]);
            }
        }
    }

    /// The sums, `JᵀJ` made symmetric.
    fn finish(mut self) -> ([[f64; N]; N], [f64; N]) {
        for r in 0..N {
            for c in 0..r {
                self.jtj[r][c] = self.jtj[c][r];
            }
        }
        (self.jtj, self.jte)
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    //! The AVX-512 kernel: per row, lane `p` of four vectors holds one sum, the
    //! products `(r, c)`, `r ≤ c`, of `JᵀJ` then the products `r` of `Jᵀe`.

    use core::arch::x86_64::__m512;

    use pulp::x86::V4;

    use super::{BLOCK, Sums};

    /// Vectors of sums.
    const VECTORS: usize = 4;

    /// The widest rows handled: `N (N + 1)/2 + N` sums in `16 · VECTORS` lanes.
    pub(super) const MAX_COLUMNS: usize = 9;

    /// Which product each lane sums: two-source permute indices of its factors
    /// (`x` from `[w·row | row]`, `y` from `[row | e]`), and where its sum goes.
    struct Lanes {
        x: [[i32; 16]; VECTORS],
        y: [[i32; 16]; VECTORS],
        /// `(r, c)` of a `JᵀJ` sum, `(r, N)` of a `Jᵀe` sum, per lane in use.
        target: [(usize, usize); 16 * VECTORS],
        count: usize,
    }

    /// The lanes of rows of `n` columns (`n ≤ MAX_COLUMNS`).
    const fn lanes(n: usize) -> Lanes {
        let mut l = Lanes {
            x: [[0; 16]; VECTORS],
            y: [[0; 16]; VECTORS],
            target: [(0, 0); 16 * VECTORS],
            count: 0,
        };
        let mut r = 0;
        while r < n {
            let mut c = r;
            while c < n {
                // block[r][c] += (row[r] · w) · row[c]
                let p = l.count;
                l.x[p / 16][p % 16] = r as i32;
                l.y[p / 16][p % 16] = c as i32;
                l.target[p] = (r, c);
                l.count += 1;
                c += 1;
            }
            r += 1;
        }
        let mut r = 0;
        while r < n {
            // block_e[r] += row[r] · e
            let p = l.count;
            l.x[p / 16][p % 16] = 16 + r as i32;
            l.y[p / 16][p % 16] = 16;
            l.target[p] = (r, n);
            l.count += 1;
            r += 1;
        }
        l
    }

    /// The arguments of [`super::normal_equations`], run compiled for AVX-512.
    pub(super) struct Normal<'a, const N: usize> {
        pub(super) simd: V4,
        pub(super) rows: &'a [[f32; N]],
        pub(super) residuals: &'a [f32],
        pub(super) weights: Option<&'a [f32]>,
    }

    impl<const N: usize> pulp::WithSimd for Normal<'_, N> {
        type Output = ([[f64; N]; N], [f64; N]);

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
            self.run()
        }
    }

    impl<const N: usize> Normal<'_, N> {
        #[inline(always)]
        fn run(self) -> ([[f64; N]; N], [f64; N]) {
            let lanes = const { lanes(N) };
            let vectors = lanes.count.div_ceil(16);
            let f = self.simd.avx512f;
            let flat = self.rows.as_flattened();
            let mut sums = Sums::<N>::default();
            for (b, chunk) in self.rows.chunks(BLOCK).enumerate() {
                let mut acc = [f._mm512_setzero_ps(); VECTORS];
                for k in b * BLOCK..b * BLOCK + chunk.len() {
                    let w = self.weights.map_or(1.0, |w| w[k]);
                    if w == 0.0 {
                        continue;
                    }
                    let e = self.residuals[k] * w;
                    // The row in the first N lanes (the next rows' values beyond).
                    let row: __m512 = match flat.get(k * N..k * N + 16) {
                        Some(s) => pulp::cast(*<&[f32; 16]>::try_from(s).expect("16")),
                        None => {
                            let mut padded = [0.0f32; 16];
                            padded[..N].copy_from_slice(&self.rows[k]);
                            pulp::cast(padded)
                        }
                    };
                    let weighted = f._mm512_mul_ps(row, f._mm512_set1_ps(w));
                    let e = f._mm512_set1_ps(e);
                    for (v, acc) in acc.iter_mut().enumerate().take(vectors) {
                        let x = f._mm512_permutex2var_ps(weighted, pulp::cast(lanes.x[v]), row);
                        let y = f._mm512_permutex2var_ps(row, pulp::cast(lanes.y[v]), e);
                        *acc = f._mm512_add_ps(*acc, f._mm512_mul_ps(x, y));
                    }
                }
                let all: [[f32; 16]; VECTORS] = pulp::cast(acc);
                let all = all.as_flattened();
                let mut block = [[0.0f32; N]; N];
                let mut block_e = [0.0f32; N];
                for (&sum, &(r, c)) in all.iter().zip(&lanes.target[..lanes.count]) {
                    if c == N {
                        block_e[r] = sum;
                    } else {
                        block[r][c] = sum;
                    }
                }
                sums.add_block(&block, &block_e);
            }
            sums.finish()
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn bits<const N: usize>(s: ([[f64; N]; N], [f64; N])) -> Vec<u64> {
        s.0.as_flattened()
            .iter()
            .chain(&s.1)
            .map(|x| x.to_bits())
            .collect()
    }

    fn same_bits<const N: usize>(values: &[f32], weights: &[f32]) {
        let m = values.len() / (N + 1);
        let rows: Vec<[f32; N]> = (0..m)
            .map(|k| std::array::from_fn(|c| values[k * (N + 1) + c]))
            .collect();
        let residuals: Vec<f32> = (0..m).map(|k| values[k * (N + 1) + N]).collect();
        let w = &weights[..m];
        for weights in [None, Some(w)] {
            let fast = normal_equations::<N>(&rows, &residuals, weights);
            let reference = scalar::<N>(&rows, &residuals, weights);
            assert_eq!(bits(fast), bits(reference), "N = {N}, {m} rows");
        }
    }

    proptest! {
        /// The kernel of the processor (AVX-512 here) gives the bits of the plain loops,
        /// for the widths the servo uses, over several blocks, with dropped rows.
        #[test]
        fn every_kernel_gives_the_bits_of_the_plain_loops(
            values in prop::collection::vec(-1e3f32..1e3, 0..6000),
            weights in prop::collection::vec(
                prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..2.0], 600),
        ) {
            same_bits::<6>(&values[..values.len().min(7 * 600)], &weights);
            same_bits::<7>(&values[..values.len().min(8 * 600)], &weights);
            same_bits::<9>(&values[..values.len().min(10 * 600)], &weights);
            same_bits::<2>(&values[..values.len().min(3 * 600)], &weights);
        }
    }
}
