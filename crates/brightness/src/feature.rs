//! [`Brightness`]: intensities of the valid pixels and their interaction matrix.

use std::sync::Arc;

use frame::AnyImage;
use ucm::{Camera, PixelGrid};

use crate::BrightnessError;
use crate::gradient::MaskedGradient;
use crate::photometric;

/// A camera's tables, set up once and shared by the features of that camera.
#[derive(Debug)]
struct Tables {
    grid: PixelGrid,
    gradient_plan: MaskedGradient,
    /// `[start, end)` row-major runs of valid pixels.
    valid_runs: Vec<[u32; 2]>,
    /// Per image row, its runs (indices in `valid_runs`: the runs end at the rows'
    /// ends), and per run, where its factors start in `factors_u` and `factors_v`.
    row_runs: Vec<[u32; 2]>,
    run_factors: Vec<u32>,
    /// The rows `[T_u | R_u]` and `[T_v | R_v]` of the valid pixels' factors
    /// ([`PixelGrid::factors`]), one run after the other: what the interaction rows
    /// read, contiguous.
    factors_u: Vec<[f32; 6]>,
    factors_v: Vec<[f32; 6]>,
    width: usize,
    height: usize,
    /// Row-major indices of the valid pixels.
    samples: Vec<u32>,
}

impl Tables {
    /// The valid runs as ranges of pixel indices: the samples, run by run.
    fn runs(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.valid_runs
            .iter()
            .map(|&[start, end]| start as usize..end as usize)
    }

    /// The photometric rows of valid run `i` into `out` (one per pixel of the run),
    /// from an image's gradient and inverse ranges.
    #[inline(always)]
    fn run_rows(
        &self,
        i: usize,
        gradient: &[[f32; 2]],
        inverse_range: &[f32],
        out: &mut [[f32; 6]],
    ) {
        let [start, stop] = self.valid_runs[i].map(|k| k as usize);
        let f = self.run_factors[i] as usize;
        photometric::rows(photometric::Run {
            u: &self.factors_u[f..f + out.len()],
            v: &self.factors_v[f..f + out.len()],
            gradient: &gradient[start..stop],
            inverse_range: &inverse_range[start..stop],
            out,
        });
    }
}

/// The picture a rendering is compared with on their common support
/// ([`Brightness::compute_against`]).
#[derive(Clone, Copy, Debug)]
pub struct Against<'a> {
    /// The picture's intensities as compared (centred and scaled like the rendering's
    /// when the brightness is normalised), at every pixel it observes, row-major.
    pub intensity: &'a [f32],
    /// Whether the picture holds an intensity at each pixel, row-major.
    pub observed: &'a [bool],
}

/// Pixels looked at together for the edge of the support's neighbours
/// ([`Brightness::compute_against`]).
const EDGE_BLOCK: usize = 64;

/// The brightness feature of one camera, with its buffers (no allocation per image).
#[derive(Debug, Clone)]
pub struct Brightness {
    /// The camera's tables, shared by the clones of a feature (a clone allocates its
    /// own buffers only).
    tables: Arc<Tables>,
    /// Whether each pixel of the last picture holds an intensity (false outside the
    /// region).
    observed: Vec<bool>,
    /// Whether every pixel of the region held one in the last picture.
    all_observed: bool,
    /// The gradient's plan of the last picture's observed pixels, when not all are.
    observed_gradient: MaskedGradient,
    /// With a picture compared against ([`Brightness::compute_against`]): the pixels
    /// both compare on (1) or not (0), and that picture's observed pixels.
    compared: Vec<f32>,
    against_observed: Vec<bool>,
    compared_gradient: Vec<[f32; 2]>,
    image: Vec<f32>,
    inverse_range: Vec<f32>,
    gradient: Vec<[f32; 2]>,
    pixel_interaction: Vec<[f32; 6]>,
    values: Vec<f32>,
    interaction: Vec<[f32; 6]>,
    normalize: bool,
    scale: f32,
    mean: f64,
}

