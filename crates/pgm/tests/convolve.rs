//! The correlations against the textbook loops, bit for bit: skipping the zero inputs
//! outside each row's span and computing only at the samples changes no value.

use pgm::convolve::{ImageRows, SampleRow, Span, at_samples};
use proptest::prelude::*;

/// One output at a time over the whole row, taps in order, zero padding.
fn reference_rows(src: &[f32], width: usize, kernel: &[f32]) -> Vec<f32> {
    let r = (kernel.len() - 1) as isize / 2;
    let mut out = vec![0.0f32; src.len()];
    for (row_in, row_out) in src.chunks(width).zip(out.chunks_mut(width)) {
        for (x, o) in row_out.iter_mut().enumerate() {
            for (ki, &c) in kernel.iter().enumerate() {
                let xs = x as isize + ki as isize - r;
                if (0..width as isize).contains(&xs) {
                    *o += c * row_in[xs as usize];
                }
            }
        }
    }
    out
}

/// Adds the column correlation to every pixel of `out`, taps in order, zero padding.
fn reference_add_columns(src: &[f32], out: &mut [f32], width: usize, kernel: &[f32]) {
    let height = src.len() / width;
    let r = (kernel.len() - 1) as isize / 2;
    for y in 0..height {
        for x in 0..width {
            for (ki, &c) in kernel.iter().enumerate() {
                let ys = y as isize + ki as isize - r;
                if (0..height as isize).contains(&ys) {
                    out[y * width + x] += c * src[ys as usize * width + x];
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The correlations at the samples, row by row from a ring of row passes, are the
    /// textbook sums bit for bit: any size (narrower or wider than the kernels), two
    /// channels whose inputs are zero outside random spans (some empty), three row
    /// passes and outputs of one and of two terms of any radii and signs, any samples,
    /// sequential or parallel in one band or several.
    #[test]
    fn correlations_at_samples_equal_the_textbook_loops(
        width in 1usize..50,
        // Past two bands of rows: split over threads when parallel.
        height in 1usize..150,
        radii in proptest::array::uniform6(0usize..30),
        seed in any::<u64>(),
        keep in 0.05f64..1.0,
        parallel in any::<bool>(),
    ) {
        let mut rng = Lcg(seed);
        let spans = random_spans(&mut rng, width, height);
        let mut src = vec![[0.0f32; 2]; width * height];
        for (y, &[a, b]) in spans.iter().enumerate() {
            for v in &mut src[y * width + a..y * width + b] {
                *v = [0; 2].map(|_| rng.uniform(-1.0, 1.0) as f32);
            }
        }
        let kernels: Vec<Vec<f32>> = radii
            .iter()
            .map(|&r| (0..2 * r + 1).map(|_| rng.uniform(-1.0, 1.0) as f32).collect())
            .collect();
        let samples: Vec<u32> = (0..(width * height) as u32).filter(|_| rng.unit() < keep).collect();
        let sample_rows = SampleRow::of_samples(&samples, width);
        let planes: [(usize, &[f32]); 3] = [(1, &kernels[0]), (0, &kernels[1]), (1, &kernels[2])];
        let first: &[(usize, &[f32])] = &[(2, &kernels[3])];
        let second: &[(usize, &[f32])] = &[(0, &kernels[4]), (1, &kernels[5])];
        let mut got = vec![[f32::NAN; 2]; samples.len()];
        let image = ImageRows { image: &src, width };
        at_samples(&image, width, &spans, &planes, [first, second], &sample_rows, &samples, &mut got, parallel);

        let passes: Vec<Vec<f32>> = planes
            .iter()
            .map(|&(c, kernel)| {
                let channel: Vec<f32> = src.iter().map(|v| v[c]).collect();
                reference_rows(&channel, width, kernel)
            })
            .collect();
        for (o, terms) in [first, second].into_iter().enumerate() {
            let mut expected = vec![0.0f32; width * height];
            for &(p, kernel) in terms {
                reference_add_columns(&passes[p], &mut expected, width, kernel);
            }
            for (g, &k) in got.iter().zip(&samples) {
                prop_assert_eq!(g[o].to_bits(), expected[k as usize].to_bits());
            }
        }
    }
}

/// A random span of each of `height` rows `width` pixels wide (some empty).
fn random_spans(rng: &mut Lcg, width: usize, height: usize) -> Vec<Span> {
    (0..height)
        .map(|_| {
            let a = (rng.unit() * width as f64) as usize;
            let b = a + (rng.unit() * (width - a + 1) as f64) as usize;
            [a, b.min(width)]
        })
        .collect()
}

/// A small deterministic generator for the tests' random inputs.
struct Lcg(u64);

impl Lcg {
    /// Uniform in `[0, 1)`.
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[a, b)`.
    fn uniform(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.unit()
    }
}
