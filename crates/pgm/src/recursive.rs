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

/// Pole pairs `(b, ω)` (units of `1/λ`) of the three sections of each kernel: found
/// by minimising the fit's RMS error over the poles (Nelder–Mead on the continuous
/// kernel, weights by least squares; the ignored test `design::optimise_poles`),
/// started from Deriche's fourth-order poles. RMS error over the kernel, relative to its
/// peak: 8e-7 (`g`), 2.5e-5 (`k² g`), 6e-6 (`(k/λ²) g`); with Deriche's two sections
/// 6e-5, 1.4e-3 and 4e-4.
const POLES: [[(f64, f64); 3]; 3] = [
    [
        (2.204086, 0.527520),
        (2.173333, 1.618922),
        (2.101828, 2.861562),
    ],
    [
        (1.990528, 0.549120),
        (1.983032, 1.670266),
        (1.937829, 2.924540),
    ],
    [
        (1.797607, 0.557821),
        (1.794245, 1.707133),
        (1.771230, 2.980603),
    ],
];

/// Which kernel a [`Recursive`] filter approximates (λ is the Gaussian's extent,
/// `g(k) = exp(−k²/(2λ²))`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// `g(k)`.
    Gaussian,
    /// `k² g(k)` (the λ-derivative's kernel, times λ³).
    SquaredOffset,
    /// `(k/λ²) g(k)` (the derivative with respect to the sample position).
    Derivative,
}

impl Shape {
    /// The kernel's value at offset `k` for extent `lambda`.
    pub fn value(self, lambda: f64, k: f64) -> f64 {
        let g = (-k * k / (2.0 * lambda * lambda)).exp();
        match self {
            Shape::Gaussian => g,
            Shape::SquaredOffset => k * k * g,
            Shape::Derivative => k / (lambda * lambda) * g,
        }
    }

    /// The pole pairs `(b, ω)` of its sections.
    fn poles(self) -> &'static [(f64, f64)] {
        match self {
            Shape::Gaussian => &POLES[0],
            Shape::Derivative => &POLES[1],
            Shape::SquaredOffset => &POLES[2],
        }
    }

    fn symmetry(self) -> f32 {
        match self {
            Shape::Derivative => -1.0,
            _ => 1.0,
        }
    }
}

/// One second-order section: `y[k] = n₁ x[k−1] + n₂ x[k−2] − d₁ y[k−1] − d₂ y[k−2]`,
/// the strictly causal filter of impulse response `Re(A pᵏ)`, `k ≥ 1`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Section {
    /// `n₁ = Re(A p)`, `n₂ = −|p|² Re(A)`.
    pub numerator: [f32; 2],
    /// `d₁ = −2 Re(p)`, `d₂ = |p|²`.
    pub denominator: [f32; 2],
}

/// Most sections of a filter.
pub const MAX_SECTIONS: usize = 3;

/// A recursive approximation of one kernel at one λ: its centre tap and the
/// second-order sections (in parallel) of its right half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recursive {
    /// The centre tap `K(0)`.
    pub center: f32,
    /// `σ`: +1 for a symmetric kernel, −1 for an antisymmetric one.
    pub symmetry: f32,
    /// The sections (the first `len` are used).
    pub sections: [Section; MAX_SECTIONS],
    /// Number of sections.
    pub len: usize,
}

