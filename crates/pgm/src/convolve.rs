//! Separable correlation with zero padding, the workhorse of the transform's exact path
//! (below λ = 3 by default).
//!
//! `out[x] = Σ_{k=−r..r} K[k + r] · in[x + k]`, the sum restricted to `0 ≤ x + k < n`
//! (exact zero padding: pixels outside the image contribute nothing), along the rows,
//! then along the columns of that, evaluated at the samples only ([`at_samples`]).
//! Every output adds its taps in kernel order, so both passes give the textbook sums
//! bit for bit (tested). Each pass keeps 32 neighbouring outputs of a row in registers
//! over all its taps, and both vectorise, on the widest instruction set found at run
//! time (the same bits on every one). The row passes an output row needs are kept in a
//! ring of rows in cache, each output row gathered at its samples as soon as it is
//! summed: whole-image passes, which wrote and read back whole images, took 3.2–4.2 ms
//! for `G`, `J_λ` and `L_G` at 640×480, λ = 1 on AVX2, this 2.5–3.4 in the same sitting
//! (no faster at 320×240, whose images stay in cache anyway).

/// Sampled 1-D kernels of a Gaussian of extent `λ` over offsets `k = −r..=r`
/// (`k = u − u_g`, pixel minus sample).
#[derive(Debug, Clone, Default)]
pub struct Kernels {
    /// Radius `r` in pixels.
    pub radius: usize,
    /// `g(k) = exp(−k²/(2λ²))`.
    pub g: Vec<f32>,
    /// `k² g(k)`: the λ-derivative needs `‖u − u_g‖² g`.
    pub k2g: Vec<f32>,
    /// `(k/λ²) g(k) = ∂g(u − u_g)/∂u_g`: the derivative with respect to the sample
    /// position.
    pub dg: Vec<f32>,
}

impl Kernels {
    /// Kernels for extent `lambda` truncated at `radius` pixels.
    pub fn new(lambda: f32, radius: usize) -> Self {
        let mut k = Self::default();
        k.set(lambda, radius);
        k
    }

    /// Recompute in place (no allocation once the largest radius has been seen).
    pub fn set(&mut self, lambda: f32, radius: usize) {
        let l = f64::from(lambda);
        self.radius = radius;
        self.g.clear();
        self.k2g.clear();
        self.dg.clear();
        for i in 0..=2 * radius {
            let d = i as f64 - radius as f64;
            let g = (-d * d / (2.0 * l * l)).exp();
            self.g.push(g as f32);
            self.k2g.push((d * d * g) as f32);
            self.dg.push((d / (l * l) * g) as f32);
        }
    }
}

/// Columns `[start, end)` of one image row.
pub type Span = [usize; 2];

/// Outputs computed together, in registers (eight SSE vectors: enough independent sums
/// to hide the latency of an addition).
const LANES: usize = 32;

/// Outputs of a row that the column pass keeps in registers over all its taps (16 and
/// 32 were alike on AVX2, 64 slower; 64 was better on AVX-512, 32 kept for both).
const COLUMN_LANES: usize = 32;

/// Channel `.1` of a row of vectors, as [`row_inline`] reads it.
#[derive(Clone, Copy)]
struct Channel<'a, const C: usize>(&'a [[f32; C]], usize);

impl<const C: usize> Channel<'_, C> {
    /// Copy the values of columns `a..b` into `out` (`b − a` values).
    #[inline(always)]
    fn copy(self, a: usize, b: usize, out: &mut [f32]) {
        if C == 1 {
            out.copy_from_slice(self.0[a..b].as_flattened());
            return;
        }
        for (o, v) in out.iter_mut().zip(&self.0[a..b]) {
            *o = v[self.1];
        }
    }
}