impl Brightness {
    /// The feature for `camera`: one sample per valid pixel of its region.
    pub fn new(camera: &Camera) -> Self {
        let grid = PixelGrid::new(camera);
        let samples: Vec<u32> = grid
            .valid()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
            .map(|(k, _)| k as u32)
            .collect();
        let (width, height) = (camera.width() as usize, camera.height() as usize);
        let gradient_plan = MaskedGradient::new(grid.valid(), width, height);
        // Runs of consecutive valid pixels of one row (the samples in their order).
        let mut valid_runs: Vec<[u32; 2]> = Vec::new();
        for &k in &samples {
            match valid_runs.last_mut() {
                Some(run) if run[1] == k && !(k as usize).is_multiple_of(width) => run[1] += 1,
                _ => valid_runs.push([k, k + 1]),
            }
        }
        let mut row_runs = vec![[0u32; 2]; height];
        let mut run_factors = Vec::with_capacity(valid_runs.len());
        let mut first = 0;
        for (i, &[start, end]) in valid_runs.iter().enumerate() {
            let y = start as usize / width.max(1);
            if row_runs[y][1] == 0 {
                row_runs[y] = [i as u32, i as u32];
            }
            row_runs[y][1] = i as u32 + 1;
            run_factors.push(first);
            first += end - start;
        }
        let (factors_u, factors_v) = samples
            .iter()
            .map(|&k| photometric::factor_rows(&grid.factors()[k as usize]))
            .unzip();
        Self::with_tables(Arc::new(Tables {
            grid,
            gradient_plan,
            valid_runs,
            row_runs,
            run_factors,
            factors_u,
            factors_v,
            width,
            height,
            samples,
        }))
    }

    /// A feature of the same camera, with buffers of its own but sharing the camera's
    /// tables (its pixel grid, gradient plan and samples): [`Brightness::new`] without
    /// setting them up again. Not normalised.
    pub fn sharing_tables(&self) -> Self {
        Self::with_tables(Arc::clone(&self.tables))
    }

    /// The feature of these tables, its buffers allocated.
    fn with_tables(tables: Arc<Tables>) -> Self {
        let (n, m) = (tables.width * tables.height, tables.samples.len());
        Self {
            tables,
            observed: vec![false; n],
            all_observed: true,
            observed_gradient: MaskedGradient::default(),
            compared: Vec::new(),
            against_observed: Vec::new(),
            compared_gradient: Vec::new(),
            image: vec![0.0; n],
            inverse_range: vec![0.0; n],
            gradient: vec![[0.0; 2]; n],
            pixel_interaction: vec![[0.0; 6]; n],
            values: vec![0.0; m],
            interaction: vec![[0.0; 6]; m],
            normalize: false,
            scale: 1.0,
            mean: 0.0,
        }
    }

    /// Centre and normalise the brightness (zero mean, unit norm over the observed
    /// pixels of the region) before use, as the paper does for real images (§4). The
    /// interaction matrix is scaled by the same factor (the dependence of the mean and
    /// norm on the pose is neglected, as usual).
    pub fn with_normalization(mut self, normalize: bool) -> Self {
        self.normalize = normalize;
        self
    }

    /// Compute values and interaction matrix from a rendered frame or a measured image.
    /// Pixels not observed are ignored: intensity 0 (after normalisation), no gradient
    /// (the gradient is taken inside the observed pixels, one-sided at their edge, as
    /// at the region's); sky pixels, and every pixel of a measured image, have
    /// `1/ρ = 0`.
    pub fn compute(&mut self, picture: &impl AnyImage) -> Result<(), BrightnessError> {
        self.compute_pixels(picture, PixelRows::Stored)?;
        for (s, &k) in self.tables.samples.iter().enumerate() {
            self.values[s] = self.image[k as usize];
            self.interaction[s] = self.pixel_interaction[k as usize];
        }
        Ok(())
    }

    /// The per-pixel part of [`Brightness::compute`] only: [`Brightness::image`],
    /// [`Brightness::inverse_range`], [`Brightness::gradient`] and, as `rows` asks,
    /// [`Brightness::pixel_interaction`], what a feature of the whole image (the PGM)
    /// reads. [`Brightness::values`] and [`Brightness::interaction`] keep what the
    /// last [`Brightness::compute`] gave.
    pub fn compute_pixels(
        &mut self,
        picture: &impl AnyImage,
        rows: PixelRows,
    ) -> Result<(), BrightnessError> {
        let outputs = match rows {
            PixelRows::Stored => Outputs::Derivatives,
            PixelRows::OnDemand => Outputs::Gradient,
        };
        self.checked_pixels(picture, outputs)
    }

