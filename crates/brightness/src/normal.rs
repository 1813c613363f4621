//! Normal equations of a dense least-squares problem, without materialising `J`.
//!
//! The sums are accumulated in `f32` over blocks of [`BLOCK`] rows, then in `f64`: the
//! blocks keep the inner loop fast, the `f64` sums keep the precision of long sums.
//! On AVX-512 (found at run time through `pulp`) one row's products of the upper
//! triangle of `JᵀJ` and of `Jᵀe` are formed together, sixteen per instruction (each
//! sum in its own lane, the rows added in order); on AVX2, eight per instruction (rows
//! of at most eight columns): the same operations in the same order as the plain
//! loop, hence the same bits (tested).

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
    run(Plain(rows), residuals, weights)
}

/// [`normal_equations`] of the rows `[j[k] | column[k]]` (`M = N + 1` columns: the
/// rows of a feature and one more column, such as the PGM's `J_λ`), without copying
/// them into rows of `M`: the same bits as [`normal_equations`]`::<M>` of the joined
/// rows (tested).
///
/// # Panics
/// If `M ≠ N + 1` or the slices differ in length (callers check).
pub fn normal_equations_with_column<const N: usize, const M: usize>(
    rows: &[[f32; N]],
    column: &[f32],
    residuals: &[f32],
    weights: Option<&[f32]>,
) -> ([[f64; M]; M], [f64; M]) {
    assert_eq!(M, N + 1, "one more column");
    assert_eq!(column.len(), rows.len());
    run(WithColumn { rows, column }, residuals, weights)
}

/// Where the rows of `M` columns come from.
trait Rows<const M: usize>: Copy {
    /// Number of rows.
    fn len(&self) -> usize;

    /// Row `k`.
    fn row(&self, k: usize) -> [f32; M];

    /// Row `k` in the first `M` lanes of a vector (anything beyond).
    #[cfg(target_arch = "x86_64")]
    fn lanes(&self, simd: pulp::x86::V4, k: usize) -> core::arch::x86_64::__m512;

    /// Row `k` in the first `M` lanes of an AVX2 vector (`M ≤ 8`; anything beyond).
    #[cfg(target_arch = "x86_64")]
    fn lanes8(&self, simd: pulp::x86::V3, k: usize) -> core::arch::x86_64::__m256;
}

/// Rows as they are.
#[derive(Clone, Copy)]
struct Plain<'a, const M: usize>(&'a [[f32; M]]);

