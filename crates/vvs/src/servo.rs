//! [`Servo`]: the virtual visual servoing loop.

use std::time::Instant;

use brightness::{Against, Brightness, normal_equations, normal_equations_with_column};
use frame::{AnyImage, Frame, Image, PixelStatus, Restricted};
use glam::DVec3;
use pgm::{Pgm, PgmOptions};
use splat::{PointCloud, RenderOptions, Renderer};
use ucm::{Camera, Isometry3};

use crate::global::{MAX_CANDIDATES, PriorBox, SearchPhase, SearchProgress, SearchReport};
use crate::photometric::{MAX_COEFFICIENT, RadialVignetting};
use crate::solve::solve;
use crate::{
    Divergence, IterationRecord, Method, Outcome, Robust, StopReason, Support, VvsConfig, VvsError,
};

/// One stage of a method.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    Brightness,
    Pgm {
        lambda_star: f32,
        lambda_start: f32,
        optimise_lambda: bool,
    },
}

/// A stage with its step (1 or 2), pyramid level and iteration cap.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Planned {
    stage: Stage,
    step: u8,
    level: usize,
    /// Most iterations this stage may take; the step's last stage takes whatever the
    /// step's budget has left.
    cap: usize,
    last_of_step: bool,
    /// The stall test's window for this stage (`VvsConfig::stall_window`, or
    /// `intermediate_stall_window` for step 1's stages before a step 2).
    stall_window: usize,
}

/// How a stage ended: why, with which λ and cost, after how many iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StageResult {
    stop: StopReason,
    lambda: f32,
    cost: f64,
    iterations: usize,
}

/// The buffers of one pyramid level (level 0: full resolution).
#[derive(Debug)]
struct Level {
    camera: Camera,
    renderer: Renderer,
    frame: Frame,
    pgm: Pgm,
    brightness: Brightness,
    /// The vignetting model's basis, the corrected rendering, and the transform of its
    /// derivative pictures (used only with `VvsConfig::vignetting`).
    vignetting: RadialVignetting,
    corrected: Frame,
    derivative: Image,
    derivative_pgm: Pgm,
    /// With [`Support::Common`]: the desired picture's features on the pixels compared
    /// (taken again at every iteration), and those pixels.
    desired_pgm: Pgm,
    desired_brightness: Brightness,
    support: Vec<bool>,
    /// The desired picture as compared, at every pixel it observes, and those pixels.
    against: Vec<f32>,
    against_observed: Vec<bool>,
}

/// The widest intensity range of a desired image that holds nothing to align to (a
/// sixteenth of an 8-bit level).
const UNIFORM_INTENSITY_RANGE: f32 = 1.0 / (255.0 * 16.0);

/// The PGM's options of `config`, its brightness normalised or not.
fn pgm_options(config: &VvsConfig, normalize: bool) -> PgmOptions {
    PgmOptions {
        stride: config.pgm_stride,
        normalize,
        parallel: config.parallel,
        recursive_from_lambda: config.pgm_recursive(),
        interaction_row_step_lambdas: config.pgm_interaction_row_step(),
        ..PgmOptions::default()
    }
}

impl Level {
    fn new(camera: Camera, config: &VvsConfig) -> Result<Self, VvsError> {
        let options = RenderOptions {
            lod_spacing_px: config.lod_spacing_px,
            parallel: config.parallel,
            ..RenderOptions::default()
        };
        // The camera's pixel grid set up once, shared by every feature of the level.
        let brightness = Brightness::new(&camera).with_normalization(config.normalize);
        let pgm = |normalize| {
            Pgm::from_brightness(brightness.sharing_tables(), pgm_options(config, normalize))
        };
        Ok(Self {
            renderer: Renderer::new(camera.clone(), options)?,
            frame: Frame::for_camera(&camera),
            pgm: pgm(config.normalize)?,
            vignetting: RadialVignetting::new(&camera),
            corrected: Frame::for_camera(&camera),
            derivative: Image::new(camera.width(), camera.height()),
            derivative_pgm: pgm(false)?,
            desired_pgm: pgm(config.normalize)?,
            desired_brightness: brightness
                .sharing_tables()
                .with_normalization(config.normalize),
            brightness,
            support: vec![false; camera.pixel_count()],
            against: vec![0.0; camera.pixel_count()],
            against_observed: vec![false; camera.pixel_count()],
            camera,
        })
    }
}

/// The most pixels a camera may have for [`Servo`]: its buffers (renderings, features,
/// interaction rows, pyramid levels) take about [`SERVO_BYTES_PER_PIXEL`] bytes a pixel,
/// so 2²² pixels (2048 × 2048) take about 0.9 GB. Larger pictures are refused
/// ([`VvsError::TooManyPixels`]) rather than set up for minutes.
pub const MAX_SERVO_PIXELS: u64 = 1 << 22;

/// Set-up memory of [`Servo`] per camera pixel, bytes (measured: a 4096 × 4096 camera
/// took 3.7 GB).
pub const SERVO_BYTES_PER_PIXEL: u64 = 220;

/// A callback given a global search's progress ([`Servo::set_search_progress`]).
pub type SearchProgressFn = Box<dyn FnMut(SearchProgress) + Send>;

/// [`SearchProgressFn`], optional, shown by `Debug` as whether it is set.
struct ProgressHook(Option<SearchProgressFn>);

impl std::fmt::Debug for ProgressHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "ProgressHook({})",
            if self.0.is_some() { "set" } else { "unset" }
        )
    }
}

/// The optimiser for one cloud and camera, owning every buffer (no allocation per
/// iteration once warm).
#[derive(Debug)]
pub struct Servo<'a> {
    cloud: &'a PointCloud,
    camera: Camera,
    config: VvsConfig,
    levels: Vec<Level>,
    bounds: (DVec3, DVec3),
    desired: Vec<f32>,
    costs: Vec<f64>,
    residuals: Vec<f32>,
    weights: Vec<f32>,
    scratch: Vec<f32>,
    search_desired: Vec<f32>,
    search_weights: Vec<f32>,
    /// Per orientation: whether only some samples are compared (a tilt).
    search_masked: Vec<bool>,
    /// With [`Support::Common`]: the desired picture turned back by each orientation
    /// (its PGM is taken on each node's common support).
    search_pictures: Vec<Image>,
    /// With [`Support::Common`]: per orientation, the second screening score (the
    /// PGMs' mean squared difference over the compared samples, divided by the
    /// fraction of the picture compared) beside the correlation's in the costs.
    search_squared: Vec<f64>,
    /// Called as a global search goes on, when set.
    search_progress: ProgressHook,
    rows9: Vec<[f32; 9]>,
    columns: [Vec<f32>; 2],
    vignetting_start: [f64; 2],
}

