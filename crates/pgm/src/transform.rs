//! [`Pgm`]: the photometric Gaussian mixture of an omnidirectional image, its
//! λ-derivative and its interaction matrix, on a fixed sample grid.

use brightness::{Against, Brightness, PixelRows};
use frame::AnyImage;
use ucm::Camera;

use crate::PgmError;
use crate::convolve::{self, ImageRows, Kernels, RowSource, SampleRow, Span, Terms};
use crate::recursive::{self, Mode, Recursive, Scratch, Shape, Window};

/// Supported Gaussian extents, pixels.
pub const LAMBDA_RANGE: std::ops::RangeInclusive<f32> = 0.5..=40.0;

/// The widest truncated kernel accepted, in λ ([`PgmOptions::kernel_radius_lambdas`]).
pub const MAX_KERNEL_RADIUS_LAMBDAS: f32 = 64.0;

/// Which interaction matrix `L_G` to compute (`../shared/notes/math.md`): the one
/// Jacobian setting of the project (the optimiser's, the protocols'). Written by its
/// [`PgmJacobian::name`] in files (`"convolved"`, `"paper"`, `"paper-margin3"`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum PgmJacobian {
    /// The derivative of what is computed on the fixed pixel grid:
    /// `L_G = g_λ ⊛ (mask · L_I)`, six separable convolutions of the per-pixel
    /// photometric interaction rows (gradient inside the valid region, `1/ρ = 0` for
    /// sky).
    Convolved,
    /// The paper's eq. (5): `L_G(u_g) = −∇G(u_g)ᵀ ∂u_g/∂v`, the UCM interaction matrix at
    /// the sample with the sample's own rendered range. It treats the static edge of
    /// the mask as moving with the scene; samples closer to that edge than
    /// `edge_margin` × λ pixels get weight 0 when `edge_margin` is given (3 is where
    /// the notes' prototype saw eq. (5) agree with finite differences again).
    Paper {
        /// Drop samples within this many λ of the mask's edge.
        edge_margin: Option<f32>,
    },
}

impl PgmJacobian {
    /// Short name: `convolved`, `paper`, or `paper-margin<m>` with a margin of `m` λ.
    pub fn name(self) -> String {
        match self {
            PgmJacobian::Convolved => "convolved".into(),
            PgmJacobian::Paper { edge_margin: None } => "paper".into(),
            PgmJacobian::Paper {
                edge_margin: Some(m),
            } => format!("paper-margin{m}"),
        }
    }
}

impl std::fmt::Display for PgmJacobian {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

impl std::str::FromStr for PgmJacobian {
    type Err = PgmError;

    /// The Jacobian of a [`PgmJacobian::name`] (the margin finite and ≥ 0).
    fn from_str(text: &str) -> Result<Self, PgmError> {
        let text = text.trim();
        let bad = || PgmError::Option {
            name: "jacobian",
            message: format!("unknown Jacobian `{text}` (convolved, paper, paper-margin<m>)"),
        };
        match text {
            "convolved" => Ok(PgmJacobian::Convolved),
            "paper" => Ok(PgmJacobian::Paper { edge_margin: None }),
            _ => {
                let margin: f32 = text
                    .strip_prefix("paper-margin")
                    .and_then(|m| m.parse().ok())
                    .ok_or_else(bad)?;
                if !(margin >= 0.0 && margin.is_finite()) {
                    return Err(bad());
                }
                Ok(PgmJacobian::Paper {
                    edge_margin: Some(margin),
                })
            }
        }
    }
}

impl TryFrom<String> for PgmJacobian {
    type Error = PgmError;