    /// The image part of [`Brightness::compute_pixels`] only: [`Brightness::image`]
    /// (normalised if enabled) and [`Brightness::observed`], the same values, without
    /// the inverse ranges, the gradient and the interaction rows (what a feature of a
    /// desired picture reads: its transform, not its derivative).
    /// [`Brightness::inverse_range`], [`Brightness::gradient`] and
    /// [`Brightness::pixel_interaction`] keep what the last computation with them gave.
    pub fn compute_image(&mut self, picture: &impl AnyImage) -> Result<(), BrightnessError> {
        self.checked_pixels(picture, Outputs::Image)
    }

    /// [`Brightness::pixels`] once the size is checked.
    fn checked_pixels(
        &mut self,
        picture: &impl AnyImage,
        outputs: Outputs,
    ) -> Result<(), BrightnessError> {
        if picture.width() as usize != self.tables.width
            || picture.height() as usize != self.tables.height
        {
            return Err(BrightnessError::ImageSize {
                got_width: picture.width(),
                got_height: picture.height(),
                width: self.tables.width as u32,
                height: self.tables.height as u32,
            });
        }
        // Every buffer a value per pixel (the pictures' buffers are public fields).
        picture.check_buffers()?;
        // Compiled for the widest instruction set found at run time, so that the plain
        // loops below are vectorised with it (the same operations: the same bits).
        isa::arch().dispatch(Pixels {
            brightness: self,
            picture,
            outputs,
        });
        Ok(())
    }

    /// [`Brightness::compute`] of a rendering compared with a picture on their common
    /// support (beyond the paper): `rendering` observes the pixels compared (the
    /// rendering's points that the picture sees, e.g. a `frame::Restricted` view),
    /// normalised over them as [`Brightness::compute`] does; `against` is the picture
    /// as compared. Values are the rendering's; the interaction rows are the
    /// derivative of the difference of the two on that support when the camera moves:
    /// the rendering moves with the scene and so does the edge of its points inside
    /// the picture's observed pixels, the picture does not, so the difference changes
    /// there by the two intensities' difference as the edge sweeps across the
    /// picture. The gradient is `∇(H R) − P ∇H` (`H` the pixels compared, `R` the
    /// rendering, `P` the picture, differences taken inside the picture's observed
    /// pixels); a pixel next to the edge outside it takes the mean inverse range of
    /// its neighbours inside (the edge's depth).
    pub fn compute_against(
        &mut self,
        rendering: &impl AnyImage,
        against: Against<'_>,
    ) -> Result<(), BrightnessError> {
        self.compute_pixels_against(rendering, against, PixelRows::Stored)?;
        for (s, &k) in self.tables.samples.iter().enumerate() {
            self.values[s] = self.image[k as usize];
            self.interaction[s] = self.pixel_interaction[k as usize];
        }
        Ok(())
    }

    /// The per-pixel part of [`Brightness::compute_against`] only (as
    /// [`Brightness::compute_pixels`] is of [`Brightness::compute`]).
    pub fn compute_pixels_against(
        &mut self,
        rendering: &impl AnyImage,
        against: Against<'_>,
        rows: PixelRows,
    ) -> Result<(), BrightnessError> {
        let n = self.tables.width * self.tables.height;
        for (what, got) in [
            ("picture compared against", against.intensity.len()),
            ("its observed pixels", against.observed.len()),
        ] {
            if got != n {
                return Err(BrightnessError::Length {
                    what,
                    got,
                    expected: n,
                });
            }
        }
        // The gradient and the rows are those of the edge of the support, below.
        self.checked_pixels(rendering, Outputs::Ranges)?;
        // Compiled for the widest instruction set found at run time (the same
        // operations: the same bits).
        isa::arch().dispatch(EdgeOfSupport {
            brightness: self,
            against,
            rows,
        });
        Ok(())
    }