/// One row pass: channel `s` of a row correlated with `kernel` into `d` (`width`
/// outputs; those farther than the radius from the span `[a, b)` that holds the row's
/// non-zero inputs are zero, the others computed, `LANES` at a time in registers from
/// a zero-padded copy of the row). `pad` holds at least `width + kernel.len() + LANES`
/// values and is zero outside the span's copy (restored before returning). Taps that
/// fall on zeros add `±0`, which leaves a sum started at `+0` unchanged: the textbook
/// sum's bits.
#[inline(always)]
fn row_inline<const C: usize>(
    s: Channel<'_, C>,
    d: &mut [f32],
    width: usize,
    kernel: &[f32],
    [a, b]: Span,
    pad: &mut [f32],
) {
    let r = (kernel.len() - 1) / 2;
    let (a, b) = (a.min(width), b.min(width));
    if a >= b {
        d.fill(0.0);
        return;
    }
    // pad[i] = s[i − r] inside the span, 0 elsewhere: out[x] = Σ_k K[k] pad[x + k].
    s.copy(a, b, &mut pad[a + r..b + r]);
    let (x0, x1) = (a.saturating_sub(r), (b + r).min(width));
    // Zero beyond the radius of the span; every output between is written below.
    d[..x0].fill(0.0);
    d[x1..].fill(0.0);
    let mut x = x0;
    while x < x1 {
        let mut acc = [0.0f32; LANES];
        let window = &pad[x..x + kernel.len() - 1 + LANES];
        for (input, &c) in window.windows(LANES).zip(kernel) {
            for j in 0..LANES {
                acc[j] += c * input[j];
            }
        }
        // A whole block as a copy of known size (a call to `memmove` otherwise).
        if x + LANES <= x1 {
            d[x..x + LANES].copy_from_slice(&acc);
        } else {
            d[x..x1].copy_from_slice(&acc[..x1 - x]);
        }
        x += LANES;
    }
    pad[a + r..b + r].fill(0.0);
}

/// A row of samples for [`at_samples`]: image row `y`, the columns `span` its samples
/// lie in, and the index of its first sample (the samples of a row are consecutive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleRow {
    /// The image row.
    pub y: usize,
    /// The columns of its samples (first, last + 1).
    pub span: Span,
    /// Its first sample's index in the samples.
    pub first: usize,
}

impl SampleRow {
    /// The rows of `samples` (row-major pixel indices of an image `width` wide, in
    /// increasing order), in order.
    pub fn of_samples(samples: &[u32], width: usize) -> Vec<SampleRow> {
        let mut rows: Vec<SampleRow> = Vec::new();
        for (i, &k) in samples.iter().enumerate() {
            let (x, y) = (k as usize % width, k as usize / width);
            match rows.last_mut() {
                Some(row) if row.y == y => row.span[1] = x + 1,
                _ => rows.push(SampleRow {
                    y,
                    span: [x, x + 1],
                    first: i,
                }),
            }
        }
        rows
    }
}

/// The input rows of [`at_samples`], one image row at a time.
pub trait RowSource<const C: usize>: Sync {
    /// Row `y`: borrowed, or computed into `buffer` (a row's `width` vectors).
    fn row<'a>(&'a self, y: usize, buffer: &'a mut [[f32; C]]) -> &'a [[f32; C]];
}

/// An image of `C`-vectors as a [`RowSource`]: its rows, `width` vectors each.
#[derive(Clone, Copy, Debug)]
pub struct ImageRows<'a, const C: usize> {
    /// The image, row-major.
    pub image: &'a [[f32; C]],
    /// Its width.
    pub width: usize,
}

impl<const C: usize> RowSource<C> for ImageRows<'_, C> {
    #[inline(always)]
    fn row<'a>(&'a self, y: usize, _: &'a mut [[f32; C]]) -> &'a [[f32; C]] {
        &self.image[y * self.width..(y + 1) * self.width]
    }
}

