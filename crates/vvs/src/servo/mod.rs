//! [`Servo`]: the virtual visual servoing loop of the local methods (PoVS and the
//! paper's PGM rules): a method is a plan of stages ([`stage::plan`]), each a loop of
//! render, feature, update ([`Servo::run_stage`]), on the buffers of a pyramid level
//! ([`Level`]). The global search ([`crate::global`]) drives the same stages.

mod level;
mod stage;
mod warp;

use std::sync::Arc;
use std::time::Instant;

use frame::{AnyImage, Frame};
use glam::DVec3;
use splat::PointCloud;
use ucm::{Camera, Isometry3};

pub(crate) use level::{Level, render_once};
pub(crate) use stage::{Planned, Stage, StageResult, outside};

use crate::vignetting::MAX_COEFFICIENT;
use crate::{Method, Outcome, StopReason, VvsConfig, VvsError};

/// The widest intensity range of a desired image that holds nothing to align to (a
/// sixteenth of an 8-bit level).
const UNIFORM_INTENSITY_RANGE: f32 = 1.0 / (255.0 * 16.0);

/// Pixels of the desired picture checked at a time ([`Servo::check_inputs`]).
const CHECK_BLOCK: usize = 256;

/// The most pixels a camera may have for [`Servo`]: its buffers (renderings, features,
/// interaction rows, pyramid levels) take about [`SERVO_BYTES_PER_PIXEL`] bytes a pixel,
/// so 2²² pixels (2048 × 2048) take about 1 GB. Larger pictures are refused
/// ([`VvsError::TooManyPixels`]) rather than set up for minutes.
pub const MAX_SERVO_PIXELS: u64 = 1 << 22;

/// Set-up memory of [`Servo`] per camera pixel, bytes (measured: a 4096 × 4096 camera
/// took 3.7 GB, one thread, before the 37–39 bytes a pixel of
/// [`VvsConfig::rerender_px`]'s buffers over two or three pyramid levels; with `VvsConfig::parallel` each renderer also holds about 20
/// bytes a pixel for each more thread of the pool, up to 7, and a global search a
/// servo of its own for each thread, up to 8 and 1 GB together).
pub const SERVO_BYTES_PER_PIXEL: u64 = 260;

/// The optimiser for one cloud and camera, owning every buffer (no allocation per
/// iteration once warm).
#[derive(Debug)]
pub struct Servo<'a> {
    pub(crate) cloud: &'a PointCloud,
    pub(crate) camera: Camera,
    pub(crate) config: VvsConfig,
    /// Pyramid levels (0: full resolution), then the global search's level if built.
    pub(crate) levels: Vec<Level>,
    /// The cloud's bounding box (lowest, highest corner).
    pub(crate) bounds: (DVec3, DVec3),
    /// The desired feature of the stage running.
    desired: Vec<f32>,
    /// The stage's cost at each iteration so far (the stall test's).
    costs: Vec<f64>,
    residuals: Vec<f32>,
    weights: Vec<f32>,
    /// Tukey's median and deviations.
    scratch: Vec<f32>,
    /// Rows of the vignetting model's system: the pose, λ and two coefficients.
    rows9: Vec<[f32; 9]>,
    /// The vignetting coefficients' columns.
    columns: [Vec<f32>; 2],
    pub(crate) vignetting_start: [f64; 2],
    /// The global search's workers (servos of the same cloud, camera and settings, one
    /// thread each), made on a parallel search's first use and kept for the next.
    pub(crate) workers: Vec<crate::global::SearchWorker<'a>>,
    /// The global search level's thinned cloud (`GlobalConfig::thin_search_cloud`),
    /// made at the first search (a servo's settings do not change), shared with its
    /// workers.
    pub(crate) search_cloud: Option<Arc<PointCloud>>,
}