    /// The interaction rows of [`Brightness::compute_against`], after
    /// [`Brightness::compute_image`] of the rendering on the compared pixels.
    #[inline(always)]
    fn edge_of_support(&mut self, against: Against<'_>, rows: PixelRows) {
        let (w, h, n) = (
            self.tables.width,
            self.tables.height,
            self.tables.width * self.tables.height,
        );
        let valid = self.tables.grid.valid();
        self.compared.clear();
        self.compared
            .extend(self.observed.iter().map(|&o| if o { 1.0 } else { 0.0 }));
        self.against_observed.clear();
        self.against_observed
            .extend(against.observed.iter().zip(valid).map(|(&a, &v)| a && v));
        // Both gradients are written at every pixel the picture observes, and read only
        // there (elsewhere the rows are 0, below): no need to clear them.
        self.compared_gradient.resize(n, [0.0; 2]);
        // ∇(H R) and ∇H, inside the picture's observed pixels.
        self.observed_gradient.rebuild(&self.against_observed, w, h);
        self.observed_gradient
            .compute(&self.image, &self.against_observed, &mut self.gradient);
        self.observed_gradient.compute(
            &self.compared,
            &self.against_observed,
            &mut self.compared_gradient,
        );
        // `∇(H R) − P ∇H` inside the picture's observed pixels, 0 outside, without a
        // branch (so that the loop vectorises).
        let pixels = self
            .gradient
            .iter_mut()
            .zip(&self.compared_gradient)
            .zip(against.intensity.iter().zip(&self.against_observed));
        for ((g, &[hu, hv]), (&p, &inside)) in pixels {
            let edge = [g[0] - p * hu, g[1] - p * hv];
            *g = if inside { edge } else { [0.0; 2] };
        }
        // Outside the compared pixels, next to them: the edge's inverse range (read
        // from compared pixels only, which this does not write: in any order). Only
        // where the picture observes a pixel the rendering does not (a few, near the
        // support's edge): looked for a block at a time, without a branch.
        for start in (0..n).step_by(EDGE_BLOCK) {
            let end = (start + EDGE_BLOCK).min(n);
            let outside = self.against_observed[start..end]
                .iter()
                .zip(&self.observed[start..end])
                .fold(false, |any, (&a, &o)| any | (a & !o));
            if !outside {
                continue;
            }
            for k in start..end {
                let [hu, hv] = self.compared_gradient[k];
                if self.against_observed[k] && !self.observed[k] && (hu != 0.0 || hv != 0.0) {
                    let (x, y) = (k % w, k / w);
                    let (mut sum, mut count) = (0.0f32, 0u32);
                    for (nx, ny) in [
                        (x.wrapping_sub(1), y),
                        (x + 1, y),
                        (x, y.wrapping_sub(1)),
                        (x, y + 1),
                    ] {
                        if nx < w && ny < h && self.observed[ny * w + nx] {
                            sum += self.inverse_range[ny * w + nx];
                            count += 1;
                        }
                    }
                    self.inverse_range[k] = if count > 0 { sum / count as f32 } else { 0.0 };
                }
            }
        }
        if rows == PixelRows::Stored {
            self.rows();
        }
    }

