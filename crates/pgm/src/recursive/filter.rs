//! The filters: the kernels ([`Shape`]) and their recursive approximations
//! ([`Recursive`]: a centre tap and second-order [`Section`]s), designed for each λ by
//! a least-squares fit of the sections' weights on fixed poles.

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