    fn try_from(text: String) -> Result<Self, PgmError> {
        text.parse()
    }
}

impl From<PgmJacobian> for String {
    fn from(jacobian: PgmJacobian) -> String {
        jacobian.name()
    }
}

/// Options of the transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PgmOptions {
    /// Kernel radius in units of λ (rounded up to whole pixels), in `[1, 64]`. Default
    /// 4: the truncated tail weighs `exp(−8) ≈ 3.4e−4` of the peak.
    pub kernel_radius_lambdas: f32,
    /// Sample every `stride`-th pixel in both directions (1: every pixel). The values
    /// (and `J_λ`, `L_G`) at the kept samples are exactly those of the full grid (the
    /// whole image still enters every sum; tested); what changes is the number of
    /// residuals, `stride²` times fewer. For a large λ the mixture varies over about λ
    /// pixels, so a stride well below λ keeps its information; the cost of the vertical
    /// passes of the truncated kernels falls by the stride (the recursive filters always
    /// filter the whole image, so there the stride saves only the solve).
    pub stride: u32,
    /// Centre and normalise the brightness (zero mean, unit norm over the valid
    /// pixels) before the transform, as the paper does for real images (§4).
    pub normalize: bool,
    /// Spread the convolutions over rayon's threads (the result is the same either
    /// way; turn it off when the caller already keeps every thread busy). Default true.
    /// The recursive passes run on one thread.
    pub parallel: bool,
    /// From this λ (pixels) up, correlate with recursive filters
    /// ([`crate::recursive`]: a cost per pixel independent of λ, no truncation, kernels
    /// within 2.2e-4 of their peak of the exact ones for λ ≤ 40) instead of the kernels
    /// truncated at `kernel_radius_lambdas` · λ; infinite: always the truncated
    /// kernels. Default 3: below it the truncated kernels (at most 25 taps) are as
    /// cheap, and step 2 of the paper's rules (λ ≈ 1) is computed exactly as before.
    pub recursive_from_lambda: f32,
    /// On the recursive path of [`PgmJacobian::Convolved`], `L_G`'s vertical pass keeps
    /// one row in `max(1, ⌊q λ⌋)` (`q` this value) and the samples interpolate
    /// between the kept rows: the six channels of `L_I`, smoothed over λ pixels
    /// vertically, vary little over `q λ` rows: cubics through four kept rows are within
    /// 1.5e-4 of their peak at λ = 15, 3.1e-4 at λ = 40 (tested; the recursive filters'
    /// own error), where a line between two was 20 times worse. Only the Jacobian is
    /// approximated: `G` and `J_λ`, hence the cost and the optimum, are exact. 0:
    /// every row. Default 0.2: one row in 3 at λ = 15, every row below λ = 10.
    pub interaction_row_step_lambdas: f32,
}

impl Default for PgmOptions {
    fn default() -> Self {
        Self {
            kernel_radius_lambdas: 4.0,
            stride: 1,
            normalize: false,
            parallel: true,
            recursive_from_lambda: 3.0,
            interaction_row_step_lambdas: 0.2,
        }
    }
}

/// The PGM feature of one camera, with its buffers (no allocation per image once the
/// largest λ has been seen).
#[derive(Debug, Clone)]
pub struct Pgm {
    brightness: Brightness,
    options: PgmOptions,
    width: usize,
    height: usize,
    samples: Vec<u32>,
    /// The rows of the samples.
    sample_rows: Vec<SampleRow>,
    /// Per image row, the columns spanned by its valid pixels (the image and `L_I` are
    /// zero elsewhere).
    row_spans: Vec<Span>,
    /// The bounding box of the valid region: the image and `L_I` are zero outside
    /// it, and every sample is inside it, so the recursive passes compute it alone.
    window: Window,
    edge_distance_px: Vec<f32>,
    kernels: Kernels,
    filters: Option<Filters>,
    scratch: Scratch,
    /// Per sample, its index in the transposed plane (`x · height + y`).
    transposed: Vec<u32>,
    /// Per sample, where it lies between the rows kept by `L_G`'s vertical pass, for
    /// the row step `interpolation_step`.
    interpolation: Vec<Between>,
    interpolation_step: usize,
    /// Interleaved six-channel planes of the recursive `L_G` (allocated on first use;
    /// the exact path needs no plane, [`convolve::at_samples`]).
    lanes: Vec<[f32; 6]>,
    lanes_t: Vec<[f32; 6]>,
    // Full-image planes of the recursive path.
    h_g: Vec<f32>,
    h_k2g: Vec<f32>,
    h_dg: Vec<f32>,
    plane: Vec<f32>,
    out: Vec<f32>,
    out2: Vec<f32>,
    // Per-sample outputs.
    values: Vec<f32>,
    j_lambda: Vec<f32>,
    interaction: Vec<[f32; 6]>,
    /// The exact path's outputs at the samples before they are split (`G`, `J_λ` and
    /// eq. (5)'s `∇G`).
    per_sample: Vec<[f32; 4]>,
    weights: Vec<f32>,
    /// ∇G at the samples (eq. 5).
    gradient: Vec<[f32; 2]>,
}

/// The brightness's interaction rows `L_I`, computed a row at a time
/// ([`Brightness::interaction_row`]).
struct Interaction<'a>(&'a Brightness);

impl RowSource<6> for Interaction<'_> {
    #[inline(always)]
    fn row<'a>(&'a self, y: usize, buffer: &'a mut [[f32; 6]]) -> &'a [[f32; 6]] {
        self.0.interaction_row(y, buffer);
        buffer
    }
}

/// How a run of samples is interpolated from the rows kept by `L_G`'s vertical pass:
/// samples of one image row at consecutive pixels share the cubic through four
/// consecutive kept rows around that row (the run's first pixel in the first of them
/// as a pixel of the packed plane of kept rows, `j · width + x`), by its Lagrange
/// weights.
#[derive(Clone, Copy, Debug)]
struct Between {
    /// The run's first sample.
    sample: u32,
    /// Its number of samples.
    len: u32,
    pixel: u32,
    weights: [f32; 4],
}

