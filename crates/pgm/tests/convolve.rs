//! The correlations against the textbook loops, bit for bit: skipping the zero inputs
//! outside each row's span and writing only the wanted spans changes no value.

use pgm::convolve::{
    ImageRows, SampleRow, Span, add_columns, at_samples, columns, columns_of, rows,
    rows_interleaved,
};
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

/// Adds the column correlation to every pixel of `out` at the rows `out_rows`.
fn reference_add_columns(
    src: &[f32],
    out: &mut [f32],
    width: usize,
    kernel: &[f32],
    out_rows: &[usize],
) {
    let height = src.len() / width;
    let r = (kernel.len() - 1) as isize / 2;
    for &y in out_rows {
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

    /// Any size (narrower or wider than the kernel), any kernel radius and sign, inputs
    /// zero outside random spans (some empty), sequential or parallel.
    #[test]
    fn correlations_equal_the_textbook_loops(
        width in 1usize..70,
        height in 1usize..40,
        radius in 0usize..30,
        seed in any::<u64>(),
        parallel in any::<bool>(),
        row_step in 1usize..4,
    ) {
        let mut rng = Lcg(seed);
        let spans = random_spans(&mut rng, width, height);
        let mut src = vec![0.0f32; width * height];
        for (y, &[a, b]) in spans.iter().enumerate() {
            for v in &mut src[y * width + a..y * width + b] {
                *v = rng.uniform(-1.0, 1.0) as f32;
            }
        }
        let kernel: Vec<f32> = (0..2 * radius + 1).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();

        let mut out = vec![0.0f32; src.len()];
        rows(&src, &mut out, width, &kernel, &spans, parallel);
        let expected = reference_rows(&src, width, &kernel);
        prop_assert!(out.iter().zip(&expected).all(|(a, b)| a.to_bits() == b.to_bits()));

        let out_rows: Vec<usize> = (0..height).step_by(row_step).collect();
        let wanted: Vec<(usize, Span)> = out_rows.iter().map(|&y| (y, spans[y])).collect();
        let base: Vec<f32> = (0..src.len()).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let in_spans = |got: &[f32], expected: &[f32]| {
            wanted.iter().all(|&(y, [a, b])| {
                (a..b).all(|x| got[y * width + x].to_bits() == expected[y * width + x].to_bits())
            })
        };

        let mut expected = base.clone();
        reference_add_columns(&src, &mut expected, width, &kernel, &out_rows);
        let mut got = base.clone();
        add_columns(&src, &mut got, width, height, &kernel, &wanted, parallel);
        prop_assert!(in_spans(&got, &expected));

        let mut expected = base.clone();
        for &y in &out_rows {
            expected[y * width..(y + 1) * width].fill(0.0);
        }
        reference_add_columns(&src, &mut expected, width, &kernel, &out_rows);
        let mut got = base;
        columns(&src, &mut got, width, height, &kernel, &wanted, parallel);
        prop_assert!(in_spans(&got, &expected));
    }

    /// The row passes of three channels together, and the column pass of each channel
    /// in their layout, give each channel's own passes' bits.
    #[test]
    fn interleaved_channels_equal_each_channel_alone(
        width in 1usize..50,
        height in 1usize..30,
        radius in 0usize..12,
        seed in any::<u64>(),
        parallel in any::<bool>(),
    ) {
        let mut rng = Lcg(seed);
        let spans = random_spans(&mut rng, width, height);
        let mut src = vec![[0.0f32; 3]; width * height];
        for (y, &[a, b]) in spans.iter().enumerate() {
            for v in &mut src[y * width + a..y * width + b] {
                *v = [0; 3].map(|_| rng.uniform(-1.0, 1.0) as f32);
            }
        }
        let kernel: Vec<f32> = (0..2 * radius + 1).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let wanted: Vec<(usize, Span)> = spans.iter().copied().enumerate().collect();
        let mut together = vec![f32::NAN; 3 * width * height];
        rows_interleaved(&src, &mut together, width, &kernel, &spans, parallel);
        for c in 0..3 {
            let channel: Vec<f32> = src.iter().map(|v| v[c]).collect();
            let mut alone = vec![0.0f32; width * height];
            rows(&channel, &mut alone, width, &kernel, &spans, parallel);
            for y in 0..height {
                let got = &together[(3 * y + c) * width..][..width];
                let expected = &alone[y * width..][..width];
                prop_assert!(got.iter().zip(expected).all(|(a, b)| a.to_bits() == b.to_bits()));
            }
            let mut expected = vec![1.0f32; width * height];
            columns(&alone, &mut expected, width, height, &kernel, &wanted, parallel);
            let mut got = vec![1.0f32; width * height];
            columns_of(&together, [c * width, 3 * width], &mut got, width, height, &kernel, &wanted, parallel);
            prop_assert!(got.iter().zip(&expected).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

    /// The correlations at the samples, row by row from a ring of row passes, give the
    /// bits of the whole-image passes at every sample: two channels, three row passes
    /// of any radii, outputs of one and of two terms of any column radii, any samples,
    /// in one band or several.
    #[test]
    fn correlations_at_samples_equal_the_whole_image_passes(
        width in 1usize..50,
        // Past two bands of rows: split over threads when parallel.
        height in 1usize..150,
        radii in proptest::array::uniform6(0usize..10),
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
                let mut out = vec![0.0f32; width * height];
                rows(&channel, &mut out, width, kernel, &spans, parallel);
                out
            })
            .collect();
        let wanted: Vec<(usize, Span)> = sample_rows.iter().map(|r| (r.y, r.span)).collect();
        let mut expected = [vec![f32::NAN; width * height], vec![f32::NAN; width * height]];
        for (out, terms) in expected.iter_mut().zip([first, second]) {
            for (i, &(p, kernel)) in terms.iter().enumerate() {
                if i == 0 {
                    columns(&passes[p], out, width, height, kernel, &wanted, parallel);
                } else {
                    add_columns(&passes[p], out, width, height, kernel, &wanted, parallel);
                }
            }
        }
        for (g, &k) in got.iter().zip(&samples) {
            for o in 0..2 {
                prop_assert_eq!(g[o].to_bits(), expected[o][k as usize].to_bits());
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