impl Recursive {
    /// The filter of `shape` at extent `lambda` (> 0, finite).
    pub fn new(shape: Shape, lambda: f32) -> Self {
        let l = f64::from(lambda);
        let pairs = shape.poles();
        let n = 2 * pairs.len();
        let basis = |k: f64, out: &mut [f64; 2 * MAX_SECTIONS]| {
            for (i, &(b, w)) in pairs.iter().enumerate() {
                let e = (-b * k / l).exp();
                let (sin, cos) = (w * k / l).sin_cos();
                out[2 * i] = e * cos;
                out[2 * i + 1] = e * sin;
            }
        };
        // Least squares over the right half, far enough for every term to have decayed.
        let last = (16.0 * l).ceil().max(16.0) as usize;
        let mut normal = [[0.0f64; 2 * MAX_SECTIONS]; 2 * MAX_SECTIONS];
        let mut rhs = [0.0f64; 2 * MAX_SECTIONS];
        let mut phi = [0.0f64; 2 * MAX_SECTIONS];
        for k in 1..=last {
            let k = k as f64;
            basis(k, &mut phi);
            let target = shape.value(l, k);
            for i in 0..n {
                rhs[i] += phi[i] * target;
                for j in 0..n {
                    normal[i][j] += phi[i] * phi[j];
                }
            }
        }
        let weights = solve(&mut normal, &mut rhs, n);
        let mut sections = [Section::default(); MAX_SECTIONS];
        for (i, &(b, w)) in pairs.iter().enumerate() {
            // Re(A pᵏ) with A = c − i s equals c Re(pᵏ) + s Im(pᵏ).
            let (c, s) = (weights[2 * i], -weights[2 * i + 1]);
            let r = (-b / l).exp();
            let (pr, pi) = (r * (w / l).cos(), r * (w / l).sin());
            sections[i] = Section {
                numerator: [(c * pr - s * pi) as f32, (-r * r * c) as f32],
                denominator: [(-2.0 * pr) as f32, (r * r) as f32],
            };
        }
        Self {
            center: shape.value(l, 0.0) as f32,
            symmetry: shape.symmetry(),
            sections,
            len: pairs.len(),
        }
    }

    /// The filter's response at offsets `−radius..=radius` (what the passes apply),
    /// computed by running its recursions on an impulse (`f64`, for tests and accuracy
    /// checks).
    pub fn impulse_response(&self, radius: usize) -> Vec<f64> {
        let mut f = vec![0.0f64; radius + 1];
        for s in &self.sections[..self.len] {
            let [n1, n2] = s.numerator.map(f64::from);
            let [d1, d2] = s.denominator.map(f64::from);
            let (mut y1, mut y2) = (0.0, 0.0);
            for k in 1..=radius {
                let x1 = if k == 1 { 1.0 } else { 0.0 };
                let x2 = if k == 2 { 1.0 } else { 0.0 };
                let y = n1 * x1 + n2 * x2 - d1 * y1 - d2 * y2;
                (y2, y1) = (y1, y);
                f[k] += y;
            }
        }
        let mut out = vec![0.0; 2 * radius + 1];
        out[radius] = f64::from(self.center);
        for k in 1..=radius {
            out[radius + k] = f[k];
            out[radius - k] = f64::from(self.symmetry) * f[k];
        }
        out
    }
}

/// Solve the first `n` equations of `a x = b` by Gaussian elimination with partial
/// pivoting (the normal equations of the fit, in `f64`).
fn solve(
    a: &mut [[f64; 2 * MAX_SECTIONS]; 2 * MAX_SECTIONS],
    b: &mut [f64; 2 * MAX_SECTIONS],
    n: usize,
) -> [f64; 2 * MAX_SECTIONS] {
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, pivot);
        b.swap(col, pivot);
        let p = a[col][col];
        if p == 0.0 {
            continue;
        }
        for row in col + 1..n {
            let factor = a[row][col] / p;
            for k in col..n {
                a[row][k] -= factor * a[col][k];
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = [0.0; 2 * MAX_SECTIONS];
    for row in (0..n).rev() {
        let mut s = b[row];
        for k in row + 1..n {
            s -= a[row][k] * x[k];
        }
        x[row] = if a[row][row] == 0.0 {
            0.0
        } else {
            s / a[row][row]
        };
    }
    x
}

/// Whether a column pass writes its result or adds it to the destination.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// `dst = filter(src)`.
    Write,
    /// `dst += filter(src)`.
    Add,
}

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

/// Scratch buffers of the recursive passes (reused: no allocation per image once
/// warm).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    causal: Vec<f32>,
}

/// The coefficients of the three sections, as one value per lane role.
#[derive(Clone, Copy)]
struct Coefficients {
    n1: [f32; 3],
    n2: [f32; 3],
    d1: [f32; 3],
    d2: [f32; 3],
}