/// The samples' `L_G` interpolated from the packed plane of kept rows, a
/// [`crate::simd::Kernel`] (compiled for the widest instruction set): per run, one
/// weighted sum of four stretches of rows, element by element, so that the loop
/// runs over whole registers.
struct Interpolate<'a> {
    out: &'a mut [[f32; 6]],
    between: &'a [Between],
    plane: &'a [[f32; 6]],
    width: usize,
}

impl crate::simd::Kernel for Interpolate<'_> {
    #[inline(always)]
    fn run<S: pulp::Simd>(self, _: S) {
        let width = self.width;
        for run in self.between {
            let (k, len) = (run.pixel as usize, run.len as usize);
            let s = run.sample as usize;
            let w = run.weights;
            let row = |j: usize| self.plane[k + j * width..][..len].as_flattened();
            let (a, b, c, d) = (row(0), row(1), row(2), row(3));
            let out = self.out[s..s + len].as_flattened_mut();
            for ((((o, a), b), c), d) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
                *o = w[0] * a + w[1] * b + w[2] * c + w[3] * d;
            }
        }
    }
}

/// The runs of samples (row-major pixel indices in an image `width` wide, in
/// row-major order) and their cubic between the rows `[r0, r1)` kept every `step`
/// and the last (`kept` ≥ 4 of them, [`recursive::kept_rows`]): the kept rows
/// `j − 1 … j + 2` around their row, shifted inside at the ends (error `O(step⁴)` of
/// the fourth derivative; a line between two rows would leave `O(step²)`).
fn interpolation(
    samples: &[u32],
    width: usize,
    [r0, r1]: [usize; 2],
    step: usize,
    kept: usize,
) -> Vec<Between> {
    // The rows `r0 + j · step` (`j < regular`), then the last row if off that grid.
    let regular = (r1 - 1 - r0) / step + 1;
    let row = |j: usize| if j < regular { r0 + j * step } else { r1 - 1 } as f64;
    let mut runs: Vec<Between> = Vec::new();
    for (i, &k) in samples.iter().enumerate() {
        if let Some(run) = runs.last_mut()
            && i > 0
            && k == samples[i - 1] + 1
            && !(k as usize).is_multiple_of(width)
        {
            run.len += 1;
            continue;
        }
        let (x, y) = (k as usize % width, k as usize / width);
        let first = ((y - r0) / step).saturating_sub(1).min(kept - 4);
        let rows: [f64; 4] = std::array::from_fn(|i| row(first + i));
        let y = y as f64;
        let weights = std::array::from_fn(|i| {
            (0..4)
                .filter(|&m| m != i)
                .map(|m| (y - rows[m]) / (rows[i] - rows[m]))
                .product::<f64>() as f32
        });
        runs.push(Between {
            sample: i as u32,
            len: 1,
            pixel: (first * width + x) as u32,
            weights,
        });
    }
    runs
}

impl Pgm {
    /// The feature for `camera`. Samples are the valid pixels on the stride lattice.
    pub fn new(camera: &Camera, options: PgmOptions) -> Result<Self, PgmError> {
        Self::from_brightness(Brightness::new(camera), options)
    }