/// A sum of column correlations of row passes ([`at_samples`]): each term is a row
/// pass's index in `planes` and the column kernel applied to it, added in order.
pub type Terms<'a> = &'a [(usize, &'a [f32])];

/// Separable correlations at the samples only, row after row: each of `planes` is a
/// channel of the image whose rows `src` gives, correlated along its rows with a
/// kernel (`(channel, row kernel)`; `spans[y]` holds every non-zero input of row `y`,
/// `[0, width]` if unknown, and only outputs within the radius of it are computed;
/// each row is asked for once, or twice at the edge of two bands), and output `o` at a
/// sample is the sum of `outputs[o]`'s terms, each a plane correlated along its columns
/// with a kernel, every term's taps added in order from `+0`: the textbook sums' bits.
/// `dst[s][o]` is output `o` at `samples[s]`; `sample_rows` are
/// [`SampleRow::of_samples`].
///
/// The passes never leave the caches: the row passes of the rows an output row reads
/// (its column kernels' radius around it) are kept in a ring of rows, each computed
/// once, and each output row is gathered at its samples as soon as it is summed (whole
/// images written and read back instead moved about 45 MB for `L_G` at 640×480). With
/// `parallel`, bands of output rows are spread over
/// rayon's threads, each with its own ring (its first rows' row passes computed twice);
/// the result does not depend on the thread count.
///
/// # Panics
/// If a row of `src` is not `width` vectors, `dst` is shorter than the samples,
/// `sample_rows` are not the samples' rows, a plane names a channel beyond `C`, a term
/// a plane beyond `planes`, or a kernel has an even length.
#[allow(clippy::too_many_arguments)]
pub fn at_samples<const C: usize, const O: usize>(
    src: &impl RowSource<C>,
    width: usize,
    spans: &[Span],
    planes: &[(usize, &[f32])],
    outputs: [Terms<'_>; O],
    sample_rows: &[SampleRow],
    samples: &[u32],
    dst: &mut [[f32; O]],
    parallel: bool,
) {
    assert!(dst.len() >= samples.len(), "an output per sample");
    assert!(planes.iter().all(|&(c, k)| c < C && k.len() % 2 == 1));
    assert!(
        outputs
            .iter()
            .flat_map(|terms| terms.iter())
            .all(|&(p, k)| p < planes.len() && k.len() % 2 == 1)
    );
    let radius = outputs
        .iter()
        .flat_map(|terms| terms.iter())
        .map(|&(_, k)| (k.len() - 1) / 2)
        .max()
        .unwrap_or(0);
    let dst = &mut dst[..samples.len()];
    let band = Band {
        src,
        width,
        spans,
        planes,
        outputs,
        radius,
        samples,
    };
    if parallel {
        band.split(sample_rows, dst);
    } else {
        band.run(sample_rows, dst);
    }
}

/// Output rows at a time of [`at_samples`] on one thread (at least; more rows share
/// more of each band's row passes).
const BAND_ROWS: usize = 32;

/// What every band of [`at_samples`] shares.
struct Band<'a, R, const C: usize, const O: usize> {
    src: &'a R,
    width: usize,
    spans: &'a [Span],
    planes: &'a [(usize, &'a [f32])],
    outputs: [Terms<'a>; O],
    /// The largest radius of the column kernels: the rows an output row reads.
    radius: usize,
    samples: &'a [u32],
}

impl<R, const C: usize, const O: usize> Clone for Band<'_, R, C, O> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<R, const C: usize, const O: usize> Copy for Band<'_, R, C, O> {}

thread_local! {
    /// The ring of row passes of [`at_samples`] (`planes × (2 radius + 1)` rows), the
    /// zero-padded input row of its row passes, its output rows and the buffer of a
    /// computed input row, per thread.
    static RING: std::cell::RefCell<([Vec<f32>; 4], Vec<usize>)> = const {
        std::cell::RefCell::new(([Vec::new(), Vec::new(), Vec::new(), Vec::new()], Vec::new()))
    };
}

impl<R: RowSource<C>, const C: usize, const O: usize> Band<'_, R, C, O> {
    /// The rows `rows` (writing `dst`, from their first sample), cut in halves on
    /// rayon's threads down to [`BAND_ROWS`] rows.
    fn split(self, rows: &[SampleRow], dst: &mut [[f32; O]]) {
        if rows.len() <= 2 * BAND_ROWS {
            self.run(rows, dst);
            return;
        }
        let mid = rows.len() / 2;
        let (top, bottom) = rows.split_at(mid);
        let (dst_top, dst_bottom) = dst.split_at_mut(bottom[0].first - top[0].first);
        rayon::join(
            || self.split(top, dst_top),
            || self.split(bottom, dst_bottom),
        );
    }

    /// The rows `rows` on this thread, writing `dst` from their first sample.
    fn run(self, rows: &[SampleRow], dst: &mut [[f32; O]]) {
        let Some(first) = rows.first() else {
            return;
        };
        let (w, ring_rows) = (self.width, 2 * self.radius + 1);
        let longest = self.planes.iter().map(|(_, k)| k.len()).max().unwrap_or(1);
        RING.with_borrow_mut(|([ring, pad, line, input], starts)| {
            let ring_len = self.planes.len() * ring_rows * w;
            if ring.len() < ring_len {
                ring.resize(ring_len, 0.0);
            }
            if pad.len() < w + longest + LANES {
                pad.resize(w + longest + LANES, 0.0);
            }
            if line.len() < O * w {
                line.resize(O * w, 0.0);
            }
            if input.len() < C * w {
                input.resize(C * w, 0.0);
            }
            starts.resize(ring_rows, 0);
            crate::simd::on_widest(BandOp {
                band: self,
                rows,
                dst,
                base: first.first,
                ring,
                pad,
                line,
                input: &mut input.as_chunks_mut::<C>().0[..w],
                starts,
            });
        });
    }
}

/// [`Band::run`]'s loops, a [`crate::simd::Kernel`] (compiled for the widest
/// instruction set).
struct BandOp<'a, R, const C: usize, const O: usize> {
    band: Band<'a, R, C, O>,
    rows: &'a [SampleRow],
    dst: &'a mut [[f32; O]],
    /// The sample `dst[0]` is.
    base: usize,
    ring: &'a mut [f32],
    pad: &'a mut [f32],
    line: &'a mut [f32],
    /// Where a computed input row is written.
    input: &'a mut [[f32; C]],
    /// Where the rows `y − radius ..= y + radius` of an output row `y` start in the
    /// ring (plane 0's; the others' `p · (2 radius + 1) · width` further).
    starts: &'a mut [usize],
}