/// The cloud that level `level` renders: the search's thinned copy at its level (index
/// `pyramid_levels`), else the servo's.
pub(crate) fn level_cloud<'c>(
    cloud: &'c PointCloud,
    search_cloud: &'c Option<Arc<PointCloud>>,
    config: &VvsConfig,
    level: usize,
) -> &'c PointCloud {
    match search_cloud {
        Some(thinned) if level == config.pyramid_levels as usize => thinned,
        _ => cloud,
    }
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
            rows9: Vec::new(),
            columns: [Vec::new(), Vec::new()],
            vignetting_start: [0.0; 2],
            workers: Vec::new(),
            search_cloud: None,
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

    /// Align with a local method (PoVS or a PGM rule): estimate the pose at which the
    /// cloud looks like `desired`, from `initial` (`world_from_camera`). Errors only on
    /// invalid input ([`Method::Global`] among them: the global search takes a prior
    /// box, [`Servo::localize_in_box`]); divergence is reported in the outcome.
    pub fn run<D: AnyImage + Clone>(
        &mut self,
        method: Method,
        desired: &D,
        initial: Isometry3,
    ) -> Result<Outcome, VvsError> {
        let mut outcomes = self.run_methods(&[method], desired, initial)?;
        Ok(outcomes.pop().expect("one outcome per method"))
    }

    /// The desired picture fits the camera and holds something to align to; the
    /// initial pose is finite.
    pub(crate) fn check_inputs(
        &self,
        desired: &impl AnyImage,
        initial: &Isometry3,
    ) -> Result<(), VvsError> {
        if desired.width() != self.camera.width() || desired.height() != self.camera.height() {
            return Err(VvsError::DesiredSize {
                got_width: desired.width(),
                got_height: desired.height(),
                width: self.camera.width(),
                height: self.camera.height(),
            });
        }
        desired.check_buffers()?;
        if !initial.is_finite() {
            return Err(VvsError::NonFinitePose);
        }
        // A picture with nothing to align to (black, white, cut to one value) is an
        // input error, not a localisation that stalls at a pose.
        // Blocks of pixels without a branch (a picture is checked at every localisation
        // and every tracked frame); the first pixel that is not finite looked for only
        // if there is one.
        let (mut low, mut high, mut observed) = (f32::INFINITY, f32::NEG_INFINITY, 0usize);
        let mut finite = true;
        let intensity = desired.intensity();
        let valid = self.camera.valid_pixels();
        let mut flags = [false; CHECK_BLOCK];
        for start in (0..valid.len()).step_by(CHECK_BLOCK) {
            let end = (start + CHECK_BLOCK).min(valid.len());
            let flags = &mut flags[..end - start];
            desired.observed(start..end, flags);
            let pixels = flags
                .iter()
                .zip(&valid[start..end])
                .zip(&intensity[start..end]);
            let mut seen_here = 0u32;
            for ((&o, &v), &value) in pixels {
                // Comparisons and selections, which vectorise (`f32::min` does not).
                let seen = o & v;
                finite &= !seen | value.is_finite();
                low = if seen & (value < low) { value } else { low };
                high = if seen & (value > high) { value } else { high };
                seen_here += u32::from(seen);
            }
            observed += seen_here as usize;
        }
        if !finite {
            let index = (0..valid.len())
                .find(|&k| valid[k] && desired.is_observed(k) && !intensity[k].is_finite())
                .unwrap_or(0);
            return Err(VvsError::NonFiniteDesired { index });
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

    /// Align with several local methods from the same `initial` pose: one outcome per
    /// method, each exactly what [`Servo::run`] returns for it. Methods whose step 1 is the same
    /// (Rule1 and Rule2) run it once: step 2 of each starts from the shared result,
    /// and each outcome's `time_s` counts the shared step in full.
    pub fn run_methods<D: AnyImage + Clone>(
        &mut self,
        methods: &[Method],
        desired: &D,
        initial: Isometry3,
    ) -> Result<Vec<Outcome>, VvsError> {
        if methods.contains(&Method::Global) {
            return Err(VvsError::GlobalWithoutPrior);
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
            let stages = stage::plan(&self.config, method);
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
}

/// A scene for unit tests: 400 points 0.1 m apart on a 2 m square of the plane z = 0,
/// brighter along x, and the 320×240 fixture camera.
#[cfg(test)]
pub(crate) fn test_plane() -> (PointCloud, Camera) {
    let positions: Vec<DVec3> = (0..400)
        .map(|k| DVec3::new(f64::from(k % 20) * 0.1, f64::from(k / 20) * 0.1, 0.0))
        .collect();
    let intensities: Vec<f32> = positions.iter().map(|p| (p.x * 0.4) as f32).collect();
    let cloud = PointCloud::from_points(DVec3::ZERO, &positions, &intensities, None, None)
        .expect("a valid cloud");
    let camera = Camera::load_toml(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/omni-320x240.toml"),
    )
    .expect("the fixture camera");
    (cloud, camera)
}