    /// [`Pgm::new`] for the camera of `brightness` (a [`Brightness::new`] of it, or one
    /// sharing its tables: [`Brightness::sharing_tables`]), whose normalisation is set
    /// to `options.normalize`.
    pub fn from_brightness(brightness: Brightness, options: PgmOptions) -> Result<Self, PgmError> {
        // At most MAX_KERNEL_RADIUS_LAMBDAS: the kernels are allocated from it (a
        // Gaussian is below 1e-300 of its peak by 38 standard deviations).
        if !(1.0..=MAX_KERNEL_RADIUS_LAMBDAS).contains(&options.kernel_radius_lambdas) {
            return Err(PgmError::Option {
                name: "kernel_radius_lambdas",
                message: format!(
                    "must be in [1, {MAX_KERNEL_RADIUS_LAMBDAS}], got {}",
                    options.kernel_radius_lambdas
                ),
            });
        }
        let l = options.recursive_from_lambda;
        if !(l > 0.0) {
            return Err(PgmError::Option {
                name: "recursive_from_lambda",
                message: format!("must be > 0 (infinite: never), got {l}"),
            });
        }
        let q = options.interaction_row_step_lambdas;
        if !(q >= 0.0 && q.is_finite()) {
            return Err(PgmError::Option {
                name: "interaction_row_step_lambdas",
                message: format!("must be >= 0 (0: every row) and finite, got {q}"),
            });
        }
        if options.stride == 0 {
            return Err(PgmError::Option {
                name: "stride",
                message: "must be >= 1".into(),
            });
        }
        let brightness = brightness.with_normalization(options.normalize);
        let (width, height) = (brightness.width(), brightness.height());
        let s = options.stride as usize;
        let valid = brightness.valid();
        let samples: Vec<u32> = (0..height)
            .step_by(s)
            .flat_map(|j| (0..width).step_by(s).map(move |i| j * width + i))
            .filter(|&k| valid[k])
            .map(|k| k as u32)
            .collect();
        let sample_rows = SampleRow::of_samples(&samples, width);
        let row_spans: Vec<Span> = valid
            .chunks_exact(width)
            .map(
                |row| match (row.iter().position(|&v| v), row.iter().rposition(|&v| v)) {
                    (Some(a), Some(b)) => [a, b + 1],
                    _ => [0, 0],
                },
            )
            .collect();
        // The bounding box of the rows' spans (empty if no pixel is valid).
        let mut window = Window {
            columns: [width, 0],
            rows: [height, 0],
        };
        for (y, &[first, end]) in row_spans.iter().enumerate().filter(|(_, s)| s[1] > 0) {
            window.columns = [window.columns[0].min(first), window.columns[1].max(end)];
            window.rows = [window.rows[0].min(y), y + 1];
        }
        if window.rows[0] >= window.rows[1] {
            window = Window::whole(0, 0);
        }
        let edge_distance_px = edge_distance(valid, width, height);
        let n = width * height;
        let m = samples.len();
        let transposed = samples
            .iter()
            .map(|&k| ((k as usize % width) * height + k as usize / width) as u32)
            .collect();
        Ok(Self {
            brightness,
            options,
            width,
            height,
            samples,
            sample_rows,
            row_spans,
            window,
            edge_distance_px,
            kernels: Kernels::default(),
            filters: None,
            scratch: Scratch::default(),
            transposed,
            interpolation: Vec::new(),
            interpolation_step: 0,
            lanes: Vec::new(),
            lanes_t: Vec::new(),
            h_g: vec![0.0; n],
            h_k2g: vec![0.0; n],
            h_dg: vec![0.0; n],
            plane: vec![0.0; n],
            out: vec![0.0; n],
            out2: vec![0.0; n],
            values: vec![0.0; m],
            j_lambda: vec![0.0; m],
            interaction: vec![[0.0; 6]; m],
            per_sample: vec![[0.0; 4]; m],
            weights: vec![1.0; m],
            gradient: vec![[0.0; 2]; m],
        })
    }

    fn check_lambda(lambda: f32) -> Result<(), PgmError> {
        if LAMBDA_RANGE.contains(&lambda) {
            Ok(())
        } else {
            Err(PgmError::Lambda(lambda))
        }
    }

    /// The kernels of `lambda`, recomputed in place (taken out of `self` so that the
    /// buffers can be borrowed beside them; put back by the caller).
    fn kernels(&mut self, lambda: f32) -> Kernels {
        let radius = (self.options.kernel_radius_lambdas * lambda).ceil() as usize;
        let mut k = std::mem::take(&mut self.kernels);
        k.set(lambda, radius.max(1));
        k
    }

    /// The recursive filters of `lambda` if the options ask for them at this λ: `g`,
    /// and `k² g` and `(k/λ²) g` if asked for (each a least-squares fit: designed once
    /// per λ, and only when a path needs it).
    fn filters(&mut self, lambda: f32, with_k2g: bool, with_dg: bool) -> Option<Filters> {
        if !self.recursive(lambda) {
            return None;
        }
        let mut filters = match self.filters {
            Some(f) if f.lambda == lambda => f,
            _ => Filters::new(lambda),
        };
        if with_k2g && filters.k2g.is_none() {
            filters.k2g = Some(Recursive::new(Shape::SquaredOffset, lambda));
        }
        if with_dg && filters.dg.is_none() {
            filters.dg = Some(Recursive::new(Shape::Derivative, lambda));
        }
        self.filters = Some(filters);
        Some(filters)
    }

    /// `G(I, λ)` at the samples only (for the desired image).
    pub fn transform(&mut self, picture: &impl AnyImage, lambda: f32) -> Result<&[f32], PgmError> {
        Self::check_lambda(lambda)?;
        self.brightness.compute_image(picture)?;
        if let Some(f) = self.filters(lambda, false, false) {
            self.recursive_g_j(&f, false);
            return Ok(&self.values);
        }
        let k = self.kernels(lambda);
        convolve::at_samples(
            &ImageRows {
                image: self.brightness.image().as_chunks::<1>().0,
                width: self.width,
            },
            self.width,
            &self.row_spans,
            &[(0, &k.g)],
            [&[(0, &k.g)]],
            &self.sample_rows,
            &self.samples,
            self.values.as_chunks_mut::<1>().0,
            self.options.parallel,
        );
        self.kernels = k;
        Ok(&self.values)
    }