impl Coefficients {
    fn of(filter: &Recursive) -> Self {
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
const BLOCK: usize = 2;

/// Vectors per block of columns of a sweep on the instruction set `S`: two where it
/// has 32 registers (the block's state, two past outputs per section, two past inputs
/// and the sums, 18 vectors, and the twelve coefficients fit in them), one where it has
/// 16.
#[inline(always)]
fn vectors<S: pulp::Simd>() -> usize {
    if S::REGISTER_COUNT >= 32 { BLOCK } else { 1 }
}

/// The `f32` lanes `[v · lanes, (v + 1) · lanes)` of a block of `n` columns that are
/// inside it (an empty range past `n`).
#[inline(always)]
fn lanes_of<S: pulp::Simd>(v: usize, n: usize) -> std::ops::Range<usize> {
    let start = (v * S::F32_LANES).min(n);
    start..((v + 1) * S::F32_LANES).min(n)
}

/// A vector from `part` (whole, or its first lanes and zeros: a masked load, slower
/// on this project's machines, for a block's last columns only).
#[inline(always)]
fn load<S: pulp::Simd>(simd: S, part: &[f32]) -> S::f32s {
    match S::as_simd_f32s(part) {
        ([whole], []) => *whole,
        _ => simd.partial_load_f32s(part),
    }
}

/// `part` from a vector's first lanes (all if `part` holds a vector).
#[inline(always)]
fn store<S: pulp::Simd>(simd: S, part: &mut [f32], value: S::f32s) {
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
fn sweep<S: pulp::Simd, E: Emit<S>>(
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

/// Correlate the columns of `window` in the row-major plane `src` (`width` elements
/// per row) with `filter`, `src` taken as zero outside the window's rows, into `dst`
/// (written or added to, by `mode`) inside the window only. Interleaved channels
/// (`[f32; C]` pixels) are filtered by passing `width = C × pixels per row` and the
/// window's columns times `C` ([`Window::interleaved`]).
///
/// Panics if the window does not fit in both planes.
pub fn columns(
    src: &[f32],
    dst: &mut [f32],
    width: usize,
    window: Window,
    filter: &Recursive,
    mode: Mode,
    scratch: &mut Scratch,
) {
    run_columns(src, dst, width, window, filter, mode, 1, scratch);
}

/// The rows of a window of rows `[r0, r1)` that [`columns_every`] writes with `step`:
/// `r0, r0 + step, …` and the last, `r1 − 1`; their number.
pub fn kept_rows([r0, r1]: [usize; 2], step: usize) -> usize {
    let step = step.max(1);
    match r1.checked_sub(r0 + 1) {
        None => 0,
        Some(span) => span / step + 1 + usize::from(!span.is_multiple_of(step)),
    }
}

/// [`columns`] (written) that keeps only the rows `r0, r0 + step, …` and the last
/// `r1 − 1` of the window's rows `[r0, r1)`, packed from the first row of `dst`
/// (the `k`-th kept row in row `k`; [`kept_rows`] of them), in the window's columns.
/// Every row is still filtered; only the final sum and the store are skipped. For
/// planes that the filter smooths over many rows, interpolated between kept rows
/// afterwards.
///
/// Panics if the window does not fit in `src`, or its kept rows in `dst`.
pub fn columns_every(
    src: &[f32],
    dst: &mut [f32],
    width: usize,
    window: Window,
    filter: &Recursive,
    step: usize,
    scratch: &mut Scratch,
) {
    let step = step.max(1);
    run_columns(src, dst, width, window, filter, Mode::Write, step, scratch);
}

/// [`columns`] or [`columns_every`] on the widest instruction set, after checking that
/// the window fits in the source, and the rows it writes in the destination.
#[allow(clippy::too_many_arguments)]
fn run_columns(
    src: &[f32],
    dst: &mut [f32],
    width: usize,
    window: Window,
    filter: &Recursive,
    mode: Mode,
    step: usize,
    scratch: &mut Scratch,
) {
    let ([c0, c1], [r0, r1]) = (window.columns, window.rows);
    let dst_rows = match step {
        1 => r1,
        step => kept_rows([r0, r1], step),
    };
    assert!(
        c0 <= c1
            && c1 <= width
            && r0 <= r1
            && r1 * width <= src.len()
            && dst_rows * width <= dst.len(),
        "window {window:?} outside a plane of {width} columns"
    );
    crate::simd::on_widest(ColumnsOp {
        src,
        dst,
        width,
        window,
        filter,
        mode,
        step,
        scratch,
    });
}

/// The arguments of [`columns`], a [`crate::simd::Kernel`].
struct ColumnsOp<'a> {
    src: &'a [f32],
    dst: &'a mut [f32],
    width: usize,
    window: Window,
    filter: &'a Recursive,
    mode: Mode,
    /// 1: every row in place; else the kept rows of [`columns_every`], packed.
    step: usize,
    scratch: &'a mut Scratch,
}

impl crate::simd::Kernel for ColumnsOp<'_> {
    #[inline(always)]
    fn run<S: pulp::Simd>(self, simd: S) {
        columns_inline(simd, self);
    }
}

/// [`columns`] and [`columns_every`] in blocks of [`vectors`] of columns,
/// inlined into each instruction set's copy.
#[inline(always)]
fn columns_inline<S: pulp::Simd>(simd: S, op: ColumnsOp<'_>) {
    let ColumnsOp {
        src,
        dst,
        width,
        window,
        filter,
        mode,
        step,
        scratch,
    } = op;
    let ([c0, c1], rows) = (window.columns, window.rows);
    let height = rows[1] - rows[0];
    let block = vectors::<S>() * S::F32_LANES;
    let mut causal = std::mem::take(&mut scratch.causal);
    causal.resize(height * block, 0.0);
    let (center, sigma) = (filter.center, filter.symmetry);
    let c = Coefficients::of(filter);
    for x0 in (c0..c1).step_by(block) {
        let n = block.min(c1 - x0);
        let mut causal_rows = Causal {
            simd,
            causal: &mut causal,
            first_row: rows[0],
        };
        sweep(simd, src, width, rows, [x0, n], c, true, &mut causal_rows);
        let mut finish = Finish {
            simd,
            src,
            dst: &mut *dst,
            width,
            rows,
            block: [x0, n],
            causal: &causal,
            center,
            sigma,
            mode,
            step,
        };
        sweep(simd, src, width, rows, [x0, n], c, false, &mut finish);
    }
    scratch.causal = causal;
}

/// What a [`sweep`] does with the sums of each row: a struct with an
/// `#[inline(always)]` method, not a closure (a closure that the compiler does not
/// inline is compiled apart, without the instruction set of its caller).
trait Emit<S: pulp::Simd> {
    /// The sections' sums at row `y`, a block's vectors.
    fn row(&mut self, y: usize, sums: [S::f32s; BLOCK]);
}

/// The causal sweep's [`Emit`]: keep every row's sums (whole vectors, [`vectors`]
/// a row).
struct Causal<'a, S> {
    simd: S,
    causal: &'a mut [f32],
    first_row: usize,
}

impl<S: pulp::Simd> Emit<S> for Causal<'_, S> {
    #[inline(always)]
    fn row(&mut self, y: usize, sums: [S::f32s; BLOCK]) {
        let (lanes, y) = (S::F32_LANES, y - self.first_row);
        let block = vectors::<S>() * lanes;
        let row = &mut self.causal[y * block..][..block];
        for (v, sum) in sums.into_iter().enumerate().take(vectors::<S>()) {
            store(self.simd, &mut row[v * lanes..(v + 1) * lanes], sum);
        }
    }
}

