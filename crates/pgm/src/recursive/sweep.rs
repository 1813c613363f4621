//! One sweep of the three sections of a filter down or up the rows of a block of
//! columns, its state in registers ([`sweep`]), handing the sums of each row to an
//! [`Emit`].

use super::filter::Recursive;

/// The coefficients of the three sections, as one value per lane role.
#[derive(Clone, Copy)]
pub(super) struct Coefficients {
    pub(super) n1: [f32; 3],
    pub(super) n2: [f32; 3],
    pub(super) d1: [f32; 3],
    pub(super) d2: [f32; 3],
}

impl Coefficients {
    pub(super) fn of(filter: &Recursive) -> Self {
        let mut c = Self {
            n1: [0.0; 3],
            n2: [0.0; 3],
            d1: [0.0; 3],
            d2: [0.0; 3],
        };
        // Unused sections stay zero: they add exactly nothing.
        for (i, s) in filter.sections[..filter.len].iter().enumerate() {
            [c.n1[i], c.n2[i]] = s.numerator;
            [c.d1[i], c.d2[i]] = s.denominator;
        }
        c
    }
}

/// Most vectors per block of columns of a sweep.
pub(super) const BLOCK: usize = 2;

/// Vectors per block of columns of a sweep on the instruction set `S`: two where it
/// has 32 registers (the block's state, two past outputs per section, two past inputs
/// and the sums, 18 vectors, and the twelve coefficients fit in them), one where it has
/// 16.
#[inline(always)]
pub(super) fn vectors<S: pulp::Simd>() -> usize {
    if S::REGISTER_COUNT >= 32 { BLOCK } else { 1 }
}

/// The `f32` lanes `[v · lanes, (v + 1) · lanes)` of a block of `n` columns that are
/// inside it (an empty range past `n`).
#[inline(always)]
pub(super) fn lanes_of<S: pulp::Simd>(v: usize, n: usize) -> std::ops::Range<usize> {
    let start = (v * S::F32_LANES).min(n);
    start..((v + 1) * S::F32_LANES).min(n)
}

/// A vector from `part` (whole, or its first lanes and zeros: a masked load, slower
/// on this project's machines, for a block's last columns only).
#[inline(always)]
pub(super) fn load<S: pulp::Simd>(simd: S, part: &[f32]) -> S::f32s {
    match S::as_simd_f32s(part) {
        ([whole], []) => *whole,
        _ => simd.partial_load_f32s(part),
    }
}

/// `part` from a vector's first lanes (all if `part` holds a vector).
#[inline(always)]
pub(super) fn store<S: pulp::Simd>(simd: S, part: &mut [f32], value: S::f32s) {
    match S::as_mut_simd_f32s(part) {
        ([whole], []) => *whole = value,
        (_, part) => simd.partial_store_f32s(part, value),
    }
}

/// One sweep of the three sections down or up the rows `[r0, r1)` of the block of
/// columns `[x0, x0 + n)`, `n ≤` [`vectors`] `· lanes` (the input taken as zero before them),
/// handing `emit.row(y, sums)` the sum of the sections' outputs at every row, row
/// after row. The block's state stays in registers for the whole sweep: each row
/// reads its input and hands its sums, nothing else goes to memory. Lanes past `n`
/// read zeros and are never written to the destination.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn sweep<S: pulp::Simd, E: Emit<S>>(
    simd: S,
    src: &[f32],
    width: usize,
    [r0, r1]: [usize; 2],
    [x0, n]: [usize; 2],
    c: Coefficients,
    down: bool,
    emit: &mut E,
) {
    let zero = simd.splat_f32s(0.0);
    let (mut n1, mut n2, mut d1, mut d2) = ([zero; 3], [zero; 3], [zero; 3], [zero; 3]);
    for i in 0..3 {
        n1[i] = simd.splat_f32s(c.n1[i]);
        n2[i] = simd.splat_f32s(c.n2[i]);
        d1[i] = simd.splat_f32s(c.d1[i]);
        d2[i] = simd.splat_f32s(c.d2[i]);
    }
    if down {
        // The first rows, before the sweep asks for each row ahead of itself.
        for y in r0..(r0 + PREFETCH_ROWS).min(r1) {
            prefetch_line(src, y * width + x0, n);
        }
    }
    // Per section, `older` (y[t − 2]) and `newer` (y[t − 1]); the inputs x[t − 1],
    // x[t − 2].
    let mut older = [[zero; BLOCK]; 3];
    let mut newer = [[zero; BLOCK]; 3];
    let (mut x1, mut x2) = ([zero; BLOCK], [zero; BLOCK]);
    for t in 0..r1 - r0 {
        let y = if down { r0 + t } else { r1 - 1 - t };
        let mut sums = [zero; BLOCK];
        for v in 0..vectors::<S>() {
            let (a, b) = (x1[v], x2[v]);
            let mut out = [zero; 3];
            for i in 0..3 {
                // n₁ a + n₂ b − d₁ y[t − 1] − d₂ y[t − 2], in this order.
                let feed = simd.add_f32s(simd.mul_f32s(n1[i], a), simd.mul_f32s(n2[i], b));
                let back = simd.sub_f32s(feed, simd.mul_f32s(d1[i], newer[i][v]));
                out[i] = simd.sub_f32s(back, simd.mul_f32s(d2[i], older[i][v]));
                older[i][v] = newer[i][v];
                newer[i][v] = out[i];
            }
            sums[v] = simd.add_f32s(simd.add_f32s(out[0], out[1]), out[2]);
        }
        emit.row(y, sums);
        x2 = x1;
        if down && y + PREFETCH_ROWS < r1 {
            prefetch_line(src, (y + PREFETCH_ROWS) * width + x0, n);
        }
        let line = &src[y * width + x0..][..n];
        for (v, x) in x1.iter_mut().enumerate().take(vectors::<S>()) {
            *x = load(simd, &line[lanes_of::<S>(v, n)]);
        }
    }
}

/// How many rows ahead a down sweep asks for its input: the rows of a block are a
/// plane's width apart (a new page each, for interleaved channels), so the hardware
/// prefetchers do not follow them, and the first sweep reads a plane that an earlier
/// stage wrote (cold); the second sweep finds the block's rows in cache.
const PREFETCH_ROWS: usize = 32;

/// Ask for the cache lines of `src[at..at + n]` (`n` ≥ 1): a prefetch instruction per
/// 64 bytes on x86-64; nothing elsewhere. Only the time depends on it.
#[inline(always)]
fn prefetch_line(src: &[f32], at: usize, n: usize) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
    {
        let line = &src[at..at + n];
        for k in (0..n).step_by(16) {
            safe_arch::prefetch_t0(&line[k]);
        }
        safe_arch::prefetch_t0(&line[n - 1]);
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
    let _ = (src, at, n);
}

/// What a [`sweep`] does with the sums of each row: a struct with an
/// `#[inline(always)]` method, not a closure (a closure that the compiler does not
/// inline is compiled apart, without the instruction set of its caller).
pub(super) trait Emit<S: pulp::Simd> {
    /// The sections' sums at row `y`, a block's vectors.
    fn row(&mut self, y: usize, sums: [S::f32s; BLOCK]);
}
