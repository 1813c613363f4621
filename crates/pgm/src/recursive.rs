//! Recursive (IIR) Gaussian correlations whose cost does not depend on λ.
//!
//! A 1-D kernel `K(k)`, `k = −∞..∞`, symmetric (`K(−k) = K(k)`: `g`, `k² g`) or
//! antisymmetric (`K(−k) = −K(k)`: `(k/λ²) g`), is split into its centre tap `K(0)`
//! and its right half `f(k) = K(k)`, `k ≥ 1`, which is approximated by a sum of three
//! damped oscillations, `f(k) ≈ Σᵢ e^{−bᵢ k/λ} (cᵢ cos(ωᵢ k/λ) + sᵢ sin(ωᵢ k/λ))`, the
//! form of Deriche's recursive filters (R. Deriche, *Recursively implementing the
//! Gaussian and its derivatives*, INRIA RR-1893, 1993) with one more section. The
//! poles `(bᵢ, ωᵢ)` are ours (`POLES`: fitted once from Deriche's); the six weights
//! `(cᵢ, sᵢ)` are fitted here, for each λ, to the sampled kernel by linear least
//! squares (in `f64`), which also fixes the gain exactly.
//!
//! The correlation `out[x] = Σ_k K(k) in[x + k]` is then
//! `K(0) in[x] + a[x] + σ c[x]`, with `σ = ±1` the kernel's symmetry,
//! `a[x] = Σ_{k≥1} f(k) in[x + k]` (anticausal) and `c[x] = Σ_{k≥1} f(k) in[x − k]`
//! (causal): three second-order sections each way, 12 multiply-adds per pixel and
//! direction, whatever λ. Both start from zero states at the ends of the line, which is
//! exactly the zero padding of [`crate::convolve`]; unlike those truncated kernels the
//! recursive ones have no truncation (their tail decays like `e^{−1.77 k/λ}` at worst).
//!
//! Accuracy (tested in `impulse_responses_match_the_kernels`, λ ∈ [1, 40]): the impulse
//! response differs from the sampled kernel by at most 2.5e-6 (`g`), 8.1e-5 (`k² g`)
//! and 2.0e-5 (`(k/λ²) g`) of the kernel's peak for λ ≤ 15, 2.2e-4 at worst at
//! λ = 40; for comparison the exact correlation truncated at 4λ drops tails of 3.4e-4
//! of the peak.
//!
//! Passes run down the columns of a row-major plane, a block of vectors of columns at
//! a time (two on AVX-512, one on AVX2 and SSE4.2) whose recursion state stays in
//! registers from the first row to the last (interleaved channels are filtered
//! together); the caller transposes the plane to filter along its rows. The first
//! sweep asks for its rows 32 ahead (a plane's width apart, they escape
//! the hardware prefetchers). Precision:
//! `f32` arithmetic, `f64` design. The loops run on the widest instruction set found
//! at run time (AVX-512, AVX2 or SSE4.2 on x86-64), with the same bits on every one,
//! and the bits of the plain recursion of each column (tested on every level the
//! processor has).

// The modules: `filter` (the kernels and the design of their recursive filters), `sweep`
// (one recursion down or up a block of columns, in registers), `columns` (the column
// passes over a `Window` of a plane) and `transpose` (the transposes between the passes
// along columns and along rows).
mod columns;
mod filter;
mod sweep;
mod transpose;

pub use columns::{Mode, Scratch, columns, columns_every, kept_rows};
pub use filter::{MAX_SECTIONS, Recursive, Section, Shape};
pub use transpose::{transpose, transpose_f32};

/// The part of a row-major plane a pass computes: the columns `columns` (element
/// indices within a row) of the rows `rows`. The PGM's planes are zero outside the
/// bounding box of the camera's valid region, so its passes compute that box alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// First and one-past-last column.
    pub columns: [usize; 2],
    /// First and one-past-last row.
    pub rows: [usize; 2],
}

impl Window {
    /// The whole `width × height` plane.
    pub fn whole(width: usize, height: usize) -> Self {
        Self {
            columns: [0, width],
            rows: [0, height],
        }
    }

    /// The same window in the transposed plane.
    pub fn transposed(self) -> Self {
        Self {
            columns: self.rows,
            rows: self.columns,
        }
    }

    /// The same window over pixels of `channels` interleaved elements.
    pub fn interleaved(self, channels: usize) -> Self {
        Self {
            columns: self.columns.map(|c| c * channels),
            rows: self.rows,
        }
    }
}
