//! [`Servo`]: the virtual visual servoing loop.

use std::time::Instant;

use brightness::{Brightness, normal_equations};
use glam::DVec3;
use pgm::{Pgm, PgmOptions};
use splat::{Frame, PointCloud, RenderOptions, Renderer};
use ucm::{Camera, Isometry3};

use crate::solve::solve;
use crate::{
    Divergence, IterationRecord, Method, Outcome, Robust, StopReason, VvsConfig, VvsError,
};

/// One stage of a method.
#[derive(Clone, Copy, Debug)]
enum Stage {
    Brightness,
    Pgm {
        lambda_star: f32,
        lambda_start: f32,
        optimise_lambda: bool,
    },
}

/// The optimiser for one cloud and camera, owning every buffer (no allocation per
/// iteration once warm).
#[derive(Debug)]
pub struct Servo<'a> {
    cloud: &'a PointCloud,
    camera: Camera,
    config: VvsConfig,
    renderer: Renderer,
    frame: Frame,
    pgm: Pgm,
    brightness: Brightness,
    bounds: (DVec3, DVec3),
    desired: Vec<f32>,
    residuals: Vec<f32>,
    weights: Vec<f32>,
    rows7: Vec<[f32; 7]>,
    scratch: Vec<f32>,
}

impl<'a> Servo<'a> {
    /// An optimiser of poses of `camera` in `cloud`. Fails on an invalid configuration.
    pub fn new(
        cloud: &'a PointCloud,
        camera: &Camera,
        config: VvsConfig,
    ) -> Result<Self, VvsError> {
        config.validate()?;
        let options = RenderOptions {
            lod_spacing_px: config.lod_spacing_px,
            ..RenderOptions::default()
        };
        let renderer = Renderer::new(camera.clone(), options)?;
        let pgm = Pgm::new(
            camera,
            PgmOptions {
                stride: config.pgm_stride,
                normalize: config.normalize,
                ..PgmOptions::default()
            },
        )?;
        let brightness = Brightness::new(camera).with_normalization(config.normalize);
        Ok(Self {
            cloud,
            camera: camera.clone(),
            renderer,
            frame: Frame::for_camera(camera),
            pgm,
            brightness,
            bounds: cloud.bounds(),
            config,
            desired: Vec::new(),
            residuals: Vec::new(),
            weights: Vec::new(),
            rows7: Vec::new(),
            scratch: Vec::new(),
        })
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
        self.renderer
            .render(self.cloud, &world_from_camera.inverse(), &mut frame)?;
        Ok(frame)
    }

    fn stages(&self, method: Method) -> Vec<(Stage, usize)> {
        let c = &self.config;
        let step1 = |lambda_start: f32| Stage::Pgm {
            lambda_star: c.lambda_star_step1,
            lambda_start,
            optimise_lambda: true,
        };
        let step2 = |optimise_lambda: bool| Stage::Pgm {
            lambda_star: c.lambda_star_step2,
            lambda_start: c.lambda_star_step2,
            optimise_lambda,
        };
        let rest = c.max_iterations - c.step1_max_iterations;
        match method {
            Method::Povs => vec![(Stage::Brightness, c.max_iterations)],
            Method::Rule0 => vec![
                (
                    step1(c.rule0_lambda_factor * c.lambda_star_step1),
                    c.step1_max_iterations,
                ),
                (step2(false), rest),
            ],
            Method::Rule1 => vec![
                (step1(c.lambda_star_step1), c.step1_max_iterations),
                (step2(false), rest),
            ],
            Method::Rule2 => vec![
                (step1(c.lambda_star_step1), c.step1_max_iterations),
                (step2(true), rest),
            ],
        }
    }

    /// Align: estimate the pose at which the cloud looks like `desired`, from
    /// `initial` (`world_from_camera`). Errors only on invalid input; divergence is
    /// reported in the outcome.
    pub fn run(
        &mut self,
        method: Method,
        desired: &Frame,
        initial: Isometry3,
    ) -> Result<Outcome, VvsError> {
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
        let rule0_start = self.config.rule0_lambda_factor * self.config.lambda_star_step1;
        if method == Method::Rule0 && !pgm::LAMBDA_RANGE.contains(&rule0_start) {
            return Err(VvsError::Config {
                name: "rule0_lambda_factor",
                message: format!("Rule0 would start at λ = {rule0_start} px, outside [0.5, 40]"),
            });
        }
        let mut pose = initial;
        let mut lambda = 0.0f32;
        let mut cost = f64::NAN;
        let mut history = Vec::new();
        let mut iterations = [0usize; 2];
        let mut stop = StopReason::IterationBudget;
        let stages = self.stages(method);
        for (index, (stage, budget)) in stages.iter().enumerate() {
            let (result, stage_lambda, stage_cost, count) = self.run_stage(
                *stage,
                index as u8 + 1,
                *budget,
                desired,
                &mut pose,
                &mut history,
            )?;
            iterations[index.min(1)] += count;
            lambda = stage_lambda;
            cost = stage_cost;
            stop = result;
            if let StopReason::Diverged(_) = result {
                break;
            }
        }
        Ok(Outcome {
            world_from_camera: pose,
            lambda,
            cost,
            stop,
            iterations,
            history,
        })
    }