    /// `G`, `J_λ = ∂G/∂λ` and the interaction matrix `L_G` at the samples.
    pub fn compute(
        &mut self,
        picture: &impl AnyImage,
        lambda: f32,
        jacobian: PgmJacobian,
    ) -> Result<(), PgmError> {
        Self::check_lambda(lambda)?;
        let rows = self.pixel_rows(lambda, jacobian);
        self.brightness.compute_pixels(picture, rows)?;
        self.features(lambda, jacobian)
    }

    /// [`Pgm::compute`] of a rendering compared with a picture on their common support
    /// (beyond the paper): the brightness of
    /// [`brightness::Brightness::compute_against`], whose interaction rows follow the
    /// edge of the support as the camera moves; the Convolved `L_G` is then the
    /// derivative of the difference of the two pictures' `G` on that support.
    pub fn compute_against(
        &mut self,
        rendering: &impl AnyImage,
        against: Against<'_>,
        lambda: f32,
        jacobian: PgmJacobian,
    ) -> Result<(), PgmError> {
        Self::check_lambda(lambda)?;
        let rows = self.pixel_rows(lambda, jacobian);
        self.brightness
            .compute_pixels_against(rendering, against, rows)?;
        self.features(lambda, jacobian)
    }

    /// Whether the features at `lambda` take the recursive path
    /// ([`PgmOptions::recursive_from_lambda`]).
    fn recursive(&self, lambda: f32) -> bool {
        lambda >= self.options.recursive_from_lambda
    }

    /// Whether the features at `lambda` read the brightness's stored interaction rows:
    /// only the recursive `L_G` does; the exact one filters them a row at a time as it
    /// computes them, eq. (5) reads none.
    fn pixel_rows(&self, lambda: f32, jacobian: PgmJacobian) -> PixelRows {
        if self.recursive(lambda) && jacobian == PgmJacobian::Convolved {
            PixelRows::Stored
        } else {
            PixelRows::OnDemand
        }
    }