    /// The body of [`Brightness::compute_pixels`], [`Brightness::compute_image`] and
    /// of the start of [`Brightness::compute_pixels_against`], once the size is
    /// checked.
    #[inline(always)]
    fn pixels(&mut self, picture: &impl AnyImage, outputs: Outputs) {
        let valid = self.tables.grid.valid();
        let ranges = outputs >= Outputs::Ranges;
        let derivatives = outputs >= Outputs::Gradient;
        let rows = outputs == Outputs::Derivatives;
        if ranges {
            picture
                .inverse_range(&mut self.inverse_range)
                .expect("picture size and buffers checked above");
        }
        // The image is zero outside the valid pixels from the start and never written
        // there; the inverse ranges are zeroed between the valid runs.
        let mut end = 0;
        let mut all_observed = true;
        for run in self.tables.runs() {
            if ranges {
                self.inverse_range[end..run.start].fill(0.0);
            }
            picture.observed_intensity(run.clone(), &mut self.image[run.clone()]);
            picture.observed(run.clone(), &mut self.observed[run.clone()]);
            all_observed &= self.observed[run.clone()].iter().all(|&o| o);
            end = run.end;
        }
        if ranges {
            self.inverse_range[end..].fill(0.0);
        }
        self.all_observed = all_observed;
        self.scale = 1.0;
        self.mean = 0.0;
        if !all_observed {
            self.partly_observed(derivatives, rows);
            return;
        }
        if self.normalize {
            // The samples are the valid runs' pixels, in order: the sums read them run
            // by run (contiguous, not gathered), in the same order.
            let m = self.tables.samples.len().max(1) as f64;
            let samples = || self.tables.runs().flat_map(|run| &self.image[run]);
            let mean = samples().map(|&x| f64::from(x)).sum::<f64>() / m;
            let norm = samples()
                .map(|&x| (f64::from(x) - mean).powi(2))
                .sum::<f64>()
                .sqrt();
            let scale = if norm > 0.0 { 1.0 / norm } else { 1.0 };
            for run in self.tables.runs() {
                for x in &mut self.image[run] {
                    *x = ((f64::from(*x) - mean) * scale) as f32;
                }
            }
            self.scale = scale as f32;
            self.mean = mean;
        }
        if !derivatives {
            return;
        }
        // The gradient and the interaction rows are zero outside the region from the
        // start, and only the region is written.
        self.tables
            .gradient_plan
            .compute(&self.image, valid, &mut self.gradient);
        if rows {
            self.rows();
        }
    }

    /// [`Brightness::pixels`] for a picture that does not hold an intensity at every
    /// pixel of the region: the normalisation over the observed pixels only, the
    /// others 0, the gradient inside the observed pixels.
    #[inline(always)]
    fn partly_observed(&mut self, derivatives: bool, rows: bool) {
        if self.normalize {
            // Run by run, as in `pixels`.
            let (tables, image, observed) = (&self.tables, &self.image, &self.observed);
            let count = tables
                .runs()
                .map(|run| observed[run].iter().filter(|&&o| o).count())
                .sum::<usize>()
                .max(1) as f64;
            let samples = || {
                tables
                    .runs()
                    .flat_map(|run| image[run.clone()].iter().zip(&observed[run]))
                    .filter(|(_, o)| **o)
                    .map(|(&x, _)| f64::from(x))
            };
            let mean = samples().sum::<f64>() / count;
            let norm = samples().map(|x| (x - mean).powi(2)).sum::<f64>().sqrt();
            let scale = if norm > 0.0 { 1.0 / norm } else { 1.0 };
            for run in self.tables.runs() {
                let pixels = self.image[run.clone()].iter_mut().zip(&self.observed[run]);
                for (x, &o) in pixels {
                    let normalized = ((f64::from(*x) - mean) * scale) as f32;
                    *x = if o { normalized } else { 0.0 };
                }
            }
            self.scale = scale as f32;
            self.mean = mean;
        }
        if !derivatives {
            return;
        }
        self.observed_gradient
            .rebuild(&self.observed, self.tables.width, self.tables.height);
        self.observed_gradient
            .compute(&self.image, &self.observed, &mut self.gradient);
        for run in self.tables.runs() {
            let pixels = self.gradient[run.clone()]
                .iter_mut()
                .zip(&self.observed[run]);
            for (g, &o) in pixels {
                *g = if o { *g } else { [0.0; 2] };
            }
        }
        if rows {
            self.rows();
        }
    }

    /// Every valid pixel's interaction row from [`Brightness::gradient`] and
    /// [`Brightness::inverse_range`], run by run.
    #[inline(always)]
    fn rows(&mut self) {
        for (i, run) in self.tables.runs().enumerate() {
            let out = &mut self.pixel_interaction[run];
            self.tables
                .run_rows(i, &self.gradient, &self.inverse_range, out);
        }
    }