impl<'a> Servo<'a> {
    /// An optimiser of poses of `camera` in `cloud`. Fails on an invalid configuration.
    pub fn new(
        cloud: &'a PointCloud,
        camera: &Camera,
        config: VvsConfig,
    ) -> Result<Self, VvsError> {
        config.validate()?;
        let pixels = u64::from(camera.width()) * u64::from(camera.height());
        if pixels > MAX_SERVO_PIXELS {
            return Err(VvsError::TooManyPixels {
                pixels,
                max: MAX_SERVO_PIXELS,
                bytes_per_pixel: SERVO_BYTES_PER_PIXEL,
            });
        }
        let mut levels = vec![Level::new(camera.clone(), &config)?];
        for k in 1..config.pyramid_levels {
            let coarse = camera.downsampled(1 << k).map_err(|e| VvsError::Config {
                name: "pyramid_levels",
                message: format!("level {k}: {e}"),
            })?;
            levels.push(Level::new(coarse, &config)?);
        }
        Ok(Self {
            cloud,
            camera: camera.clone(),
            levels,
            bounds: cloud.bounds(),
            config,
            desired: Vec::new(),
            costs: Vec::new(),
            residuals: Vec::new(),
            weights: Vec::new(),
            scratch: Vec::new(),
            search_desired: Vec::new(),
            search_weights: Vec::new(),
            search_masked: Vec::new(),
            search_pictures: Vec::new(),
            search_squared: Vec::new(),
            search_progress: ProgressHook(None),
            rows9: Vec::new(),
            columns: [Vec::new(), Vec::new()],
            vignetting_start: [0.0; 2],
        })
    }

    /// Where the vignetting coefficients start in the next runs (with
    /// [`VvsConfig::vignetting`]; default 0: no vignetting). A tracker passes each
    /// frame's estimate on to the next frame.
    pub fn set_vignetting_start(&mut self, coefficients: [f64; 2]) {
        self.vignetting_start = coefficients.map(|c| {
            if c.is_finite() {
                c.clamp(-MAX_COEFFICIENT, MAX_COEFFICIENT)
            } else {
                0.0
            }
        });
    }