impl<R: RowSource<C>, const C: usize, const O: usize> crate::simd::Kernel for BandOp<'_, R, C, O> {
    #[inline(always)]
    fn run<S: pulp::Simd>(self, _: S) {
        let Self {
            band,
            rows,
            dst,
            base,
            ring,
            pad,
            line,
            input,
            starts,
        } = self;
        let (w, h, r) = (band.width, band.spans.len(), band.radius);
        let ring_rows = 2 * r + 1;
        // Where row `j` of plane `p` is kept.
        let at = |p: usize, j: usize| (p * ring_rows + j % ring_rows) * w;
        let plane_len = ring_rows * w;
        // The first input row not computed yet.
        let mut next = 0;
        for (i, row) in rows.iter().enumerate() {
            let y = row.y;
            for j in y.saturating_sub(r).max(next)..(y + r + 1).min(h) {
                let input = band.src.row(j, input);
                assert_eq!(input.len(), w, "a row of the image");
                for (p, &(c, kernel)) in band.planes.iter().enumerate() {
                    let d = &mut ring[at(p, j)..at(p, j) + w];
                    row_inline(Channel(input, c), d, w, kernel, band.spans[j], pad);
                }
                next = j + 1;
            }
            for (i, start) in starts.iter_mut().enumerate() {
                // Rows above the image are never read.
                *start = (y + i).wrapping_sub(r) % ring_rows * w;
            }
            let [a, b] = row.span;
            // `dst` ends with the band's last row.
            let end = rows.get(i + 1).map_or(base + dst.len(), |n| n.first);
            let samples = &band.samples[row.first..end];
            let dst = &mut dst[row.first - base..end - base];
            // Each output's row, then each sample's outputs together.
            for (terms, line) in band.outputs.iter().zip(line.chunks_exact_mut(w)) {
                column_sums(ring, [plane_len, r], starts, terms, [y, h], [a, b], line);
            }
            let line = &line[..O * w];
            if samples.len() == b - a {
                // Every pixel of the span (most rows).
                for (i, d) in dst.iter_mut().enumerate() {
                    *d = std::array::from_fn(|o| line[o * w + a + i]);
                }
            } else {
                for (d, &k) in dst.iter_mut().zip(samples) {
                    let x = k as usize - y * w;
                    *d = std::array::from_fn(|o| line[o * w + x]);
                }
            }
        }
    }
}

/// Output row `y` (of `h`) of a sum of column correlations over the columns `[a, b)`
/// of `line`, from the row passes kept in `ring` (row `y + i − radius` of plane `p` at
/// `p · plane_len + starts[i]`): `COLUMN_LANES` outputs at a time
/// in registers over every term's taps in order, the last outputs one tap at a time.
#[inline(always)]
fn column_sums(
    ring: &[f32],
    [plane_len, radius]: [usize; 2],
    starts: &[usize],
    terms: Terms<'_>,
    [y, h]: [usize; 2],
    [a, b]: Span,
    line: &mut [f32],
) {
    // A kernel's taps that fall inside the image, and where tap 0's row starts.
    let taps = |kernel: &[f32]| {
        let r = (kernel.len() - 1) / 2;
        (radius - r, r.saturating_sub(y), kernel.len().min(h + r - y))
    };
    let mut x = a;
    while x + COLUMN_LANES <= b {
        let mut acc = [0.0f32; COLUMN_LANES];
        for &(p, kernel) in terms {
            let (shift, k0, k1) = taps(kernel);
            for ki in k0..k1 {
                let c = kernel[ki];
                let row = p * plane_len + starts[ki + shift] + x;
                let input: &[f32; COLUMN_LANES] = ring[row..row + COLUMN_LANES].try_into().unwrap();
                for j in 0..COLUMN_LANES {
                    acc[j] += c * input[j];
                }
            }
        }
        line[x..x + COLUMN_LANES].copy_from_slice(&acc);
        x += COLUMN_LANES;
    }
    line[x..b].fill(0.0);
    for &(p, kernel) in terms {
        let (shift, k0, k1) = taps(kernel);
        for ki in k0..k1 {
            let c = kernel[ki];
            let row = p * plane_len + starts[ki + shift];
            for (o, &i) in line[x..b].iter_mut().zip(&ring[row + x..row + b]) {
                *o += c * i;
            }
        }
    }
}