    /// The interaction rows of image row `y` into `out` (`width` of them; zero outside
    /// the region): what [`Brightness::pixel_interaction`] holds there after a
    /// computation that stores them, the same bits, from the last computation's
    /// gradient and inverse ranges (one with [`PixelRows::OnDemand`] too).
    ///
    /// # Panics
    /// If `y` is not a row of the image or `out` is not `width` long.
    pub fn interaction_row(&self, y: usize, out: &mut [[f32; 6]]) {
        let w = self.tables.width;
        assert!(
            y < self.tables.height && out.len() == w,
            "a row of the image"
        );
        out.fill([0.0; 6]);
        let [first, end] = self.tables.row_runs[y];
        for i in first as usize..end as usize {
            let [start, stop] = self.tables.valid_runs[i].map(|k| k as usize);
            let out = &mut out[start - y * w..stop - y * w];
            self.tables
                .run_rows(i, &self.gradient, &self.inverse_range, out);
        }
    }

    /// Whether each pixel held an intensity in the last picture (false outside the
    /// region), row-major.
    pub fn observed(&self) -> &[bool] {
        &self.observed
    }

    /// Whether every pixel of the region held an intensity in the last picture.
    pub fn all_observed(&self) -> bool {
        self.all_observed
    }

    /// Row-major pixel indices of the samples (the valid pixels).
    pub fn samples(&self) -> &[u32] {
        &self.tables.samples
    }

    /// Intensity of every sample (after normalisation if enabled).
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// Interaction matrix row `∂I/∂v` of every sample.
    pub fn interaction(&self) -> &[[f32; 6]] {
        &self.interaction
    }

    /// The whole image as used (masked to 0 outside the region, normalised if enabled).
    pub fn image(&self) -> &[f32] {
        &self.image
    }

    /// Every pixel's interaction row (zero outside the region), row-major.
    pub fn pixel_interaction(&self) -> &[[f32; 6]] {
        &self.pixel_interaction
    }

    /// Every pixel's masked image gradient `(∂I/∂u, ∂I/∂v)`, row-major.
    pub fn gradient(&self) -> &[[f32; 2]] {
        &self.gradient
    }

    /// Every pixel's inverse range (0 for sky and outside the region), row-major.
    pub fn inverse_range(&self) -> &[f32] {
        &self.inverse_range
    }

    /// Validity of every pixel (the camera's region minus pixels the model cannot
    /// invert).
    pub fn valid(&self) -> &[bool] {
        self.tables.grid.valid()
    }

    /// The camera's pixel grid.
    pub fn grid(&self) -> &PixelGrid {
        &self.tables.grid
    }

    /// Image width, pixels.
    pub fn width(&self) -> usize {
        self.tables.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> usize {
        self.tables.height
    }

    /// The factor applied by normalisation to the last image (1 without).
    pub fn normalization_scale(&self) -> f32 {
        self.scale
    }

    /// The mean subtracted by normalisation from the last image (0 without).
    pub fn normalization_mean(&self) -> f64 {
        self.mean
    }
}

/// [`Brightness::pixels`] as a `pulp` kernel (a struct with an inlined method, not a
/// closure: only what is inlined into `with_simd` is compiled for its instruction set).
struct Pixels<'a, P> {
    brightness: &'a mut Brightness,
    picture: &'a P,
    outputs: Outputs,
}

/// What [`Brightness::pixels`] computes, each with what the one before does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Outputs {
    /// The image (normalised if enabled) and the observed pixels.
    Image,
    /// And the inverse ranges.
    Ranges,
    /// And the gradient.
    Gradient,
    /// And the interaction rows.
    Derivatives,
}

/// Whether a per-pixel computation ([`Brightness::compute_pixels`],
/// [`Brightness::compute_pixels_against`]) stores every pixel's interaction row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelRows {
    /// Stored: [`Brightness::pixel_interaction`].
    Stored,
    /// Left to [`Brightness::interaction_row`], a row at a time where they are needed
    /// (a feature that filters them row by row: the PGM's exact `L_G`);
    /// [`Brightness::pixel_interaction`] keeps what the last computation with them
    /// gave.
    OnDemand,
}

/// [`Brightness::edge_of_support`] as a `pulp` kernel.
struct EdgeOfSupport<'a> {
    brightness: &'a mut Brightness,
    against: Against<'a>,
    rows: PixelRows,
}

impl pulp::WithSimd for EdgeOfSupport<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.brightness.edge_of_support(self.against, self.rows);
    }
}

impl<P: AnyImage> pulp::WithSimd for Pixels<'_, P> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.brightness.pixels(self.picture, self.outputs);
    }
}