    /// The configuration.
    pub fn config(&self) -> &VvsConfig {
        &self.config
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Render the cloud at `world_from_camera` (e.g. a desired image).
    pub fn render(&mut self, world_from_camera: &Isometry3) -> Result<Frame, VvsError> {
        let mut frame = Frame::for_camera(&self.camera);
        self.levels[0]
            .renderer
            .render(self.cloud, &world_from_camera.inverse(), &mut frame)?;
        Ok(frame)
    }

    /// The stages of a method: step 1 (coarse pyramid levels first, then the full
    /// resolution at λ*₁, then the λ schedule; or, coarse to fine, λ*₁ and the
    /// schedule each at its level), then step 2.
    fn stages(&self, method: Method) -> Vec<Planned> {
        let c = &self.config;
        if method == Method::Povs {
            return vec![Planned {
                stage: Stage::Brightness,
                step: 1,
                level: 0,
                cap: c.max_iterations,
                last_of_step: true,
                stall_window: c.stall_window,
            }];
        }
        let first_lambda_factor = if method == Method::Rule0 {
            c.rule0_lambda_factor
        } else {
            1.0
        };
        // (λ*, level) of step 1's stages.
        let step1: Vec<(f32, usize)> = match c.coarse_min_lambda_px {
            None => {
                let mut step1: Vec<(f32, usize)> = (1..c.pyramid_levels as usize)
                    .rev()
                    .map(|k| (c.lambda_star_step1 / (1u32 << k) as f32, k))
                    .collect();
                step1.push((c.lambda_star_step1, 0));
                step1.extend(c.lambda_schedule.iter().map(|&l| (l, 0)));
                step1
            }
            Some(min_lambda) => std::iter::once(c.lambda_star_step1)
                .chain(c.lambda_schedule.iter().copied())
                .map(|lambda| {
                    // The coarsest level at which λ* stays at least `min_lambda` (the
                    // full resolution if λ* itself is below it).
                    let level = (0..c.pyramid_levels as usize)
                        .rev()
                        .find(|&k| lambda / (1u32 << k) as f32 >= min_lambda)
                        .unwrap_or(0);
                    (lambda / (1u32 << level) as f32, level)
                })
                .collect(),
        };
        let n = step1.len();
        let mut planned: Vec<Planned> = step1
            .into_iter()
            .enumerate()
            .map(|(i, (lambda_star, level))| Planned {
                stage: Stage::Pgm {
                    lambda_star,
                    lambda_start: if i == 0 {
                        first_lambda_factor * lambda_star
                    } else {
                        lambda_star
                    },
                    optimise_lambda: true,
                },
                step: 1,
                level,
                cap: if i + 1 == n {
                    c.step1_max_iterations
                } else {
                    c.step1_max_iterations / n
                },
                last_of_step: i + 1 == n,
                stall_window: c.intermediate_stall_window.unwrap_or(c.stall_window),
            })
            .collect();
        planned.push(Planned {
            stage: Stage::Pgm {
                lambda_star: c.lambda_star_step2,
                lambda_start: c.lambda_star_step2,
                optimise_lambda: method == Method::Rule2,
            },
            step: 2,
            level: 0,
            cap: c.max_iterations - c.step1_max_iterations,
            last_of_step: true,
            stall_window: c.stall_window,
        });
        planned
    }

    /// Align: estimate the pose at which the cloud looks like `desired`, from
    /// `initial` (`world_from_camera`). Errors only on invalid input; divergence is
    /// reported in the outcome.
    pub fn run<D: AnyImage + Clone>(
        &mut self,
        method: Method,
        desired: &D,
        initial: Isometry3,
    ) -> Result<Outcome, VvsError> {
        let mut outcomes = self.run_methods(&[method], desired, initial)?;
        Ok(outcomes.pop().expect("one outcome per method"))
    }

    fn check_inputs(&self, desired: &impl AnyImage, initial: &Isometry3) -> Result<(), VvsError> {
        if desired.width() != self.camera.width() || desired.height() != self.camera.height() {
            return Err(VvsError::DesiredSize {
                got_width: desired.width(),
                got_height: desired.height(),
                width: self.camera.width(),
                height: self.camera.height(),
            });
        }
        if !initial.is_finite() {
            return Err(VvsError::NonFinitePose);
        }
        // A picture with nothing to align to (black, white, cut to one value) is an
        // input error, not a localisation that stalls at a pose.
        let (mut low, mut high, mut observed) = (f32::INFINITY, f32::NEG_INFINITY, 0usize);
        let intensity = desired.intensity();
        for (index, &valid) in self.camera.valid_pixels().iter().enumerate() {
            if valid && desired.is_observed(index) {
                let value = intensity[index];
                if !value.is_finite() {
                    return Err(VvsError::NonFiniteDesired { index });
                }
                low = low.min(value);
                high = high.max(value);
                observed += 1;
            }
        }
        if observed == 0 {
            return Err(VvsError::EmptyDesired);
        }
        if high - low <= UNIFORM_INTENSITY_RANGE {
            return Err(VvsError::UniformDesired {
                value: low,
                observed,
            });
        }
        Ok(())
    }

    /// Global localisation (beyond the paper, [`crate::global`]): the pose at which the
    /// cloud looks like `desired`, searched for in the `prior` region around `initial`
    /// (`world_from_camera`) with the settings of [`VvsConfig::global`] (whose own
    /// `prior` is ignored here). [`Method::Global`] is this call with that `prior`.
    pub fn localize_in_box<D: AnyImage + Clone>(
        &mut self,
        desired: &D,
        initial: Isometry3,
        prior: &PriorBox,
    ) -> Result<Outcome, VvsError> {
        // The callback of `set_search_progress`, if any (taken out while the search
        // borrows the servo, put back after).
        let mut hook = self.search_progress.0.take();
        let result = match &mut hook {
            Some(progress) => {
                self.localize_in_box_with_progress(desired, initial, prior, &mut **progress)
            }
            None => self.localize_in_box_with_progress(desired, initial, prior, &mut |_| ()),
        };
        self.search_progress.0 = hook;
        result
    }

    /// Call `progress` as every later global search of this servo goes on
    /// ([`Method::Global`] among [`Servo::run_methods`]' methods, or
    /// [`Servo::localize_in_box`]); `None` stops it.
    pub fn set_search_progress(&mut self, progress: Option<SearchProgressFn>) {
        self.search_progress.0 = progress;
    }

    /// [`Servo::localize_in_box`], calling `progress` after each node screened, each
    /// descent and each refinement (a search in a large box runs for seconds).
    pub fn localize_in_box_with_progress<D: AnyImage + Clone>(
        &mut self,
        desired: &D,
        initial: Isometry3,
        prior: &PriorBox,
        progress: &mut dyn FnMut(SearchProgress),
    ) -> Result<Outcome, VvsError> {
        let mut report = |phase, done, total| {
            progress(SearchProgress { phase, done, total });
        };
        self.check_inputs(desired, &initial)?;
        let settings = self.config.global.clone();
        let nodes = prior.grid(settings.grid_spacing_m)?;
        let factor = settings.search_downsampling;
        let lambda = self.config.lambda_star_step1 / factor as f32;
        if !pgm::LAMBDA_RANGE.contains(&lambda) {
            return Err(VvsError::Config {
                name: "global.search_downsampling",
                message: format!(
                    "λ*₁ at the search's resolution would be {lambda} px, outside [0.5, 40]"
                ),
            });
        }
        let started = Instant::now();
        let search = self.search_level()?;
        let desired_small = if factor == 1 {
            desired.clone()
        } else {
            desired.downsampled(factor, &self.levels[search].camera)?
        };

        // Screening: the cost of every node at low resolution, at every orientation
        // (heading × tilts: the desired image turned back by each, one after the other
        // in `search_desired`, the samples compared in `search_weights`).
        let tilts = [
            prior.tilts_rad(0, settings.tilt_spacing_deg)?,
            prior.tilts_rad(1, settings.tilt_spacing_deg)?,
        ];
        let heading_list = prior.headings_rad(settings.heading_spacing_deg)?;
        // Counted before anything is allocated for them.
        let orientation_count = heading_list
            .len()
            .saturating_mul(tilts[0].len())
            .saturating_mul(tilts[1].len());
        if nodes.len().saturating_mul(orientation_count) > MAX_CANDIDATES {
            return Err(VvsError::Config {
                name: "global.heading_spacing_deg",
                message: format!(
                    "{} positions × {orientation_count} orientations (headings × tilts) is more than {MAX_CANDIDATES} candidates",
                    nodes.len(),
                ),
            });
        }
        let orientations: Vec<[f64; 3]> = heading_list
            .into_iter()
            .flat_map(|h| {
                let tilts = &tilts;
                tilts[0]
                    .iter()
                    .flat_map(move |&x| tilts[1].iter().map(move |&y| [x, y, h]))
            })
            .collect();
        // The desired PGM and weights of every orientation are kept (8 bytes a sample):
        // at most 512 MB.
        let samples = self.levels[search].pgm.samples().len();
        if orientations.len().saturating_mul(samples) > 1 << 26 {
            return Err(VvsError::Config {
                name: "global.heading_spacing_deg",
                message: format!(
                    "{} orientations × {samples} samples at the search's resolution would hold more than 512 MB",
                    orientations.len()
                ),
            });
        }
        self.search_desired.clear();
        self.search_weights.clear();
        self.search_masked.clear();
        self.search_pictures.clear();
        let common = self.config.support == Support::Common;
        for &[x, y, heading] in &orientations {
            let level = &mut self.levels[search];
            let g_star = if [x, y, heading] == [0.0; 3] {
                if common {
                    let n = desired_small.intensity().len();
                    let mut observed = vec![false; n];
                    desired_small.observed(0..n, &mut observed);
                    self.search_pictures.push(Image::from_parts(
                        desired_small.width(),
                        desired_small.height(),
                        desired_small.intensity().to_vec(),
                        observed,
                    )?);
                }
                level.pgm.transform(&desired_small, lambda)?
            } else if [x, y] == [0.0; 2] {
                // A turn about the optical axis keeps the field: every sample compared
                // (its own formula, as measured before tilts were searched).
                let turned = crate::global::turned_about_optical_axis(
                    &desired_small,
                    &level.camera,
                    -heading,
                )?;
                if common {
                    self.search_pictures.push(turned.clone());
                }
                level.pgm.transform(&turned, lambda)?
            } else {
                // A tilted view loses part of the field: compare only the samples
                // farther than 2λ from what the turn leaves unobserved.
                let rotation = Isometry3::from_pose_vector([0.0, 0.0, 0.0, x, y, heading])?;
                let turned = crate::global::turned(
                    &desired_small,
                    &level.camera,
                    rotation.rotation.inverse(),
                )?;
                let radius = (2.0 * lambda).ceil() as usize;
                let clear = clear_of_missing(&level.camera, &turned.valid, radius);
                let at = self.search_weights.len();
                self.search_weights
                    .resize(at + level.pgm.samples().len(), 1.0);
                for (w, &k) in self.search_weights[at..]
                    .iter_mut()
                    .zip(level.pgm.samples())
                {
                    *w = if clear[k as usize] { 1.0 } else { 0.0 };
                }
                if common {
                    self.search_pictures.push(turned.clone());
                }
                level.pgm.transform(&turned, lambda)?
            };
            self.search_masked
                .push(self.search_weights.len() > self.search_desired.len());
            self.search_desired.extend_from_slice(g_star);
            self.search_weights.resize(self.search_desired.len(), 1.0);
        }
        let node_pose = |index: usize, orientation: usize| {
            let position = initial * Isometry3::from_translation(DVec3::from_array(nodes[index]));
            let [x, y, h] = orientations[orientation];
            match Isometry3::from_pose_vector([0.0, 0.0, 0.0, x, y, h]) {
                Ok(turn) if [x, y, h] != [0.0; 3] => position * turn,
                _ => position,
            }
        };
        let mut screened: Vec<(f64, usize, usize)> =
            Vec::with_capacity(nodes.len() * orientations.len());
        let mut squared: Vec<(f64, usize, usize)> = Vec::new();
        let mut costs = vec![f64::INFINITY; orientations.len()];
        self.search_squared.clear();
        self.search_squared
            .resize(orientations.len(), f64::INFINITY);
        let identity = orientations.iter().position(|o| *o == [0.0; 3]);
        for index in 0..nodes.len() {
            self.search_cost(search, &node_pose(index, 0), lambda, &mut costs)?;
            for (orientation, &cost) in costs.iter().enumerate() {
                if cost.is_finite() {
                    screened.push((cost, index, orientation));
                }
                if common && self.search_squared[orientation].is_finite() {
                    squared.push((self.search_squared[orientation], index, orientation));
                }
            }
            report(SearchPhase::Screening, index + 1, nodes.len());
        }
        let order = |a: &(f64, usize, usize), b: &(f64, usize, usize)| {
            a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2))
        };
        screened.sort_by(order);
        if common {
            // On the common support, the `screened` best by each score, in turn: the
            // correlation finds a photograph's pose where small smooth supports fool
            // the squared difference, which tells apart renderings whose PGMs differ
            // in contrast alone (either list alone loses poses the other finds).
            squared.sort_by(order);
            let target = 2 * settings.screened;
            let mut merged: Vec<(f64, usize, usize)> = Vec::with_capacity(target);
            let mut lists = [screened.iter(), squared.iter()];
            'merge: while merged.len() < target {
                let mut any = false;
                for list in &mut lists {
                    for &(score, index, orientation) in list.by_ref() {
                        any = true;
                        if !merged.iter().any(|m| (m.1, m.2) == (index, orientation)) {
                            merged.push((score, index, orientation));
                            break;
                        }
                    }
                    if merged.len() == target {
                        break 'merge;
                    }
                }
                if !any {
                    break;
                }
            }
            screened = merged;
        } else {
            screened.truncate(settings.screened);
        }

        let screening_s = started.elapsed().as_secs_f64();
        // Descents of the best, at low resolution.
        let planned = Planned {
            stage: Stage::Pgm {
                lambda_star: lambda,
                lambda_start: lambda,
                optimise_lambda: true,
            },
            step: 1,
            level: search,
            cap: settings.descent_iterations,
            last_of_step: true,
            stall_window: self.config.stall_window,
        };
        let mut descended: Vec<(f64, (usize, usize), Isometry3)> =
            Vec::with_capacity(screened.len());
        let mut descent_iterations = 0;
        let mut history = Vec::new();
        for (done, &(_, index, orientation)) in screened.iter().enumerate() {
            report(SearchPhase::Descents, done, screened.len());
            let mut pose = node_pose(index, orientation);
            history.clear();
            let mut coefficients = self.vignetting_start;
            let result = self.run_stage(
                planned,
                settings.descent_iterations,
                &desired_small,
                &mut pose,
                &mut coefficients,
                &mut history,
            )?;
            descent_iterations += result.iterations;
            // On the common support the descents are ranked by the screening's score
            // at their end (the unturned picture), not by their costs: those compare
            // pictures normalised over supports of different shapes.
            let rank = match (common, identity) {
                (true, Some(identity)) => {
                    self.search_cost(search, &pose, lambda, &mut costs)?;
                    costs[identity]
                }
                _ => result.cost,
            };
            // A descent that left the box (grown by a grid spacing and a few degrees)
            // found something else than the truth the box holds.
            let in_box = prior.holds(
                &initial,
                &pose,
                settings.grid_spacing_m,
                crate::global::BOX_MARGIN_DEG,
            );
            if !matches!(result.stop, StopReason::Diverged(_)) && rank.is_finite() && in_box {
                descended.push((rank, (index, orientation), pose));
            }
        }
        descended.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut kept: Vec<((usize, usize), Isometry3)> = Vec::with_capacity(settings.refined);
        for &(_, index, pose) in &descended {
            if kept.len() == settings.refined {
                break;
            }
            let duplicate = kept.iter().any(|(_, other)| {
                (pose.translation - other.translation).length() < settings.merge_distance_m
            });
            if !duplicate {
                kept.push((index, pose));
            }
        }
        if kept.is_empty() {
            // Every node diverged: refine the initial pose, which says how.
            kept.push(((usize::MAX, 0), initial));
        }

        let descents_s = started.elapsed().as_secs_f64() - screening_s;
        // Refinements at full resolution: the lowest final cost wins.
        let mut best: Option<(usize, Outcome)> = None;
        let mut refined_costs = Vec::with_capacity(kept.len());
        report(SearchPhase::Descents, screened.len(), screened.len());
        for (rank, &(_, pose)) in kept.iter().enumerate() {
            report(SearchPhase::Refinements, rank, kept.len());
            let mut outcome = self.run_methods(&[settings.refine_method], desired, pose)?;
            let outcome = outcome.pop().expect("one outcome per method");
            let cost = match outcome.stop {
                StopReason::Diverged(_) => f64::INFINITY,
                _ if outcome.cost.is_finite() => outcome.cost,
                _ => f64::INFINITY,
            };
            refined_costs.push(cost);
            let better = match &best {
                None => true,
                Some((r, _)) => cost < refined_costs[*r],
            };
            if better {
                best = Some((rank, outcome));
            }
        }
        report(SearchPhase::Refinements, kept.len(), kept.len());
        let (chosen_rank, mut outcome) = best.expect("at least one refinement");
        let (chosen, chosen_orientation) = kept[chosen_rank].0;
        let chosen_node_m = nodes.get(chosen).copied();
        outcome.search = Some(SearchReport {
            candidates: nodes.len() * orientations.len(),
            descents: screened.len(),
            refinements: kept.len(),
            descent_iterations,
            chosen_node_m,
            chosen_heading_deg: chosen_node_m
                .map(|_| orientations[chosen_orientation][2].to_degrees()),
            chosen_rank,
            refined_costs,
            phase_times_s: [screening_s, descents_s, 0.0],
        });
        outcome.time_s = started.elapsed().as_secs_f64();
        if let Some(search) = &mut outcome.search {
            search.phase_times_s[2] = outcome.time_s - screening_s - descents_s;
        }
        Ok(outcome)
    }

    /// The index of the global search's low-resolution level, built on first use.
    fn search_level(&mut self) -> Result<usize, VvsError> {
        let factor = self.config.global.search_downsampling;
        if factor == 1 {
            return Ok(0);
        }
        let index = self.config.pyramid_levels as usize;
        if self.levels.len() == index {
            let camera = self
                .camera
                .downsampled(factor)
                .map_err(|e| VvsError::Config {
                    name: "global.search_downsampling",
                    message: e.to_string(),
                })?;
            self.levels.push(Level::new(camera, &self.config)?);
        }
        Ok(index)
    }

    /// The mean squared PGM residual at `world_from_camera` on level `level` against
    /// each desired PGM of `self.search_desired` (one per orientation, into `costs`;
    /// infinite where the pose is outside the cloud's enlarged bounds or sees too
    /// little of it).
    fn search_cost(
        &mut self,
        level: usize,
        world_from_camera: &Isometry3,
        lambda: f32,
        costs: &mut [f64],
    ) -> Result<(), VvsError> {
        costs.fill(f64::INFINITY);
        if outside(
            self.bounds,
            self.config.bounds_margin_m,
            world_from_camera.translation,
        ) {
            return Ok(());
        }
        let Level {
            camera,
            renderer,
            frame,
            pgm,
            desired_pgm,
            support,
            ..
        } = &mut self.levels[level];
        let stats = renderer.render(self.cloud, &world_from_camera.inverse(), frame)?;
        let valid = camera.valid_pixel_count().max(1) as f64;
        if (stats.pixels_hit as f64) / valid < self.config.min_hit_fraction {
            return Ok(());
        }
        if self.config.support == Support::Common {
            // Each orientation on its own common support: the node's hits that the
            // turned picture observes.
            let samples = pgm.samples().len().max(1);
            for ((((cost, squared), picture), weights), &masked) in costs
                .iter_mut()
                .zip(self.search_squared.iter_mut())
                .zip(&self.search_pictures)
                .zip(self.search_weights.chunks_exact(samples))
                .zip(&self.search_masked)
            {
                for ((s, &o), status) in support.iter_mut().zip(&picture.valid).zip(&frame.status) {
                    *s = o && *status == PixelStatus::Hit;
                }
                let g = pgm.transform(&Restricted::new(&*frame, support)?, lambda)?;
                self.scratch.clear();
                self.scratch.extend_from_slice(g);
                let g_star = desired_pgm.transform(&Restricted::new(picture, support)?, lambda)?;
                // The two PGMs' correlation over the compared samples (scale-free, where
                // the mean squared difference depends on the support's shape), its
                // shortfall divided by the fraction of the picture compared.
                let (mut w_sum, mut a_sum, mut b_sum) = (0.0f64, 0.0f64, 0.0f64);
                let (mut aa, mut bb, mut ab) = (0.0f64, 0.0f64, 0.0f64);
                for (k, (&a, &b)) in self.scratch.iter().zip(g_star).enumerate() {
                    let w = if masked { f64::from(weights[k]) } else { 1.0 };
                    let (a, b) = (f64::from(a), f64::from(b));
                    w_sum += w;
                    a_sum += w * a;
                    b_sum += w * b;
                    aa += w * a * a;
                    bb += w * b * b;
                    ab += w * a * b;
                }
                let compared = support.iter().filter(|&&s| s).count() as f64;
                let observed = picture.valid.iter().filter(|&&v| v).count().max(1) as f64;
                let coverage = compared / observed;
                (*cost, *squared) = if w_sum > 0.0 && coverage > 0.0 {
                    let (ma, mb) = (a_sum / w_sum, b_sum / w_sum);
                    let (va, vb) = (aa / w_sum - ma * ma, bb / w_sum - mb * mb);
                    let correlation = (ab / w_sum - ma * mb) / (va * vb).sqrt().max(1e-30);
                    let mean_squared = (aa - 2.0 * ab + bb) / w_sum;
                    (
                        (1.0 - correlation) / coverage,
                        mean_squared.max(0.0) / coverage,
                    )
                } else {
                    (f64::INFINITY, f64::INFINITY)
                };
            }
            return Ok(());
        }
        let g = pgm.transform(frame, lambda)?;
        let n = g.len().max(1);
        for (((cost, desired), weights), &masked) in costs
            .iter_mut()
            .zip(self.search_desired.chunks_exact(n))
            .zip(self.search_weights.chunks_exact(n))
            .zip(&self.search_masked)
        {
            if !masked {
                let sum: f64 = g
                    .iter()
                    .zip(desired)
                    .map(|(&a, &b)| {
                        let e = f64::from(a - b);
                        e * e
                    })
                    .sum();
                *cost = sum / n as f64;
            } else {
                let (mut sum, mut count) = (0.0f64, 0.0f64);
                for ((&a, &b), &w) in g.iter().zip(desired).zip(weights) {
                    let e = f64::from(a - b);
                    sum += f64::from(w) * e * e;
                    count += f64::from(w);
                }
                *cost = if count > 0.0 {
                    sum / count
                } else {
                    f64::INFINITY
                };
            }
        }
        Ok(())
    }

    /// Align with several methods from the same `initial` pose: one outcome per method,
    /// each exactly what [`Servo::run`] returns for it. Methods whose step 1 is the same
    /// (Rule1 and Rule2) run it once: step 2 of each starts from the shared result,
    /// and each outcome's `time_s` counts the shared step in full.
    pub fn run_methods<D: AnyImage + Clone>(
        &mut self,
        methods: &[Method],
        desired: &D,
        initial: Isometry3,
    ) -> Result<Vec<Outcome>, VvsError> {
        if let [Method::Global] = methods {
            let prior = self.config.global.prior.clone();
            return Ok(vec![self.localize_in_box(desired, initial, &prior)?]);
        }
        if methods.contains(&Method::Global) {
            // The global search alone, the others together (sharing their step 1).
            let local: Vec<Method> = methods
                .iter()
                .copied()
                .filter(|&m| m != Method::Global)
                .collect();
            let mut local = self.run_methods(&local, desired, initial)?.into_iter();
            let global = self.run_methods(&[Method::Global], desired, initial)?;
            return Ok(methods
                .iter()
                .map(|&m| {
                    if m == Method::Global {
                        global[0].clone()
                    } else {
                        local.next().expect("one outcome per local method")
                    }
                })
                .collect());
        }
        self.check_inputs(desired, &initial)?;
        let rule0_start = self.config.rule0_lambda_factor * self.config.lambda_star_step1;
        if methods.contains(&Method::Rule0) && !pgm::LAMBDA_RANGE.contains(&rule0_start) {
            return Err(VvsError::Config {
                name: "rule0_lambda_factor",
                message: format!("Rule0 would start at λ = {rule0_start} px, outside [0.5, 40]"),
            });
        }
        // The desired image at each pyramid level.
        let pyramid = self.config.pyramid_levels as usize;
        let mut coarse_desired = Vec::with_capacity(pyramid - 1);
        for level in &self.levels[1..pyramid] {
            let factor = self.camera.width() / level.camera.width();
            coarse_desired.push(desired.downsampled(factor, &level.camera)?);
        }
        let mut step1_done: Vec<(Vec<Planned>, Outcome)> = Vec::new();
        let mut outcomes = Vec::with_capacity(methods.len());
        for &method in methods {
            let stages = self.stages(method);
            let budgets = if method == Method::Povs {
                [self.config.max_iterations, 0]
            } else {
                [
                    self.config.step1_max_iterations,
                    self.config.max_iterations - self.config.step1_max_iterations,
                ]
            };
            let split = stages
                .iter()
                .position(|p| p.step == 2)
                .unwrap_or(stages.len());
            let (step1, step2) = stages.split_at(split);
            let after_step1 = match step1_done.iter().find(|(plan, _)| plan == step1) {
                Some((_, outcome)) => outcome.clone(),
                None => {
                    let start = Outcome {
                        world_from_camera: initial,
                        lambda: 0.0,
                        cost: f64::NAN,
                        stop: StopReason::IterationBudget,
                        iterations: [0; 2],
                        history: Vec::new(),
                        time_s: 0.0,
                        vignetting: None,
                        search: None,
                    };
                    let outcome =
                        self.run_stages(step1, budgets, desired, &coarse_desired, start)?;
                    step1_done.push((step1.to_vec(), outcome.clone()));
                    outcome
                }
            };
            let outcome = if matches!(after_step1.stop, StopReason::Diverged(_)) {
                after_step1
            } else {
                self.run_stages(step2, budgets, desired, &coarse_desired, after_step1)?
            };
            outcomes.push(outcome);
        }
        Ok(outcomes)
    }

    /// Run `stages` from the state in `outcome` (pose, iterations so far), stopping at
    /// the first divergence.
    fn run_stages<D: AnyImage>(
        &mut self,
        stages: &[Planned],
        budgets: [usize; 2],
        desired: &D,
        coarse_desired: &[D],
        mut outcome: Outcome,
    ) -> Result<Outcome, VvsError> {
        for planned in stages {
            let started = Instant::now();
            let step = usize::from(planned.step - 1);
            let left = budgets[step] - outcome.iterations[step];
            let budget = if planned.last_of_step {
                left
            } else {
                planned.cap.min(left)
            };
            let level_desired = match planned.level {
                0 => desired,
                k => &coarse_desired[k - 1],
            };
            let mut coefficients = outcome.vignetting.unwrap_or(self.vignetting_start);
            let result = self.run_stage(
                *planned,
                budget,
                level_desired,
                &mut outcome.world_from_camera,
                &mut coefficients,
                &mut outcome.history,
            )?;
            if self.config.vignetting {
                outcome.vignetting = Some(coefficients);
            }
            outcome.iterations[step] += result.iterations;
            outcome.lambda = result.lambda;
            outcome.cost = result.cost;
            outcome.stop = result.stop;
            outcome.time_s += started.elapsed().as_secs_f64();
            if let StopReason::Diverged(_) = result.stop {
                break;
            }
        }
        Ok(outcome)
    }

    /// One stage, from `pose` (updated in place).
    fn run_stage(
        &mut self,
        planned: Planned,
        budget: usize,
        desired: &impl AnyImage,
        pose: &mut Isometry3,
        coefficients: &mut [f64; 2],
        history: &mut Vec<IterationRecord>,
    ) -> Result<StageResult, VvsError> {
        let Planned {
            stage,
            step: stage_number,
            level,
            stall_window,
            ..
        } = planned;
        let Level {
            camera,
            renderer,
            frame,
            pgm,
            brightness,
            vignetting,
            corrected,
            derivative,
            derivative_pgm,
            desired_pgm,
            desired_brightness,
            support,
            against,
            against_observed,
        } = &mut self.levels[level];
        let vignetting_on = self.config.vignetting;
        let common = self.config.support == Support::Common;
        // The desired feature, fixed for the stage (on the common support: taken again
        // at every iteration).
        let (mut lambda, optimise_lambda) = match stage {
            Stage::Brightness => {
                if !common {
                    brightness.compute(desired)?;
                    self.desired.clear();
                    self.desired.extend_from_slice(brightness.values());
                }
                (0.0, false)
            }
            Stage::Pgm {
                lambda_star,
                lambda_start,
                optimise_lambda,
            } => {
                if !common {
                    let g = pgm.transform(desired, lambda_star)?;
                    self.desired.clear();
                    self.desired.extend_from_slice(g);
                }
                (lambda_start, optimise_lambda)
            }
        };
        let valid_count = camera.valid_pixel_count().max(1) as f64;
        let mut initial_cost = None;
        // On the common support: the fraction of the picture's observed pixels compared.
        let mut coverage = 1.0f64;
        let mut cost = f64::NAN;
        self.costs.clear();
        for iteration in 0..budget {
            let started = Instant::now();
            let stats = renderer.render(self.cloud, &pose.inverse(), frame)?;
            let hits = stats.pixels_hit as f64;
            if hits / valid_count < self.config.min_hit_fraction {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::NoValidPixels),
                    lambda,
                    cost,
                    iterations: iteration,
                });
            }
            // The rendering as the camera would see it (with the vignetting model).
            let input: &Frame = if vignetting_on {
                vignetting.apply(*coefficients, frame, corrected);
                corrected
            } else {
                frame
            };
            // Feature, residuals, rows.
            if common {
                // The pixels compared: the rendering's hits the picture observes.
                desired.observed(0..support.len(), against_observed);
                for ((s, &o), status) in support
                    .iter_mut()
                    .zip(&*against_observed)
                    .zip(&frame.status)
                {
                    *s = o && *status == PixelStatus::Hit;
                }
                let desired_view = Restricted::new(desired, support)?;
                self.desired.clear();
                let normalized = match stage {
                    Stage::Brightness => {
                        desired_brightness.compute(&desired_view)?;
                        self.desired.extend_from_slice(desired_brightness.values());
                        &*desired_brightness
                    }
                    Stage::Pgm { lambda_star, .. } => {
                        self.desired
                            .extend_from_slice(desired_pgm.transform(&desired_view, lambda_star)?);
                        desired_pgm.brightness()
                    }
                };
                // The desired picture as compared, beyond the support too (where the
                // support's edge sweeps).
                let (mean, scale) = (
                    normalized.normalization_mean(),
                    f64::from(normalized.normalization_scale()),
                );
                for ((a, &i), &o) in against
                    .iter_mut()
                    .zip(desired.intensity())
                    .zip(&*against_observed)
                {
                    *a = if o {
                        ((f64::from(i) - mean) * scale) as f32
                    } else {
                        0.0
                    };
                }
                let compared = support.iter().filter(|&&s| s).count();
                let observed = against_observed.iter().filter(|&&o| o).count();
                coverage = compared as f64 / observed.max(1) as f64;
                let view = Restricted::new(input, support)?;
                let against = Against {
                    intensity: against,
                    observed: against_observed,
                };
                match stage {
                    Stage::Brightness => brightness.compute_against(&view, against)?,
                    Stage::Pgm { .. } => {
                        pgm.compute_against(&view, against, lambda, self.config.jacobian)?
                    }
                }
            } else {
                compute_feature(stage, brightness, pgm, input, lambda, self.config.jacobian)?;
            }
            let (values, pixel_weights): (&[f32], Option<&[f32]>) = match stage {
                Stage::Brightness => (brightness.values(), None),
                Stage::Pgm { .. } => (pgm.values(), Some(pgm.weights())),
            };
            if vignetting_on {
                // The columns of the coefficients: the feature of each derivative picture.
                let feature = match stage {
                    Stage::Brightness => &*brightness,
                    Stage::Pgm { .. } => pgm.brightness(),
                };
                let normalization = self
                    .config
                    .normalize
                    .then(|| (feature.normalization_scale(), feature.image()));
                for (k, column) in self.columns.iter_mut().enumerate() {
                    vignetting.derivative(
                        k,
                        frame,
                        feature.samples(),
                        feature.observed(),
                        normalization,
                        derivative,
                    );
                    column.clear();
                    match stage {
                        Stage::Brightness => column.extend(
                            feature
                                .samples()
                                .iter()
                                .map(|&s| derivative.intensity[s as usize]),
                        ),
                        Stage::Pgm { .. } => {
                            column.extend_from_slice(derivative_pgm.transform(derivative, lambda)?)
                        }
                    }
                }
            }
            let m = values.len();
            self.residuals.clear();
            self.residuals
                .extend(values.iter().zip(&self.desired).map(|(a, b)| a - b));
            self.weights.clear();
            match pixel_weights {
                Some(w) => self.weights.extend_from_slice(w),
                None => self.weights.resize(m, 1.0),
            }
            if let Some(Robust::Tukey { c }) = self.config.robust {
                tukey_weights(&self.residuals, c, &mut self.weights, &mut self.scratch);
            }
            // Both sums in one loop: each is a chain of dependent additions (in order,
            // from -0.0 as `Iterator::sum`), and two chains run side by side.
            debug_assert_eq!(self.residuals.len(), self.weights.len());
            let (mut weight_sum, mut weighted) = (-0.0f64, -0.0f64);
            for (&e, &w) in self.residuals.iter().zip(&self.weights) {
                weight_sum += f64::from(w);
                weighted += f64::from(w) * f64::from(e) * f64::from(e);
            }
            // On the common support the residuals are of pictures normalised over the
            // pixels compared, whatever their number: the cost is divided by the
            // fraction of the picture they cover, so that a pose that sees little of the
            // cloud does not look good for it (costs are compared between poses).
            cost = weighted / weight_sum.max(1.0) / coverage.max(1e-3);
            if !cost.is_finite() {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iterations: iteration,
                });
            }
            let reference = *initial_cost.get_or_insert(cost);
            if cost > self.config.divergence_cost_factor * reference.max(1e-30) {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::CostExploded),
                    lambda,
                    cost,
                    iterations: iteration,
                });
            }
            self.costs.push(cost);
            if stalled(
                &self.costs,
                stall_window,
                self.config.stall_relative_decrease,
            ) {
                return Ok(StageResult {
                    stop: StopReason::Stalled,
                    lambda,
                    cost,
                    iterations: iteration,
                });
            }
            // The update: x = −μ J⁺ e.
            let eta = self.config.levenberg_marquardt;
            let mut coefficient_update = [0.0; 2];
            let solution: Option<([f64; 6], f64)> = match stage {
                _ if vignetting_on => {
                    let (rows, j_lambda): (&[[f32; 6]], Option<&[f32]>) = match stage {
                        Stage::Brightness => (brightness.interaction(), None),
                        Stage::Pgm { .. } => {
                            (pgm.interaction(), optimise_lambda.then(|| pgm.j_lambda()))
                        }
                    };
                    self.rows9.clear();
                    self.rows9.extend(rows.iter().enumerate().map(|(s, l)| {
                        let j = j_lambda.map_or(0.0, |j| j[s]);
                        [
                            l[0],
                            l[1],
                            l[2],
                            l[3],
                            l[4],
                            l[5],
                            j,
                            self.columns[0][s],
                            self.columns[1][s],
                        ]
                    }));
                    let (jtj, jte) =
                        normal_equations::<9>(&self.rows9, &self.residuals, Some(&self.weights));
                    solve(&jtj, &jte, eta).map(|x| {
                        coefficient_update = [x[7], x[8]];
                        ([x[0], x[1], x[2], x[3], x[4], x[5]], x[6])
                    })
                }
                Stage::Pgm { .. } if optimise_lambda => {
                    // [L_G | J_λ], without joining them into rows of 7.
                    let (jtj, jte) = normal_equations_with_column::<6, 7>(
                        pgm.interaction(),
                        pgm.j_lambda(),
                        &self.residuals,
                        Some(&self.weights),
                    );
                    solve(&jtj, &jte, eta).map(|x| ([x[0], x[1], x[2], x[3], x[4], x[5]], x[6]))
                }
                _ => {
                    let rows = match stage {
                        Stage::Brightness => brightness.interaction(),
                        Stage::Pgm { .. } => pgm.interaction(),
                    };
                    let (jtj, jte) =
                        normal_equations::<6>(rows, &self.residuals, Some(&self.weights));
                    solve(&jtj, &jte, eta).map(|x| (x, 0.0))
                }
            };
            let Some((x, lambda_x)) = solution else {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::SingularSystem),
                    lambda,
                    cost,
                    iterations: iteration,
                });
            };
            let gain = self.config.gain;
            let v = x.map(|c| -gain * c);
            let lambda_dot = (-gain * lambda_x) as f32;
            let update_t = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let update_r = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5]).sqrt();
            if self.config.keep_history {
                history.push(IterationRecord {
                    stage: stage_number,
                    level: level as u8,
                    pose: pose.to_pose_vector(),
                    lambda,
                    cost,
                    update_translation_m: update_t,
                    update_rotation_rad: update_r,
                    time_s: started.elapsed().as_secs_f64(),
                });
            }
            let Ok(update) = Isometry3::exp(v) else {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iterations: iteration + 1,
                });
            };
            *pose = *pose * update;
            if vignetting_on {
                for (c, dc) in coefficients.iter_mut().zip(coefficient_update) {
                    *c = (*c - gain * dc).clamp(-MAX_COEFFICIENT, MAX_COEFFICIENT);
                }
            }
            if optimise_lambda {
                lambda = (lambda + lambda_dot)
                    .clamp(*pgm::LAMBDA_RANGE.start(), *pgm::LAMBDA_RANGE.end());
            }
            if !pose.is_finite() || !lambda.is_finite() {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iterations: iteration + 1,
                });
            }
            let position = pose.translation;
            if outside(self.bounds, self.config.bounds_margin_m, position) {
                return Ok(StageResult {
                    stop: StopReason::Diverged(Divergence::LeftBounds),
                    lambda,
                    cost,
                    iterations: iteration + 1,
                });
            }
            if update_t < self.config.converged_translation_m
                && update_r < self.config.converged_rotation_rad
                && lambda_dot.abs() < 1e-4
            {
                return Ok(StageResult {
                    stop: StopReason::Converged,
                    lambda,
                    cost,
                    iterations: iteration + 1,
                });
            }
        }
        Ok(StageResult {
            stop: StopReason::IterationBudget,
            lambda,
            cost,
            iterations: budget,
        })
    }
}