    /// `G`, `J_λ` and `L_G` of the brightness's last picture.
    fn features(&mut self, lambda: f32, jacobian: PgmJacobian) -> Result<(), PgmError> {
        let paper = matches!(jacobian, PgmJacobian::Paper { .. });
        if let Some(f) = self.filters(lambda, true, paper) {
            self.recursive_g_j(&f, true);
            match jacobian {
                PgmJacobian::Convolved => self.recursive_convolved(&f),
                PgmJacobian::Paper { edge_margin } => {
                    self.recursive_gradient(&f);
                    self.paper_interaction(lambda, edge_margin);
                }
            }
            return Ok(());
        }
        let k = self.kernels(lambda);
        let par = self.options.parallel;
        let image = &ImageRows {
            image: self.brightness.image().as_chunks::<1>().0,
            width: self.width,
        };
        // The row passes of the image: g, k² g and, for eq. (5), (k/λ²) g.
        let planes: [(usize, &[f32]); 3] = [(0, &k.g), (0, &k.k2g), (0, &k.dg)];
        // G = g_rows g_cols; J_λ = (1/λ³) [ (k² g)_rows g_cols + g_rows (k² g)_cols ].
        let g: Terms<'_> = &[(0, &k.g)];
        let j: Terms<'_> = &[(1, &k.g), (0, &k.k2g)];
        let inv_l3 = 1.0 / (lambda * lambda * lambda);
        match jacobian {
            PgmJacobian::Convolved => {
                let m = self.samples.len();
                let gj = &mut self.per_sample.as_flattened_mut().as_chunks_mut::<2>().0[..m];
                let (w, spans, rows) = (self.width, &self.row_spans, &self.sample_rows);
                let (planes, samples) = (&planes[..2], &self.samples);
                convolve::at_samples(image, w, spans, planes, [g, j], rows, samples, gj, par);
                let per_sample = self.values.iter_mut().zip(&mut self.j_lambda).zip(gj);
                for ((v, jl), &mut [gs, js]) in per_sample {
                    (*v, *jl) = (gs, js * inv_l3);
                }
                // Six separable convolutions of the masked per-pixel rows L_I, each row
                // of L_I computed once, as the row passes need it.
                let li = &Interaction(&self.brightness);
                let planes: [(usize, &[f32]); 6] = std::array::from_fn(|c| (c, &k.g[..]));
                let terms: [[(usize, &[f32]); 1]; 6] = std::array::from_fn(|c| [(c, &k.g[..])]);
                let outputs: [Terms<'_>; 6] = std::array::from_fn(|c| &terms[c][..]);
                convolve::at_samples(
                    li,
                    w,
                    spans,
                    &planes,
                    outputs,
                    rows,
                    samples,
                    &mut self.interaction,
                    par,
                );
                self.weights.fill(1.0);
            }
            PgmJacobian::Paper { edge_margin } => {
                // ∇G at the samples: ∂G/∂u = (dg rows, g cols), ∂G/∂v = (g rows, dg cols).
                let du: Terms<'_> = &[(2, &k.g)];
                let dv: Terms<'_> = &[(0, &k.dg)];
                let out = &mut self.per_sample[..];
                convolve::at_samples(
                    image,
                    self.width,
                    &self.row_spans,
                    &planes,
                    [g, j, du, dv],
                    &self.sample_rows,
                    &self.samples,
                    out,
                    par,
                );
                let per_sample = self
                    .values
                    .iter_mut()
                    .zip(&mut self.j_lambda)
                    .zip(&mut self.gradient)
                    .zip(out.iter());
                for (((v, jl), gr), &[gs, js, gu, gv]) in per_sample {
                    (*v, *jl, *gr) = (gs, js * inv_l3, [gu, gv]);
                }
                self.paper_interaction(lambda, edge_margin);
            }
        }
        self.kernels = k;
        Ok(())
    }

    /// Eq. (5) at the samples from `self.gradient` (∇G at each sample).
    fn paper_interaction(&mut self, lambda: f32, edge_margin: Option<f32>) {
        let factors = self.brightness.grid().factors();
        let inverse_range = self.brightness.inverse_range();
        for (((l, &s), wgt), &g) in self
            .interaction
            .iter_mut()
            .zip(&self.samples)
            .zip(&mut self.weights)
            .zip(&self.gradient)
        {
            let s = s as usize;
            *l = factors[s].photometric(g, inverse_range[s]);
            *wgt = match edge_margin {
                Some(m) if self.edge_distance_px[s] < m * lambda => 0.0,
                _ => 1.0,
            };
        }
    }

    /// Recursive path: `G` (and `J_λ` if `with_j`; `f` then has `k² g`) at the samples.
    /// Columns first (`h_g = g_cols ⊛ I`, `h_k2g = (k² g)_cols ⊛ I`), then the planes
    /// are transposed (into `out`, `out2`) so that the row pass is a column pass too;
    /// samples are read at their transposed index.
    fn recursive_g_j(&mut self, f: &Filters, with_j: bool) {
        let (w, h) = (self.width, self.height);
        let (win, win_t) = (self.window, self.window.transposed());
        let image = self.brightness.image();
        let sc = &mut self.scratch;
        recursive::columns(image, &mut self.h_g, w, win, &f.g, Mode::Write, sc);
        recursive::transpose_f32(&self.h_g, &mut self.out, w, h, win);
        // G = g_rows ⊛ h_g, computed down the columns of the transposed plane.
        recursive::columns(&self.out, &mut self.plane, h, win_t, &f.g, Mode::Write, sc);
        for (v, &t) in self.values.iter_mut().zip(&self.transposed) {
            *v = self.plane[t as usize];
        }
        let (true, Some(k2g)) = (with_j, f.k2g) else {
            return;
        };
        // J_λ λ³ = (k² g)_rows ⊛ h_g + g_rows ⊛ h_k2g.
        recursive::columns(image, &mut self.h_k2g, w, win, &k2g, Mode::Write, sc);
        recursive::transpose_f32(&self.h_k2g, &mut self.out2, w, h, win);
        recursive::columns(&self.out, &mut self.plane, h, win_t, &k2g, Mode::Write, sc);
        recursive::columns(&self.out2, &mut self.plane, h, win_t, &f.g, Mode::Add, sc);
        let inv_l3 = 1.0 / (f.lambda * f.lambda * f.lambda);
        for (j, &t) in self.j_lambda.iter_mut().zip(&self.transposed) {
            *j = self.plane[t as usize] * inv_l3;
        }
    }

    /// Recursive path of [`PgmJacobian::Convolved`]: the six channels of `L_I`
    /// filtered together (interleaved), columns then rows (keeping one row in `step`
    /// of the column pass, [`PgmOptions::interaction_row_step_lambdas`]).
    fn recursive_convolved(&mut self, f: &Filters) {
        let (w, h) = (self.width, self.height);
        let n = w * h;
        self.lanes.resize(n, [0.0; 6]);
        self.lanes_t.resize(n, [0.0; 6]);
        let win = self.window;
        let step = ((self.options.interaction_row_step_lambdas * f.lambda) as usize).max(1);
        // At least four kept rows for the cubic (else every row).
        let step = if recursive::kept_rows(win.rows, step) < 4 {
            1
        } else {
            step
        };
        let sc = &mut self.scratch;
        let li = self.brightness.pixel_interaction().as_flattened();
        let lanes = self.lanes.as_flattened_mut();
        if step == 1 {
            recursive::columns(li, lanes, 6 * w, win.interleaved(6), &f.g, Mode::Write, sc);
            recursive::transpose(&self.lanes, &mut self.lanes_t, w, h, win);
            let (src, dst) = (self.lanes_t.as_flattened(), self.lanes.as_flattened_mut());
            let win_t = win.transposed().interleaved(6);
            recursive::columns(src, dst, 6 * h, win_t, &f.g, Mode::Write, sc);
            for (l, &t) in self.interaction.iter_mut().zip(&self.transposed) {
                *l = self.lanes[t as usize];
            }
        } else {
            // The kept rows, packed, then transposed: `kept` rows of `w` pixels.
            let kept = recursive::kept_rows(win.rows, step);
            recursive::columns_every(li, lanes, 6 * w, win.interleaved(6), &f.g, step, sc);
            let packed = Window {
                columns: win.columns,
                rows: [0, kept],
            };
            recursive::transpose(&self.lanes, &mut self.lanes_t, w, kept, packed);
            let (src, dst) = (self.lanes_t.as_flattened(), self.lanes.as_flattened_mut());
            let win_t = packed.transposed().interleaved(6);
            recursive::columns(src, dst, 6 * kept, win_t, &f.g, Mode::Write, sc);
            // Back to rows (`kept` rows of `w` pixels), so that the samples, in
            // row-major order, read each kept row's pixels in order (strided reads of
            // the transposed plane waited on memory).
            let back = Window {
                columns: [0, kept],
                rows: win.columns,
            };
            recursive::transpose(&self.lanes, &mut self.lanes_t, kept, w, back);
            if self.interpolation_step != step {
                self.interpolation = interpolation(&self.samples, w, win.rows, step, kept);
                self.interpolation_step = step;
            }
            crate::simd::on_widest(Interpolate {
                out: &mut self.interaction,
                between: &self.interpolation,
                plane: &self.lanes_t,
                width: w,
            });
        }
        self.weights.fill(1.0);
    }

    /// Recursive path of ∇G at the samples into `self.gradient` (after
    /// [`Pgm::recursive_g_j`], whose transposed `h_g` is in `out`):
    /// `∂G/∂u = dg_rows ⊛ h_g`, `∂G/∂v = g_rows ⊛ (dg_cols ⊛ I)`.
    fn recursive_gradient(&mut self, f: &Filters) {
        let Some(dg) = f.dg else {
            return; // not asked for (compute asks for it on this path)
        };
        let (w, h) = (self.width, self.height);
        let (win, win_t) = (self.window, self.window.transposed());
        let sc = &mut self.scratch;
        recursive::columns(&self.out, &mut self.plane, h, win_t, &dg, Mode::Write, sc);
        let image = self.brightness.image();
        recursive::columns(image, &mut self.h_dg, w, win, &dg, Mode::Write, sc);
        recursive::transpose_f32(&self.h_dg, &mut self.out2, w, h, win);
        recursive::columns(&self.out2, &mut self.h_k2g, h, win_t, &f.g, Mode::Write, sc);
        for (g, &t) in self.gradient.iter_mut().zip(&self.transposed) {
            *g = [self.plane[t as usize], self.h_k2g[t as usize]];
        }
    }

    /// Row-major pixel indices of the samples.
    pub fn samples(&self) -> &[u32] {
        &self.samples
    }

    /// `G` at the samples (from the last call).
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// `J_λ = ∂G/∂λ` at the samples (from the last [`Pgm::compute`]).
    pub fn j_lambda(&self) -> &[f32] {
        &self.j_lambda
    }

    /// `L_G` rows at the samples (from the last [`Pgm::compute`]).
    pub fn interaction(&self) -> &[[f32; 6]] {
        &self.interaction
    }

    /// Weight of every sample (0 for samples dropped near the mask's edge by
    /// [`PgmJacobian::Paper`] with a margin, 1 otherwise).
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Distance of every pixel to the nearest pixel outside the valid region (or
    /// outside the image), pixels (chamfer 3-4 approximation of the Euclidean
    /// distance).
    pub fn edge_distance_px(&self) -> &[f32] {
        &self.edge_distance_px
    }

    /// The brightness stage (the masked, possibly normalised image and its gradient).
    pub fn brightness(&self) -> &Brightness {
        &self.brightness
    }

    /// The brightness stage, to compute the brightness feature of the same camera and
    /// normalisation with its buffers (as an optimiser running PoVS and PGM stages in
    /// turn does, without a second set of buffers). The PGM's next computation
    /// overwrites what it holds.
    pub fn brightness_mut(&mut self) -> &mut Brightness {
        &mut self.brightness
    }

    /// The options.
    pub fn options(&self) -> &PgmOptions {
        &self.options
    }
}

/// The recursive filters of the three kernels at one λ (`k² g` and `(k/λ²) g` once a
/// path has needed them).
#[derive(Clone, Copy, Debug)]
struct Filters {
    lambda: f32,
    g: Recursive,
    k2g: Option<Recursive>,
    dg: Option<Recursive>,
}

impl Filters {
    fn new(lambda: f32) -> Self {
        Self {
            lambda,
            g: Recursive::new(Shape::Gaussian, lambda),
            k2g: None,
            dg: None,
        }
    }
}

/// Chamfer (3-4) distance of every valid pixel to the nearest invalid pixel, the image
/// border counting as invalid.
fn edge_distance(valid: &[bool], width: usize, height: usize) -> Vec<f32> {
    let big = u32::MAX / 4;
    let mut d: Vec<u32> = valid.iter().map(|&v| if v { big } else { 0 }).collect();
    let at = |i: isize, j: isize| -> Option<usize> {
        (i >= 0 && j >= 0 && (i as usize) < width && (j as usize) < height)
            .then(|| j as usize * width + i as usize)
    };
    // Forward pass.
    for j in 0..height as isize {
        for i in 0..width as isize {
            let k = at(i, j).unwrap_or(0);
            if d[k] == 0 {
                continue;
            }
            let mut best = d[k];
            for (di, dj, c) in [(-1, 0, 3), (0, -1, 3), (-1, -1, 4), (1, -1, 4)] {
                best = best.min(at(i + di, j + dj).map_or(c, |n| d[n] + c));
            }
            d[k] = best;
        }
    }
    // Backward pass.
    for j in (0..height as isize).rev() {
        for i in (0..width as isize).rev() {
            let k = at(i, j).unwrap_or(0);
            if d[k] == 0 {
                continue;
            }
            let mut best = d[k];
            for (di, dj, c) in [(1, 0, 3), (0, 1, 3), (1, 1, 4), (-1, 1, 4)] {
                best = best.min(at(i + di, j + dj).map_or(c, |n| d[n] + c));
            }
            d[k] = best;
        }
    }
    d.into_iter().map(|v| v as f32 / 3.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs of samples interpolate each sample as its own cubic would, bit for
    /// bit: the per-sample cubic between the four kept rows around its row, read from
    /// the packed plane of kept rows (every lattice, both ends of the rows' range).
    #[test]
    fn runs_interpolate_every_sample_as_its_own_cubic() {
        let root = test_support::workspace_root();
        let camera = Camera::load_toml(root.join("fixtures/omni-320x240.toml")).unwrap();
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let mut frame = frame::Frame::for_camera(&camera);
        for y in 0..h {
            for x in 0..w {
                let k = y * w + x;
                if camera.valid_pixels()[k] {
                    let (u, v) = (x as f32, y as f32);
                    frame.intensity[k] = 0.5 + 0.3 * (u / 7.0 + (v / 11.0).sin()).sin();
                    frame.range_m[k] = 3.0 + 0.05 * u + 0.02 * v;
                    frame.status[k] = frame::PixelStatus::Hit;
                }
            }
        }
        for stride in [1, 2, 3] {
            let options = PgmOptions {
                stride,
                parallel: false,
                ..PgmOptions::default()
            };
            let mut pgm = Pgm::new(&camera, options).unwrap();
            for lambda in [15.0f32, 40.0] {
                pgm.compute(&frame, lambda, PgmJacobian::Convolved).unwrap();
                let step = pgm.interpolation_step;
                assert!(step > 1, "λ {lambda}: rows kept every {step}");
                let [r0, r1] = pgm.window.rows;
                let kept = recursive::kept_rows([r0, r1], step);
                let regular = (r1 - 1 - r0) / step + 1;
                let row = |j: usize| if j < regular { r0 + j * step } else { r1 - 1 } as f64;
                let runs: u32 = pgm.interpolation.iter().map(|r| r.len).sum();
                assert_eq!(runs as usize, pgm.samples.len());
                for (i, &k) in pgm.samples.iter().enumerate() {
                    let (x, y) = (k as usize % w, k as usize / w);
                    let first = ((y - r0) / step).saturating_sub(1).min(kept - 4);
                    let rows: [f64; 4] = std::array::from_fn(|i| row(first + i));
                    let weights: [f32; 4] = std::array::from_fn(|i| {
                        (0..4)
                            .filter(|&m| m != i)
                            .map(|m| (y as f64 - rows[m]) / (rows[i] - rows[m]))
                            .product::<f64>() as f32
                    });
                    let p = |j: usize| pgm.lanes_t[(first + j) * w + x];
                    let [a, b, c, d] = [p(0), p(1), p(2), p(3)];
                    let expected: [f32; 6] = std::array::from_fn(|c_| {
                        weights[0] * a[c_]
                            + weights[1] * b[c_]
                            + weights[2] * c[c_]
                            + weights[3] * d[c_]
                    });
                    let bits = |v: [f32; 6]| v.map(f32::to_bits);
                    assert_eq!(
                        bits(pgm.interaction[i]),
                        bits(expected),
                        "stride {stride} λ {lambda} sample {i} at ({x}, {y})"
                    );
                }
            }
        }
    }
}