impl<const M: usize> Rows<M> for Plain<'_, M> {
    #[inline(always)]
    fn len(&self) -> usize {
        self.0.len()
    }

    #[inline(always)]
    fn row(&self, k: usize) -> [f32; M] {
        self.0[k]
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn lanes(&self, _: pulp::x86::V4, k: usize) -> core::arch::x86_64::__m512 {
        // The row then the next rows' values, or the last rows padded.
        match self.0.as_flattened().get(k * M..k * M + 16) {
            Some(s) => pulp::cast(*<&[f32; 16]>::try_from(s).expect("16")),
            None => {
                let mut padded = [0.0f32; 16];
                padded[..M].copy_from_slice(&self.0[k]);
                pulp::cast(padded)
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn lanes8(&self, _: pulp::x86::V3, k: usize) -> core::arch::x86_64::__m256 {
        match self.0.as_flattened().get(k * M..k * M + 8) {
            Some(s) => pulp::cast(*<&[f32; 8]>::try_from(s).expect("8")),
            None => {
                let mut padded = [0.0f32; 8];
                padded[..M].copy_from_slice(&self.0[k]);
                pulp::cast(padded)
            }
        }
    }
}

/// Rows of `M − 1` columns and one more column.
#[derive(Clone, Copy)]
struct WithColumn<'a, const N: usize> {
    rows: &'a [[f32; N]],
    column: &'a [f32],
}

impl<const N: usize, const M: usize> Rows<M> for WithColumn<'_, N> {
    #[inline(always)]
    fn len(&self) -> usize {
        self.rows.len()
    }

    #[inline(always)]
    fn row(&self, k: usize) -> [f32; M] {
        std::array::from_fn(|c| {
            if c < N {
                self.rows[k][c]
            } else {
                self.column[k]
            }
        })
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn lanes(&self, simd: pulp::x86::V4, k: usize) -> core::arch::x86_64::__m512 {
        let row: core::arch::x86_64::__m512 = Plain(self.rows).lanes(simd, k);
        let f = simd.avx512f;
        f._mm512_mask_blend_ps(1 << N, row, f._mm512_set1_ps(self.column[k]))
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn lanes8(&self, simd: pulp::x86::V3, k: usize) -> core::arch::x86_64::__m256 {
        let row: core::arch::x86_64::__m256 = Plain(self.rows).lanes8(simd, k);
        let column = simd.avx._mm256_set1_ps(self.column[k]);
        // Lane N from the column: a blend's mask is a constant, so it is chosen by N.
        match N {
            0 => simd.avx._mm256_blend_ps::<0b0000_0001>(row, column),
            1 => simd.avx._mm256_blend_ps::<0b0000_0010>(row, column),
            2 => simd.avx._mm256_blend_ps::<0b0000_0100>(row, column),
            3 => simd.avx._mm256_blend_ps::<0b0000_1000>(row, column),
            4 => simd.avx._mm256_blend_ps::<0b0001_0000>(row, column),
            5 => simd.avx._mm256_blend_ps::<0b0010_0000>(row, column),
            6 => simd.avx._mm256_blend_ps::<0b0100_0000>(row, column),
            _ => simd.avx._mm256_blend_ps::<0b1000_0000>(row, column),
        }
    }
}

/// [`normal_equations`] of any rows: the AVX-512 kernel where the processor has it, else
/// the AVX2 one (rows of at most eight columns), else the plain loops.
fn run<const M: usize>(
    rows: impl Rows<M>,
    residuals: &[f32],
    weights: Option<&[f32]>,
) -> ([[f64; M]; M], [f64; M]) {
    assert_eq!(rows.len(), residuals.len());
    if let Some(w) = weights {
        assert_eq!(w.len(), rows.len());
    }
    #[cfg(target_arch = "x86_64")]
    {
        if M <= avx512::MAX_COLUMNS
            && let Some(simd) = isa::avx512()
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
        if M <= avx2::MAX_COLUMNS
            && let Some(simd) = pulp::x86::V3::try_new()
        {
            return pulp::Simd::vectorize(
                simd,
                avx2::Normal {
                    simd,
                    rows,
                    residuals,
                    weights,
                },
            );
        }
    }
    scalar(rows, residuals, weights)
}

/// The plain loops (the reference of the vector kernel, and its fallback).
fn scalar<const N: usize>(
    rows: impl Rows<N>,
    residuals: &[f32],
    weights: Option<&[f32]>,
) -> ([[f64; N]; N], [f64; N]) {
    let mut sums = Sums::<N>::default();
    let m = rows.len();
    for b in 0..m.div_ceil(BLOCK) {
        let mut block = [[0.0f32; N]; N];
        let mut block_e = [0.0f32; N];
        for index in b * BLOCK..((b + 1) * BLOCK).min(m) {
            let row = rows.row(index);
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

    use super::{BLOCK, Rows, Sums};

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
    pub(super) struct Normal<'a, R, const N: usize> {
        pub(super) simd: V4,
        pub(super) rows: R,
        pub(super) residuals: &'a [f32],
        pub(super) weights: Option<&'a [f32]>,
    }

    impl<const N: usize, R: Rows<N>> pulp::WithSimd for Normal<'_, R, N> {
        type Output = ([[f64; N]; N], [f64; N]);

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
            self.run()
        }
    }

    impl<const N: usize, R: Rows<N>> Normal<'_, R, N> {
        #[inline(always)]
        fn run(self) -> ([[f64; N]; N], [f64; N]) {
            let lanes = const { lanes(N) };
            let vectors = lanes.count.div_ceil(16);
            let f = self.simd.avx512f;
            let mut sums = Sums::<N>::default();
            let m = self.rows.len();
            for b in 0..m.div_ceil(BLOCK) {
                let mut acc = [f._mm512_setzero_ps(); VECTORS];
                for k in b * BLOCK..((b + 1) * BLOCK).min(m) {
                    let w = self.weights.map_or(1.0, |w| w[k]);
                    if w == 0.0 {
                        continue;
                    }
                    let e = self.residuals[k] * w;
                    // The row in the first N lanes.
                    let row: __m512 = self.rows.lanes(self.simd, k);
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

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! The AVX2 kernel: per row, lane `p` of the first vectors holds one product
    //! `(r, c)`, `r ≤ c`, of `JᵀJ` (its factors permuted from `w·row` and `row`), and
    //! lane `r` of the last one the product `r` of `Jᵀe` (`row · e`).

    use pulp::x86::V3;

    use super::{BLOCK, Rows, Sums};

    /// Vectors of `JᵀJ` sums.
    const VECTORS: usize = 5;

    /// The widest rows handled: a row in one vector, `N (N + 1)/2` sums in
    /// `8 · VECTORS` lanes.
    pub(super) const MAX_COLUMNS: usize = 8;

    /// Which product each lane of the `JᵀJ` vectors sums: the permute indices of its
    /// factors (`x` from `w·row`, `y` from `row`), and where its sum goes.
    struct Lanes {
        x: [[i32; 8]; VECTORS],
        y: [[i32; 8]; VECTORS],
        target: [(usize, usize); 8 * VECTORS],
        count: usize,
    }

    /// The lanes of rows of `n` columns (none beyond `MAX_COLUMNS`: wider rows never
    /// run here, but every width is compiled).
    const fn lanes(n: usize) -> Lanes {
        let mut l = Lanes {
            x: [[0; 8]; VECTORS],
            y: [[0; 8]; VECTORS],
            target: [(0, 0); 8 * VECTORS],
            count: 0,
        };
        if n > MAX_COLUMNS {
            return l;
        }
        let mut r = 0;
        while r < n {
            let mut c = r;
            while c < n {
                // block[r][c] += (row[r] · w) · row[c]
                let p = l.count;
                l.x[p / 8][p % 8] = r as i32;
                l.y[p / 8][p % 8] = c as i32;
                l.target[p] = (r, c);
                l.count += 1;
                c += 1;
            }
            r += 1;
        }
        l
    }

    /// The arguments of [`super::normal_equations`], run compiled for AVX2.
    pub(super) struct Normal<'a, R, const N: usize> {
        pub(super) simd: V3,
        pub(super) rows: R,
        pub(super) residuals: &'a [f32],
        pub(super) weights: Option<&'a [f32]>,
    }

    impl<const N: usize, R: Rows<N>> pulp::WithSimd for Normal<'_, R, N> {
        type Output = ([[f64; N]; N], [f64; N]);

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
            self.run()
        }
    }

    impl<const N: usize, R: Rows<N>> Normal<'_, R, N> {
        #[inline(always)]
        fn run(self) -> ([[f64; N]; N], [f64; N]) {
            let lanes = const { lanes(N) };
            let vectors = lanes.count.div_ceil(8);
            let (avx, avx2) = (self.simd.avx, self.simd.avx2);
            let mut sums = Sums::<N>::default();
            let m = self.rows.len();
            for b in 0..m.div_ceil(BLOCK) {
                let mut acc = [avx._mm256_setzero_ps(); VECTORS];
                let mut acc_e = avx._mm256_setzero_ps();
                for k in b * BLOCK..((b + 1) * BLOCK).min(m) {
                    let w = self.weights.map_or(1.0, |w| w[k]);
                    if w == 0.0 {
                        continue;
                    }
                    let e = self.residuals[k] * w;
                    // The row in the first N lanes.
                    let row = self.rows.lanes8(self.simd, k);
                    let weighted = avx._mm256_mul_ps(row, avx._mm256_set1_ps(w));
                    for (v, acc) in acc.iter_mut().enumerate().take(vectors) {
                        let x = avx2._mm256_permutevar8x32_ps(weighted, pulp::cast(lanes.x[v]));
                        let y = avx2._mm256_permutevar8x32_ps(row, pulp::cast(lanes.y[v]));
                        *acc = avx._mm256_add_ps(*acc, avx._mm256_mul_ps(x, y));
                    }
                    acc_e = avx._mm256_add_ps(acc_e, avx._mm256_mul_ps(row, avx._mm256_set1_ps(e)));
                }
                let all: [[f32; 8]; VECTORS] = pulp::cast(acc);
                let all = all.as_flattened();
                let mut block = [[0.0f32; N]; N];
                for (&sum, &(r, c)) in all.iter().zip(&lanes.target[..lanes.count]) {
                    block[r][c] = sum;
                }
                let e: [f32; 8] = pulp::cast(acc_e);
                let block_e: [f32; N] = std::array::from_fn(|r| e[r]);
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
            let reference = scalar::<N>(Plain(&rows), &residuals, weights);
            assert_eq!(bits(fast), bits(reference), "N = {N}, {m} rows");
        }
    }

    proptest! {
        /// The widest kernel of the processor gives the bits of the plain loops,
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

        /// Rows and one more column give the bits of the joined rows, on the kernel of
        /// the processor and in the plain loops.
        #[test]
        fn one_more_column_gives_the_bits_of_the_joined_rows(
            values in prop::collection::vec(-1e3f32..1e3, 0..4800),
            weights in prop::collection::vec(
                prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..2.0], 600),
        ) {
            let m = values.len() / 8;
            let rows: Vec<[f32; 6]> =
                (0..m).map(|k| std::array::from_fn(|c| values[8 * k + c])).collect();
            let column: Vec<f32> = (0..m).map(|k| values[8 * k + 6]).collect();
            let residuals: Vec<f32> = (0..m).map(|k| values[8 * k + 7]).collect();
            let joined: Vec<[f32; 7]> = (0..m)
                .map(|k| std::array::from_fn(|c| if c < 6 { rows[k][c] } else { column[k] }))
                .collect();
            for weights in [None, Some(&weights[..m])] {
                let expected = bits(normal_equations::<7>(&joined, &residuals, weights));
                let got = normal_equations_with_column::<6, 7>(&rows, &column, &residuals, weights);
                prop_assert_eq!(bits(got), expected.clone());
                let plain = scalar::<7>(WithColumn { rows: &rows, column: &column }, &residuals, weights);
                prop_assert_eq!(bits(plain), expected.clone());
                if let Some(got) = on_avx2::<7>(WithColumn { rows: &rows, column: &column }, &residuals, weights) {
                    prop_assert_eq!(bits(got), expected);
                }
            }
        }

        /// The AVX2 kernel (where the processor has it, whatever the widest one) gives
        /// the bits of the plain loops, for every width it takes, with dropped rows.
        #[test]
        fn the_avx2_kernel_gives_the_bits_of_the_plain_loops(
            values in prop::collection::vec(-1e3f32..1e3, 0..5400),
            weights in prop::collection::vec(
                prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..2.0], 600),
        ) {
            fn check<const N: usize>(values: &[f32], weights: &[f32]) -> Result<(), TestCaseError> {
                let m = values.len() / (N + 1);
                let rows: Vec<[f32; N]> = (0..m)
                    .map(|k| std::array::from_fn(|c| values[k * (N + 1) + c]))
                    .collect();
                let residuals: Vec<f32> = (0..m).map(|k| values[k * (N + 1) + N]).collect();
                for weights in [None, Some(&weights[..m])] {
                    let reference = scalar::<N>(Plain(&rows), &residuals, weights);
                    if let Some(got) = on_avx2(Plain(&rows), &residuals, weights) {
                        prop_assert_eq!(bits(got), bits(reference), "N = {}", N);
                    }
                }
                Ok(())
            }
            check::<1>(&values[..values.len().min(2 * 600)], &weights)?;
            check::<2>(&values[..values.len().min(3 * 600)], &weights)?;
            check::<6>(&values[..values.len().min(7 * 600)], &weights)?;
            check::<7>(&values[..values.len().min(8 * 600)], &weights)?;
            check::<8>(&values[..values.len().min(9 * 600)], &weights)?;
        }
    }

    /// The AVX2 kernel's sums, if the processor has AVX2.
    fn on_avx2<const N: usize>(
        rows: impl Rows<N>,
        residuals: &[f32],
        weights: Option<&[f32]>,
    ) -> Option<([[f64; N]; N], [f64; N])> {
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = pulp::x86::V3::try_new() {
            return Some(pulp::Simd::vectorize(
                simd,
                avx2::Normal {
                    simd,
                    rows,
                    residuals,
                    weights,
                },
            ));
        }
        let _ = (rows, residuals, weights);
        None
    }
}