/// The feature of `picture` for `stage`: the brightness, or the PGM at `lambda`.
fn compute_feature(
    stage: Stage,
    brightness: &mut Brightness,
    pgm: &mut Pgm,
    picture: &impl AnyImage,
    lambda: f32,
    jacobian: pgm::PgmJacobian,
) -> Result<(), VvsError> {
    match stage {
        Stage::Brightness => brightness.compute(picture)?,
        Stage::Pgm { .. } => pgm.compute(picture, lambda, jacobian)?,
    }
    Ok(())
}

/// Whether `position` lies outside the box `bounds` (lowest, highest corner) enlarged by
/// `margin_m` on every side.
fn outside(bounds: (DVec3, DVec3), margin_m: f64, position: DVec3) -> bool {
    let margin = DVec3::splat(margin_m);
    position.cmplt(bounds.0 - margin).any() || position.cmpgt(bounds.1 + margin).any()
}

/// Whether the lowest cost of the last `window` iterations is not at least
/// `relative_decrease` below the lowest before them (`window` 0: never).
fn stalled(costs: &[f64], window: usize, relative_decrease: f64) -> bool {
    if window == 0 || costs.len() <= window {
        return false;
    }
    let (before, recent) = costs.split_at(costs.len() - window);
    let best_before = before.iter().copied().fold(f64::INFINITY, f64::min);
    let best_recent = recent.iter().copied().fold(f64::INFINITY, f64::min);
    best_recent > (1.0 - relative_decrease) * best_before
}

