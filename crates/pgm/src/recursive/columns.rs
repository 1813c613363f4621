//! The column passes: correlate the columns of a window of a row-major plane with a
//! [`Recursive`] filter ([`columns`], [`columns_every`]), on the widest instruction
//! set, a block of columns at a time.

use super::Window;
use super::filter::Recursive;
use super::sweep::{BLOCK, Coefficients, Emit, lanes_of, load, store, sweep, vectors};

/// Whether a column pass writes its result or adds it to the destination.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// `dst = filter(src)`.
    Write,
    /// `dst += filter(src)`.
    Add,
}

/// Scratch buffers of the recursive passes (reused: no allocation per image once
/// warm).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    causal: Vec<f32>,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recursive::Shape;

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
}