    /// One stage: returns why it stopped, the final λ and cost, and its iteration count.
    fn run_stage(
        &mut self,
        stage: Stage,
        stage_number: u8,
        budget: usize,
        desired: &Frame,
        pose: &mut Isometry3,
        history: &mut Vec<IterationRecord>,
    ) -> Result<(StopReason, f32, f64, usize), VvsError> {
        // The desired feature, fixed for the stage.
        let (mut lambda, optimise_lambda) = match stage {
            Stage::Brightness => {
                self.brightness.compute(desired)?;
                self.desired.clear();
                self.desired.extend_from_slice(self.brightness.values());
                (0.0, false)
            }
            Stage::Pgm {
                lambda_star,
                lambda_start,
                optimise_lambda,
            } => {
                let g = self.pgm.transform(desired, lambda_star)?;
                self.desired.clear();
                self.desired.extend_from_slice(g);
                (lambda_start, optimise_lambda)
            }
        };
        let valid_count = self.camera.valid_pixel_count().max(1) as f64;
        let (lo, hi) = self.bounds;
        let margin = DVec3::splat(self.config.bounds_margin_m);
        let mut initial_cost = None;
        let mut cost = f64::NAN;
        for iteration in 0..budget {
            let started = Instant::now();
            let stats = self
                .renderer
                .render(self.cloud, &pose.inverse(), &mut self.frame)?;
            let hits = stats.pixels_hit as f64;
            if hits / valid_count < self.config.min_hit_fraction {
                return Ok((
                    StopReason::Diverged(Divergence::NoValidPixels),
                    lambda,
                    cost,
                    iteration,
                ));
            }
            // Feature, residuals, rows.
            let (values, pixel_weights): (&[f32], Option<&[f32]>) = match stage {
                Stage::Brightness => {
                    self.brightness.compute(&self.frame)?;
                    (self.brightness.values(), None)
                }
                Stage::Pgm { .. } => {
                    self.pgm
                        .compute(&self.frame, lambda, self.config.jacobian.to_pgm())?;
                    (self.pgm.values(), Some(self.pgm.weights()))
                }
            };
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
            let weight_sum: f64 = self.weights.iter().map(|&w| f64::from(w)).sum();
            cost = self
                .residuals
                .iter()
                .zip(&self.weights)
                .map(|(&e, &w)| f64::from(w) * f64::from(e) * f64::from(e))
                .sum::<f64>()
                / weight_sum.max(1.0);
            if !cost.is_finite() {
                return Ok((
                    StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iteration,
                ));
            }
            let reference = *initial_cost.get_or_insert(cost);
            if cost > self.config.divergence_cost_factor * reference.max(1e-30) {
                return Ok((
                    StopReason::Diverged(Divergence::CostExploded),
                    lambda,
                    cost,
                    iteration,
                ));
            }
            // The step: x = −μ J⁺ e.
            let eta = self.config.levenberg_marquardt;
            let step: Option<([f64; 6], f64)> = match stage {
                Stage::Pgm { .. } if optimise_lambda => {
                    self.rows7.clear();
                    self.rows7.extend(
                        self.pgm
                            .interaction()
                            .iter()
                            .zip(self.pgm.j_lambda())
                            .map(|(l, &j)| [l[0], l[1], l[2], l[3], l[4], l[5], j]),
                    );
                    let (jtj, jte) =
                        normal_equations::<7>(&self.rows7, &self.residuals, Some(&self.weights));
                    solve(&jtj, &jte, eta).map(|x| ([x[0], x[1], x[2], x[3], x[4], x[5]], x[6]))
                }
                _ => {
                    let rows = match stage {
                        Stage::Brightness => self.brightness.interaction(),
                        Stage::Pgm { .. } => self.pgm.interaction(),
                    };
                    let (jtj, jte) =
                        normal_equations::<6>(rows, &self.residuals, Some(&self.weights));
                    solve(&jtj, &jte, eta).map(|x| (x, 0.0))
                }
            };
            let Some((x, lambda_x)) = step else {
                return Ok((
                    StopReason::Diverged(Divergence::SingularSystem),
                    lambda,
                    cost,
                    iteration,
                ));
            };
            let gain = self.config.gain;
            let v = x.map(|c| -gain * c);
            let lambda_dot = (-gain * lambda_x) as f32;
            let step_t = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let step_r = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5]).sqrt();
            if self.config.keep_history {
                history.push(IterationRecord {
                    stage: stage_number,
                    pose: pose.to_pose_vector(),
                    lambda,
                    cost,
                    step_translation_m: step_t,
                    step_rotation_rad: step_r,
                    time_s: started.elapsed().as_secs_f64(),
                });
            }
            let Ok(update) = Isometry3::exp(v) else {
                return Ok((
                    StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iteration + 1,
                ));
            };
            *pose = *pose * update;
            if optimise_lambda {
                lambda = (lambda + lambda_dot)
                    .clamp(*pgm::LAMBDA_RANGE.start(), *pgm::LAMBDA_RANGE.end());
            }
            if !pose.is_finite() || !lambda.is_finite() {
                return Ok((
                    StopReason::Diverged(Divergence::NotFinite),
                    lambda,
                    cost,
                    iteration + 1,
                ));
            }
            let position = pose.translation;
            if position.cmplt(lo - margin).any() || position.cmpgt(hi + margin).any() {
                return Ok((
                    StopReason::Diverged(Divergence::LeftBounds),
                    lambda,
                    cost,
                    iteration + 1,
                ));
            }
            if step_t < self.config.converged_translation_m
                && step_r < self.config.converged_rotation_rad
                && lambda_dot.abs() < 1e-4
            {
                return Ok((StopReason::Converged, lambda, cost, iteration + 1));
            }
        }
        Ok((StopReason::IterationBudget, lambda, cost, budget))
    }
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