/// Tukey biweight: `w *= (1 − (e/(c σ))²)²` for `|e| < c σ`, else 0, with
/// `σ = 1.4826 × median(|e − median(e)|)`.
fn tukey_weights(residuals: &[f32], c: f32, weights: &mut [f32], scratch: &mut Vec<f32>) {
    scratch.clear();
    scratch.extend_from_slice(residuals);
    let mid = scratch.len() / 2;
    if scratch.is_empty() {
        return;
    }
    let median = *scratch.select_nth_unstable_by(mid, f32::total_cmp).1;
    for v in scratch.iter_mut() {
        *v = (*v - median).abs();
    }
    let mad = *scratch.select_nth_unstable_by(mid, f32::total_cmp).1;
    let threshold = c * 1.4826 * mad.max(1e-12);
    for (w, &e) in weights.iter_mut().zip(residuals) {
        let u = (e - median) / threshold;
        *w *= if u.abs() < 1.0 {
            (1.0 - u * u).powi(2)
        } else {
            0.0
        };
    }
}

/// Per pixel: valid and no valid-but-unobserved pixel within `radius` (a square window),
/// by a summed-area table of the missing pixels.
fn clear_of_missing(camera: &Camera, observed: &[bool], radius: usize) -> Vec<bool> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let valid = camera.valid_pixels();
    let mut table = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u32;
        for x in 0..w {
            let k = y * w + x;
            row += u32::from(valid[k] && !observed[k]);
            table[(y + 1) * (w + 1) + x + 1] = table[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius + 1).min(w));
            let missing = table[y1 * (w + 1) + x1] + table[y0 * (w + 1) + x0]
                - table[y0 * (w + 1) + x1]
                - table[y1 * (w + 1) + x0];
            out[y * w + x] = valid[y * w + x] && observed[y * w + x] && missing == 0;
        }
    }
    out
}
