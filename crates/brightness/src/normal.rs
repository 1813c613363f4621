//! Normal equations of a dense least-squares problem, without materialising `J`.

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
    // Accumulate the upper triangle in f32 blocks of 256 rows, then in f64: the blocks
    // keep the inner loop vectorisable, the f64 sums keep the precision of long sums.
    let mut jtj = [[0.0f64; N]; N];
    let mut jte = [0.0f64; N];
    for (b, chunk) in rows.chunks(256).enumerate() {
        let mut block = [[0.0f32; N]; N];
        let mut block_e = [0.0f32; N];
        for (k, row) in chunk.iter().enumerate() {
            let index = b * 256 + k;
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
        for r in 0..N {
            jte[r] += f64::from(block_e[r]);
            for c in r..N {
                jtj[r][c] += f64::from(block[r][c]);
            }
        }
    }
    for r in 0..N {
        for c in 0..r {
            jtj[r][c] = jtj[c][r];
        }
    }
    (jtj, jte)
}