/// The anticausal sweep's [`Emit`]: the output `K(0) src + anticausal + σ causal` of
/// the block of columns `[x0, x0 + n)` at each row written (every row in place if `step` is 1,
/// else the kept rows packed: [`columns_every`]).
struct Finish<'a, S> {
    simd: S,
    src: &'a [f32],
    dst: &'a mut [f32],
    width: usize,
    rows: [usize; 2],
    block: [usize; 2],
    causal: &'a [f32],
    center: f32,
    sigma: f32,
    mode: Mode,
    step: usize,
}

impl<S: pulp::Simd> Emit<S> for Finish<'_, S> {
    #[inline(always)]
    fn row(&mut self, y: usize, a: [S::f32s; BLOCK]) {
        let ([x0, n], step, width, simd) = (self.block, self.step, self.width, self.simd);
        let lanes = S::F32_LANES;
        let yc = y - self.rows[0];
        // The destination row: the same, or the kept row's packed index.
        let out = if step == 1 {
            y
        } else if yc.is_multiple_of(step) {
            yc / step
        } else if y + 1 == self.rows[1] {
            yc / step + 1
        } else {
            return;
        };
        let (center, sigma) = (simd.splat_f32s(self.center), simd.splat_f32s(self.sigma));
        let (at, to) = (y * width + x0, out * width + x0);
        let (src, dst) = (&self.src[at..at + n], &mut self.dst[to..to + n]);
        let block = vectors::<S>() * lanes;
        let causal = &self.causal[yc * block..][..block];
        for (v, a) in a.into_iter().enumerate().take(vectors::<S>()) {
            let part = lanes_of::<S>(v, n);
            let s = load(simd, &src[part.clone()]);
            let c = load(simd, &causal[v * lanes..(v + 1) * lanes]);
            // K(0) s + a + σ c, in this order.
            let value = simd.add_f32s(
                simd.add_f32s(simd.mul_f32s(center, s), a),
                simd.mul_f32s(sigma, c),
            );
            let o = &mut dst[part];
            let value = match self.mode {
                Mode::Write => value,
                Mode::Add => simd.add_f32s(load(simd, o), value),
            };
            store(simd, o, value);
        }
    }
}

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

    /// Largest difference between the impulse response and the sampled kernel,
    /// relative to the kernel's largest absolute value.
    fn error(shape: Shape, lambda: f32) -> f64 {
        let filter = Recursive::new(shape, lambda);
        let radius = (16.0 * lambda).ceil() as usize;
        let response = filter.impulse_response(radius);
        let l = f64::from(lambda);
        let exact: Vec<f64> = (0..=2 * radius)
            .map(|i| shape.value(l, i as f64 - radius as f64))
            .collect();
        let peak = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        response
            .iter()
            .zip(&exact)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
            / peak
    }

    /// The impulse responses against the sampled kernels over the supported λ.
    /// Measured (largest over λ ∈ {1, 2, 3, 5, 7.5, 15, 30, 40}): `g` 1.1e-5, `k² g`
    /// 2.2e-4, `(k/λ²) g` 5.6e-5; up to λ = 15: 2.5e-6, 8.1e-5, 2.0e-5.
    #[test]
    fn impulse_responses_match_the_kernels() {
        for (shape, bound_15, bound_40) in [
            (Shape::Gaussian, 5e-6, 2e-5),
            (Shape::SquaredOffset, 1.2e-4, 3e-4),
            (Shape::Derivative, 3e-5, 8e-5),
        ] {
            for lambda in [1.0f32, 2.0, 3.0, 5.0, 7.5, 15.0, 30.0, 40.0] {
                let e = error(shape, lambda);
                let bound = if lambda <= 15.0 { bound_15 } else { bound_40 };
                assert!(e < bound, "{shape:?} at λ {lambda}: {e:.2e} of the peak");
            }
        }
    }

    /// A column pass equals the impulse response applied as a correlation (zero
    /// padding), for both modes, at the edges of the blocks of every instruction set
    /// and at the last column (a width that is not a multiple of any block).
    #[test]
    fn column_pass_is_the_correlation_of_the_impulse_response() {
        let (width, height) = (300, 37);
        let src: Vec<f32> = (0..width * height)
            .map(|k| ((k * 7919) % 1000) as f32 / 1000.0 - 0.3)
            .collect();
        let mut scratch = Scratch::default();
        for shape in [Shape::Gaussian, Shape::SquaredOffset, Shape::Derivative] {
            let filter = Recursive::new(shape, 4.0);
            let taps = filter.impulse_response(height);
            let mut dst = vec![0.5f32; width * height];
            columns(
                &src,
                &mut dst,
                width,
                Window::whole(width, height),
                &filter,
                Mode::Add,
                &mut scratch,
            );
            for x in [0, 1, 15, 16, 31, 32, 255, 256, 299] {
                for y in 0..height {
                    let mut expected = 0.5f64;
                    for yy in 0..height {
                        let k = yy as isize - y as isize + height as isize;
                        expected += taps[k as usize] * f64::from(src[yy * width + x]);
                    }
                    let got = f64::from(dst[y * width + x]);
                    assert!(
                        (got - expected).abs() < 1e-5 * (1.0 + expected.abs()),
                        "{shape:?} ({x}, {y}): {got} vs {expected}"
                    );
                }
            }
        }
    }

    /// The pass of `filter` over `window` on the instruction set `level`
    /// ([`crate::simd::levels`]), into a copy of `dst` (kept rows packed if `step` > 1).
    #[allow(clippy::too_many_arguments)]
    fn pass_on(
        level: &str,
        src: &[f32],
        dst: &[f32],
        width: usize,
        window: Window,
        filter: &Recursive,
        mode: Mode,
        step: usize,
    ) -> Vec<f32> {
        let mut out = dst.to_vec();
        let scratch = &mut Scratch::default();
        let (src, dst) = (src, out.as_mut_slice());
        let op = ColumnsOp {
            src,
            dst,
            width,
            window,
            filter,
            mode,
            step,
            scratch,
        };
        crate::simd::on_level(level, op);
        out
    }

    /// The plain recursion of one column, element by element, with the blocked
    /// passes' operations in their order: causal and anticausal sums of the three
    /// sections from zero states, then `K(0) x + a + σ c`.
    fn plain_column(filter: &Recursive, x: &[f32]) -> Vec<f32> {
        let c = Coefficients::of(filter);
        let sweep = |x: &[f32]| -> Vec<f32> {
            let (mut older, mut newer, mut out) = ([0.0f32; 3], [0.0f32; 3], vec![]);
            for t in 0..x.len() {
                let a = if t >= 1 { x[t - 1] } else { 0.0 };
                let b = if t >= 2 { x[t - 2] } else { 0.0 };
                let mut v = [0.0f32; 3];
                for i in 0..3 {
                    v[i] = c.n1[i] * a + c.n2[i] * b - c.d1[i] * newer[i] - c.d2[i] * older[i];
                    older[i] = newer[i];
                    newer[i] = v[i];
                }
                out.push(v[0] + v[1] + v[2]);
            }
            out
        };
        let causal = sweep(x);
        let reversed: Vec<f32> = x.iter().rev().copied().collect();
        let mut anticausal = sweep(&reversed);
        anticausal.reverse();
        (0..x.len())
            .map(|t| filter.center * x[t] + anticausal[t] + filter.symmetry * causal[t])
            .collect()
    }

    /// The blocked passes (the widest instruction set's vectors, and one lane at a
    /// time) give, bit for bit, the plain recursion of each column inside the
    /// window, for every kernel, both modes, blocks cut short at the window's edge,
    /// and leave the rest of the destination as it was.
    #[test]
    fn blocked_passes_are_the_plain_recursion_of_each_column() {
        for (width, height, window) in [
            (
                6 * 53,
                41,
                Window {
                    columns: [6, 6 * 53 - 12],
                    rows: [2, 40],
                },
            ),
            (37, 9, Window::whole(37, 9)),
            (
                70,
                3,
                Window {
                    columns: [33, 34],
                    rows: [0, 3],
                },
            ),
        ] {
            let src: Vec<f32> = (0..width * height)
                .map(|k| ((k * 7919) % 1000) as f32 / 1000.0 - 0.3)
                .collect();
            for shape in [Shape::Gaussian, Shape::SquaredOffset, Shape::Derivative] {
                let filter = Recursive::new(shape, 2.9);
                for mode in [Mode::Write, Mode::Add] {
                    let before = vec![0.25f32; width * height];
                    let mut expected = before.clone();
                    let [r0, r1] = window.rows;
                    for x in window.columns[0]..window.columns[1] {
                        let column: Vec<f32> = (r0..r1).map(|y| src[y * width + x]).collect();
                        for (y, v) in (r0..r1).zip(plain_column(&filter, &column)) {
                            let e = &mut expected[y * width + x];
                            *e = if mode == Mode::Add { *e + v } else { v };
                        }
                    }
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    let mut fast = before.clone();
                    let mut sc = Scratch::default();
                    columns(&src, &mut fast, width, window, &filter, mode, &mut sc);
                    assert_eq!(bits(&fast), bits(&expected), "{width} {shape:?} {mode:?}");
                    // Every instruction set this processor has, and the baseline.
                    for level in crate::simd::levels() {
                        let out = pass_on(level, &src, &before, width, window, &filter, mode, 1);
                        let what = format!("{level} {width} {shape:?} {mode:?}");
                        assert_eq!(bits(&out), bits(&expected), "{what}");
                    }
                }
            }
        }
    }

    /// The pass on every instruction set this processor has gives the bits of the
    /// baseline's loops (a window whose columns are not a multiple of any block).
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let (width, height) = (6 * 53, 41);
        let src: Vec<f32> = (0..width * height)
            .map(|k| ((k * 7919) % 1000) as f32 / 1000.0 - 0.3)
            .collect();
        let window = Window {
            columns: [6, width - 12],
            rows: [2, height - 1],
        };
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for shape in [Shape::Gaussian, Shape::SquaredOffset, Shape::Derivative] {
            let filter = Recursive::new(shape, 3.7);
            for mode in [Mode::Write, Mode::Add] {
                let before = vec![0.25f32; width * height];
                let run = |level: &str| {
                    bits(&pass_on(
                        level, &src, &before, width, window, &filter, mode, 1,
                    ))
                };
                let baseline = run("baseline");
                for level in crate::simd::levels() {
                    assert_eq!(run(level), baseline, "{level} {shape:?} {mode:?}");
                }
            }
        }
    }

    /// [`columns_every`] keeps, packed, exactly the rows `r0, r0 + step, …` and the
    /// last of the pass over every row, on every instruction set this processor has.
    #[test]
    fn kept_rows_are_the_rows_of_the_whole_pass() {
        let (width, height) = (6 * 53, 41);
        let src: Vec<f32> = (0..width * height)
            .map(|k| ((k * 7919) % 1000) as f32 / 1000.0 - 0.3)
            .collect();
        let window = Window {
            columns: [6, width - 12],
            rows: [2, height - 1],
        };
        let filter = Recursive::new(Shape::Gaussian, 12.5);
        let mut every = vec![0.0f32; width * height];
        let mut scratch = Scratch::default();
        columns(
            &src,
            &mut every,
            width,
            window,
            &filter,
            Mode::Write,
            &mut scratch,
        );
        for step in [2, 3, 7, 38, 39] {
            let kept = kept_rows(window.rows, step);
            let mut fast = vec![0.0f32; kept * width];
            columns_every(&src, &mut fast, width, window, &filter, step, &mut scratch);
            let by_level: Vec<(&str, Vec<f32>)> = crate::simd::levels()
                .into_iter()
                .map(|level| {
                    let zeros = vec![0.0f32; kept * width];
                    let out = pass_on(
                        level,
                        &src,
                        &zeros,
                        width,
                        window,
                        &filter,
                        Mode::Write,
                        step,
                    );
                    (level, out)
                })
                .collect();
            let [r0, r1] = window.rows;
            let mut rows: Vec<usize> = (r0..r1).step_by(step).collect();
            if rows.last() != Some(&(r1 - 1)) {
                rows.push(r1 - 1);
            }
            assert_eq!(rows.len(), kept, "step {step}");
            for (k, &y) in rows.iter().enumerate() {
                let [c0, c1] = window.columns;
                let want = &every[y * width + c0..y * width + c1];
                assert_eq!(
                    &fast[k * width + c0..k * width + c1],
                    want,
                    "step {step} row {y}"
                );
                for (level, out) in &by_level {
                    let got = &out[k * width + c0..k * width + c1];
                    assert_eq!(got, want, "{level} step {step} row {y}");
                }
            }
        }
    }

    /// A pass over a window of a plane that is zero outside the window's rows gives,
    /// inside the window, the values of the pass over the whole plane, and leaves
    /// the rest of the destination as it was; for both modes and interleaved
    /// channels.
    #[test]
    fn a_window_is_the_whole_pass_inside_it() {
        let (pixels, height, channels) = (90, 50, 6);
        let width = pixels * channels;
        let window = Window {
            columns: [17, 70],
            rows: [9, 41],
        }
        .interleaved(channels);
        let src: Vec<f32> = (0..width * height)
            .map(|k| {
                let (x, y) = (k % width, k / width);
                let inside = (window.rows[0]..window.rows[1]).contains(&y);
                // Zero outside the rows; the columns outside the window hold data the
                // window pass must not read.
                if inside {
                    ((k * 7919) % 1000) as f32 / 1000.0 - 0.3 + x as f32 * 1e-3
                } else {
                    0.0
                }
            })
            .collect();
        for shape in [Shape::Gaussian, Shape::SquaredOffset, Shape::Derivative] {
            let filter = Recursive::new(shape, 5.5);
            for mode in [Mode::Write, Mode::Add] {
                let mut whole = vec![0.25f32; width * height];
                let mut part = whole.clone();
                let mut scratch = Scratch::default();
                let all = Window::whole(width, height);
                columns(&src, &mut whole, width, all, &filter, mode, &mut scratch);
                columns(&src, &mut part, width, window, &filter, mode, &mut scratch);
                for y in 0..height {
                    for x in 0..width {
                        let k = y * width + x;
                        let inside = (window.rows[0]..window.rows[1]).contains(&y)
                            && (window.columns[0]..window.columns[1]).contains(&x);
                        let want = if inside { whole[k] } else { 0.25 };
                        assert_eq!(part[k], want, "{shape:?} {mode:?} ({x}, {y})");
                    }
                }
            }
        }
    }

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

#[cfg(test)]
mod design {
    use super::*;

    fn fit_error(shape: Shape, pairs: &[(f64, f64)], l: f64) -> f64 {
        let n = 2 * pairs.len();
        let last = (16.0 * l).ceil() as usize;
        let mut normal = [[0.0f64; 2 * MAX_SECTIONS]; 2 * MAX_SECTIONS];
        let mut rhs = [0.0f64; 2 * MAX_SECTIONS];
        let phi = |k: f64| {
            let mut out = [0.0; 2 * MAX_SECTIONS];
            for (i, &(b, w)) in pairs.iter().enumerate() {
                let e = (-b * k / l).exp();
                out[2 * i] = e * (w * k / l).cos();
                out[2 * i + 1] = e * (w * k / l).sin();
            }
            out
        };
        for k in 1..=last {
            let p = phi(k as f64);
            let t = shape.value(l, k as f64);
            for i in 0..n {
                rhs[i] += p[i] * t;
                for j in 0..n {
                    normal[i][j] += p[i] * p[j];
                }
            }
        }
        let x = solve(&mut normal, &mut rhs, n);
        let mut peak = 0.0f64;
        let mut err = 0.0f64;
        for k in 1..=last {
            let p = phi(k as f64);
            let v: f64 = (0..n).map(|i| p[i] * x[i]).sum();
            let t = shape.value(l, k as f64);
            peak = peak.max(t.abs());
            err += (v - t).powi(2);
        }
        (err / last as f64).sqrt() / peak
    }

    fn nelder_mead(f: impl Fn(&[f64]) -> f64, start: Vec<f64>) -> Vec<f64> {
        let n = start.len();
        let mut simplex: Vec<Vec<f64>> = vec![start.clone()];
        for i in 0..n {
            let mut p = start.clone();
            p[i] *= 1.1;
            simplex.push(p);
        }
        let mut values: Vec<f64> = simplex.iter().map(|p| f(p)).collect();
        for _ in 0..4000 {
            let mut idx: Vec<usize> = (0..=n).collect();
            idx.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
            simplex = idx.iter().map(|&i| simplex[i].clone()).collect();
            values = idx.iter().map(|&i| values[i]).collect();
            let centroid: Vec<f64> = (0..n)
                .map(|j| simplex[..n].iter().map(|p| p[j]).sum::<f64>() / n as f64)
                .collect();
            let along = |t: f64| -> Vec<f64> {
                (0..n)
                    .map(|j| centroid[j] + t * (simplex[n][j] - centroid[j]))
                    .collect()
            };
            let r = along(-1.0);
            let fr = f(&r);
            if fr < values[0] {
                let e = along(-2.0);
                let fe = f(&e);
                if fe < fr {
                    simplex[n] = e;
                    values[n] = fe;
                } else {
                    simplex[n] = r;
                    values[n] = fr;
                }
            } else if fr < values[n - 1] {
                simplex[n] = r;
                values[n] = fr;
            } else {
                let c = along(0.5);
                let fc = f(&c);
                if fc < values[n] {
                    simplex[n] = c;
                    values[n] = fc;
                } else {
                    for i in 1..=n {
                        simplex[i] = (0..n)
                            .map(|j| simplex[0][j] + 0.5 * (simplex[i][j] - simplex[0][j]))
                            .collect();
                        values[i] = f(&simplex[i]);
                    }
                }
            }
        }
        simplex[0].clone()
    }

    #[test]
    #[ignore]
    fn optimise_poles() {
        for shape in [Shape::Gaussian, Shape::SquaredOffset, Shape::Derivative] {
            for sections in [2usize, 3] {
                let start: Vec<f64> = [1.7, 0.6, 1.7, 2.0, 1.5, 3.0][..2 * sections].to_vec();
                let f = |p: &[f64]| {
                    let pairs: Vec<(f64, f64)> = p.chunks(2).map(|c| (c[0], c[1])).collect();
                    if pairs.iter().any(|&(b, _)| b <= 0.05) {
                        return 1.0;
                    }
                    fit_error(shape, &pairs, 20.0)
                };
                let mut best = nelder_mead(f, start);
                for _ in 0..3 {
                    best = nelder_mead(f, best);
                }
                eprintln!("{shape:?} {sections}: {:?} rms {:.2e}", best, f(&best));
            }
        }
    }
}
