//! One stage of a method: its plan ([`Planned`], from [`plan`]) and its loop
//! ([`crate::Servo::run_stage`]): render, feature, residuals, update, until a stop.

use std::time::Instant;

use brightness::{Against, normal_equations, normal_equations_with_column};
use frame::{AnyImage, Frame, Image, PixelStatus, Restricted};
use glam::DVec3;
use pgm::Pgm;
use ucm::{Camera, Isometry3};

use super::warp::{self, Reference};
use super::{Level, level_cloud, render_once};
use crate::solve::solve;
use crate::vignetting::MAX_COEFFICIENT;
use crate::{
    Divergence, IterationRecord, Method, Robust, Servo, StopReason, Support, VvsConfig, VvsError,
};

/// One stage of a method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Stage {
    /// PoVS: the brightness.
    Brightness,
    /// A PGM stage: its desired extent λ*, the λ it starts at, and whether λ is
    /// optimised with the pose.
    Pgm {
        lambda_star: f32,
        lambda_start: f32,
        optimise_lambda: bool,
    },
}

/// A stage with its step (1 or 2), pyramid level and iteration cap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Planned {
    pub(crate) stage: Stage,
    pub(crate) step: u8,
    pub(crate) level: usize,
    /// Most iterations this stage may take; the step's last stage takes whatever the
    /// step's budget has left.
    pub(crate) cap: usize,
    pub(crate) last_of_step: bool,
    /// The stall test's window for this stage (`VvsConfig::stall_window`, or
    /// `intermediate_stall_window` for step 1's stages before a step 2).
    pub(crate) stall_window: usize,
    /// The image motion below which an update ends the stage
    /// (`VvsConfig::converged_px`).
    pub(crate) converged_px: Option<f32>,
}

/// How a stage ended: why, with which λ and cost, after how many iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct StageResult {
    pub(crate) stop: StopReason,
    pub(crate) lambda: f32,
    pub(crate) cost: f64,
    pub(crate) iterations: usize,
}

/// The stages of a local method: step 1 (coarse pyramid levels first, then the full
/// resolution at λ*₁, then the λ schedule; or, coarse to fine, λ*₁ and the schedule
/// each at its level), then step 2 (PoVS: one stage of brightness).
pub(crate) fn plan(c: &VvsConfig, method: Method) -> Vec<Planned> {
    if method == Method::Povs {
        return vec![Planned {
            stage: Stage::Brightness,
            step: 1,
            level: 0,
            cap: c.max_iterations,
            last_of_step: true,
            stall_window: c.stall_window,
            converged_px: c.converged_px,
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
            converged_px: c.converged_px,
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
        converged_px: c.converged_px,
    });
    planned
}

impl Servo<'_> {
    /// One stage, from `pose` (updated in place).
    pub(crate) fn run_stage(
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
            converged_px,
            ..
        } = planned;
        let Level {
            camera,
            renderer,
            frame,
            rendered_at,
            pgm,
            vignetting,
            desired_pgm,
            support,
            against,
            against_observed,
            rays,
            points,
            warped,
        } = &mut self.levels[level];
        let common = self.config.support == Support::Common;
        // Beyond the paper: iterations between renderings compare the picture warped
        // into the last one (`VvsConfig::rerender_px`).
        // With the desired extent λ* the warped picture is transformed at.
        let rerender_px = match stage {
            Stage::Pgm { lambda_star, .. } if common && vignetting.is_none() => {
                self.config.rerender_px.map(|px| (px, lambda_star))
            }
            _ => None,
        };
        if rerender_px.is_some() && points.len() != camera.pixel_count() {
            points.resize(camera.pixel_count(), [f32::NAN; 3]);
            *warped = Image::new(camera.width(), camera.height());
        }
        let mut reference: Option<Reference> = None;
        // A method's last stage ends on a rendered iteration: a stop met on a warped one
        // (its cost and step the warp's) renders at the next iteration, where the stop is
        // tested again.
        let end_rendered =
            rerender_px.is_some() && self.config.end_on_rendering && stage_number == 2;
        let mut must_render = false;
        // The desired feature, fixed for the stage (on the common support: taken again
        // at every iteration).
        let (mut lambda, optimise_lambda) = match stage {
            Stage::Brightness => {
                if !common {
                    pgm.brightness_mut().compute(desired)?;
                    self.desired.clear();
                    self.desired.extend_from_slice(pgm.brightness().values());
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
        // Beyond the paper: a method's last stage lengthens updates that continue the
        // last one (`VvsConfig::extrapolate_steps`), compared with the last update as
        // computed.
        let extrapolate = self
            .config
            .extrapolate_steps
            .filter(|_| stage_number == 2 || stage == Stage::Brightness);
        let mut last_update: Option<[f64; 6]> = None;
        let (stop, iterations) = 'stage: {
            for iteration in 0..budget {
                let started = Instant::now();
                // The rendering this iteration compares with, when it is not rendered.
                let mut between = match (rerender_px, &reference) {
                    (Some((px, lambda_star)), Some(r))
                        if !must_render
                            && (lambda - r.lambda).abs() <= 0.2 * r.lambda
                            && r.image_motion_px(camera, pose)
                                <= f64::from(px) * f64::from(r.lambda).max(1.0) =>
                    {
                        Some((*r, lambda_star))
                    }
                    _ => None,
                };
                if let (Some((r, _)), Some(kept)) = (between, reference.as_mut()) {
                    // The picture seen from the rendering (rendered again if it sees too
                    // little of it).
                    if !kept.lifted {
                        if rays.len() != camera.pixel_count() {
                            warp::rays(camera, rays);
                        }
                        warp::lift(frame, rays, points);
                        kept.lifted = true;
                    }
                    warp::warp(
                        camera,
                        points,
                        &(pose.inverse() * r.world_from_reference),
                        desired,
                        warped,
                    );
                    let compared = warped.valid.iter().filter(|&&v| v).count();
                    if (compared as f64) / valid_count < self.config.min_hit_fraction {
                        between = None;
                    }
                }
                if between.is_none() {
                    let cloud = level_cloud(self.cloud, &self.search_cloud, &self.config, level);
                    let stats = render_once(renderer, rendered_at, cloud, pose, frame)?;
                    let hits = stats.pixels_hit as f64;
                    if hits / valid_count < self.config.min_hit_fraction {
                        break 'stage (StopReason::Diverged(Divergence::NoValidPixels), iteration);
                    }
                }
                // The rendering as the camera would see it (with the vignetting model).
                let input: &Frame = match vignetting {
                    Some(v) => {
                        v.model.apply(*coefficients, frame, &mut v.corrected);
                        &v.corrected
                    }
                    None => frame,
                };
                // Feature, residuals, rows.
                if let Some((r, lambda_star)) = between {
                    // The picture warped into the rendering and the rendering, both
                    // transformed on their common support; the rows (`L_G`, `J_λ`) the
                    // rendering's.
                    support.copy_from_slice(&warped.valid);
                    let compared = support.iter().filter(|&&s| s).count();
                    coverage = compared as f64 / r.observed.max(1) as f64;
                    self.desired.clear();
                    self.desired.extend_from_slice(
                        desired_pgm.transform(&Restricted::new(&*warped, support)?, lambda_star)?,
                    );
                    pgm.transform(&Restricted::new(input, support)?, lambda)?;
                } else if common {
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
                            desired_pgm.brightness_mut().compute(&desired_view)?;
                            self.desired
                                .extend_from_slice(desired_pgm.brightness().values());
                            desired_pgm.brightness()
                        }
                        Stage::Pgm { lambda_star, .. } => {
                            self.desired.extend_from_slice(
                                desired_pgm.transform(&desired_view, lambda_star)?,
                            );
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
                        Stage::Brightness => {
                            pgm.brightness_mut().compute_against(&view, against)?
                        }
                        Stage::Pgm { .. } => {
                            pgm.compute_against(&view, against, lambda, self.config.jacobian)?
                        }
                    }
                    if rerender_px.is_some() {
                        reference = Some(Reference {
                            world_from_reference: *pose,
                            lambda,
                            mean_inverse_range: mean_inverse_range(frame),
                            observed,
                            lifted: false,
                        });
                    }
                } else {
                    compute_feature(stage, pgm, input, lambda, self.config.jacobian)?;
                }
                let (values, pixel_weights): (&[f32], Option<&[f32]>) = match stage {
                    Stage::Brightness => (pgm.brightness().values(), None),
                    Stage::Pgm { .. } => (pgm.values(), Some(pgm.weights())),
                };
                if let Some(v) = vignetting {
                    // The columns of the coefficients: the feature of each derivative picture
                    // (the brightness or the PGM's brightness stage).
                    let feature = pgm.brightness();
                    let normalization = self
                        .config
                        .normalize
                        .then(|| (feature.normalization_scale(), feature.image()));
                    for (k, column) in self.columns.iter_mut().enumerate() {
                        v.model.derivative(
                            k,
                            frame,
                            feature.samples(),
                            feature.observed(),
                            normalization,
                            &mut v.derivative,
                        );
                        column.clear();
                        match stage {
                            Stage::Brightness => column.extend(
                                feature
                                    .samples()
                                    .iter()
                                    .map(|&s| v.derivative.intensity[s as usize]),
                            ),
                            Stage::Pgm { .. } => column.extend_from_slice(
                                v.derivative_pgm.transform(&v.derivative, lambda)?,
                            ),
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
                    break 'stage (StopReason::Diverged(Divergence::NotFinite), iteration);
                }
                let initial = *initial_cost.get_or_insert(cost);
                if cost > self.config.divergence_cost_factor * initial.max(1e-30) {
                    break 'stage (StopReason::Diverged(Divergence::CostExploded), iteration);
                }
                self.costs.push(cost);
                // Whether a stop met here is put off to a rendered iteration (not at the
                // budget's last iteration: the stop is then met as it is).
                let put_off = end_rendered && between.is_some() && iteration + 1 < budget;
                must_render = false;
                if stalled(
                    &self.costs,
                    stall_window,
                    self.config.stall_relative_decrease,
                ) {
                    if !put_off {
                        break 'stage (StopReason::Stalled, iteration);
                    }
                    must_render = true;
                }
                // The update: x = −μ J⁺ e.
                let eta = self.config.levenberg_marquardt;
                let mut coefficient_update = [0.0; 2];
                let solution: Option<([f64; 6], f64)> = match stage {
                    _ if vignetting.is_some() => {
                        let (rows, j_lambda): (&[[f32; 6]], Option<&[f32]>) = match stage {
                            Stage::Brightness => (pgm.brightness().interaction(), None),
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
                        let (jtj, jte) = normal_equations::<9>(
                            &self.rows9,
                            &self.residuals,
                            Some(&self.weights),
                        );
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
                            Stage::Brightness => pgm.brightness().interaction(),
                            Stage::Pgm { .. } => pgm.interaction(),
                        };
                        let (jtj, jte) =
                            normal_equations::<6>(rows, &self.residuals, Some(&self.weights));
                        solve(&jtj, &jte, eta).map(|x| (x, 0.0))
                    }
                };
                let Some((x, lambda_x)) = solution else {
                    break 'stage (StopReason::Diverged(Divergence::SingularSystem), iteration);
                };
                // The rendering's mean inverse range, read at most once an iteration (by the
                // lengthened update and the test in pixels): the reference's when there is
                // one (`frame` is its rendering).
                let reference_inverse_range = match (&rerender_px, &reference) {
                    (Some(_), Some(r)) => Some(r.mean_inverse_range),
                    _ => None,
                };
                let mut read_inverse_range = None;
                let mut inverse_range = || {
                    *read_inverse_range.get_or_insert_with(|| {
                        reference_inverse_range.unwrap_or_else(|| mean_inverse_range(frame))
                    })
                };
                let gain = self.config.gain;
                let mut v = x.map(|c| -gain * c);
                if let Some(cap) = extrapolate {
                    let computed = v;
                    if let Some(last) = last_update
                        && let Some(factor) = extrapolation(&v, &last, inverse_range(), cap)
                    {
                        v = v.map(|c| c * factor);
                    }
                    last_update = Some(computed);
                }
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
                        rendered: between.is_none(),
                    });
                }
                let Ok(update) = Isometry3::exp(v) else {
                    break 'stage (StopReason::Diverged(Divergence::NotFinite), iteration + 1);
                };
                *pose = match between {
                    Some((r, _)) => warp::compose(&r.world_from_reference, update, pose),
                    None => *pose * update,
                };
                if vignetting.is_some() {
                    for (c, dc) in coefficients.iter_mut().zip(coefficient_update) {
                        *c = (*c - gain * dc).clamp(-MAX_COEFFICIENT, MAX_COEFFICIENT);
                    }
                }
                if optimise_lambda {
                    lambda = (lambda + lambda_dot)
                        .clamp(*pgm::LAMBDA_RANGE.start(), *pgm::LAMBDA_RANGE.end());
                }
                if !pose.is_finite() || !lambda.is_finite() {
                    break 'stage (StopReason::Diverged(Divergence::NotFinite), iteration + 1);
                }
                let position = pose.translation;
                if outside(self.bounds, self.config.bounds_margin_m, position) {
                    break 'stage (StopReason::Diverged(Divergence::LeftBounds), iteration + 1);
                }
                let converged = (update_t < self.config.converged_translation_m
                    && update_r < self.config.converged_rotation_rad
                    && lambda_dot.abs() < 1e-4)
                    || converged_px.is_some_and(|px| {
                        converged_in_pixels(
                            px,
                            lambda_dot,
                            camera,
                            inverse_range,
                            update_t,
                            update_r,
                        )
                    });
                if converged {
                    if !put_off {
                        break 'stage (StopReason::Converged, iteration + 1);
                    }
                    must_render = true;
                }
            }
            (StopReason::IterationBudget, budget)
        };
        Ok(StageResult {
            stop,
            lambda,
            cost,
            iterations,
        })
    }
}

/// The feature of `picture` for `stage`: the brightness, or the PGM at `lambda`.
fn compute_feature(
    stage: Stage,
    pgm: &mut Pgm,
    picture: &impl AnyImage,
    lambda: f32,
    jacobian: pgm::PgmJacobian,
) -> Result<(), VvsError> {
    match stage {
        Stage::Brightness => pgm.brightness_mut().compute(picture)?,
        Stage::Pgm { .. } => pgm.compute(picture, lambda, jacobian)?,
    }
    Ok(())
}

/// `VvsConfig::extrapolate_steps`' factor for `update` after `last` (twists as
/// computed, translation first, each in the frame its iteration compared in: the camera's,
/// or the last rendering's when warped): `1 / (1 − r)`, at most
/// `cap`, when the update continues the last one (cosine above 0.9) and is `r` in
/// (0.5, 1) times as long; `None` otherwise. Each twist is compared as an image motion,
/// its translation times the rendering's mean inverse range `inverse_range_per_m`.
fn extrapolation(
    update: &[f64; 6],
    last: &[f64; 6],
    inverse_range_per_m: f64,
    cap: f64,
) -> Option<f64> {
    let motion = |v: &[f64; 6]| -> [f64; 6] {
        std::array::from_fn(|k| {
            if k < 3 {
                v[k] * inverse_range_per_m
            } else {
                v[k]
            }
        })
    };
    let (a, b) = (motion(update), motion(last));
    let dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let (norm_a, norm_b) = (
        a.iter().map(|x| x * x).sum::<f64>().sqrt(),
        b.iter().map(|x| x * x).sum::<f64>().sqrt(),
    );
    if !(norm_a > 0.0 && norm_b > 0.0) {
        return None;
    }
    let (cosine, ratio) = (dot / (norm_a * norm_b), norm_a / norm_b);
    (cosine > 0.9 && ratio > 0.5 && ratio < 1.0).then(|| (1.0 / (1.0 - ratio)).min(cap))
}

/// `VvsConfig::converged_px`'s test: an update changes λ by less than `px` pixels and
/// moves the image of the rendering by less than `px` ([`motion_px`] at its
/// `mean_inverse_range`, read only when the rotation alone passes).
fn converged_in_pixels(
    px: f32,
    lambda_dot: f32,
    camera: &Camera,
    mean_inverse_range: impl FnOnce() -> f64,
    translation_m: f64,
    rotation_rad: f64,
) -> bool {
    let i = camera.intrinsics();
    // The rotation's motion alone bounds the whole from below: when it does not pass,
    // the frame's ranges need not be read.
    lambda_dot.abs() < px
        && i.alpha_u.max(i.alpha_v) * rotation_rad < f64::from(px)
        && motion_px(camera, mean_inverse_range(), translation_m, rotation_rad) < f64::from(px)
}

/// How far an update of `translation_m` and `rotation_rad` moves the image of what
/// `frame` sees, in pixels of `camera` ([`motion_px`] at `frame`'s
/// [`mean_inverse_range`]).
#[cfg(test)]
fn image_motion_px(camera: &Camera, frame: &Frame, translation_m: f64, rotation_rad: f64) -> f64 {
    motion_px(
        camera,
        mean_inverse_range(frame),
        translation_m,
        rotation_rad,
    )
}

/// `α (‖t‖ / ρ̄ + ‖ω‖)`: how far a motion of `translation_m` and `rotation_rad` moves
/// the image of points at mean inverse range `1/ρ̄`, in pixels of `camera` (`α` its
/// larger focal length); infinite when `1/ρ̄` is (a translation's effect unknown).
pub(crate) fn motion_px(
    camera: &Camera,
    mean_inverse_range: f64,
    translation_m: f64,
    rotation_rad: f64,
) -> f64 {
    if mean_inverse_range.is_infinite() {
        return f64::INFINITY;
    }
    let i = camera.intrinsics();
    i.alpha_u.max(i.alpha_v) * (translation_m * mean_inverse_range + rotation_rad)
}

/// The mean inverse range of `frame`'s hits with a positive range (m⁻¹; infinite
/// without any).
pub(crate) fn mean_inverse_range(frame: &Frame) -> f64 {
    let (mut inverse_sum, mut hits) = (0.0f64, 0usize);
    for (&range_m, &status) in frame.range_m.iter().zip(&frame.status) {
        if status == PixelStatus::Hit && range_m > 0.0 {
            inverse_sum += 1.0 / f64::from(range_m);
            hits += 1;
        }
    }
    if hits == 0 {
        f64::INFINITY
    } else {
        inverse_sum / hits as f64
    }
}

/// Whether `position` lies outside the box `bounds` (lowest, highest corner) enlarged by
/// `margin_m` on every side.
pub(crate) fn outside(bounds: (DVec3, DVec3), margin_m: f64, position: DVec3) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `extrapolate_steps`' factor: `1 / (1 − r)` for an update `r` times the last in
    /// its direction, at most the cap; none for a turn, a reversal, a longer update or
    /// one shorter than half; translations weighed as image motions.
    #[test]
    fn an_update_that_continues_the_last_one_is_lengthened() {
        let last = [0.01, -0.02, 0.005, 0.002, 0.001, -0.003];
        let scaled = |r: f64| last.map(|c| c * r);
        let factor = |update: &[f64; 6], cap| extrapolation(update, &last, 0.25, cap);
        assert!((factor(&scaled(0.9), 100.0).unwrap() - 10.0).abs() < 1e-9);
        assert!((factor(&scaled(0.75), 100.0).unwrap() - 4.0).abs() < 1e-9);
        assert_eq!(factor(&scaled(0.9), 4.0), Some(4.0));
        for r in [0.5, 0.3, 1.0, 1.2, -0.9] {
            assert_eq!(factor(&scaled(r), 100.0), None, "r = {r}");
        }
        assert_eq!(factor(&[0.0; 6], 100.0), None);
        // Turned, 0.8 times as long: the cosine (0.23) below 0.9.
        let turned = [last[1], -last[0], last[2], last[4], -last[3], last[5]].map(|c| c * 0.8);
        assert_eq!(factor(&turned, 100.0), None);
        // Turned by a cosine of 0.913, lengthened; of 0.894, not (ratios 0.80 and 0.83).
        let turned_by = |e: f64| {
            let mut v = scaled(0.7);
            v[3] += e;
            v[4] -= e;
            v
        };
        assert!(factor(&turned_by(0.0016), 100.0).is_some());
        assert_eq!(factor(&turned_by(0.0018), 100.0), None);
        // The translation turned by 90°, the rotation kept: seen at 100 m the translations
        // weigh little against the rotation and the update continues the last one; at
        // 10 cm they dominate and it does not.
        let sideways = [
            0.02 * 0.8,
            0.01 * 0.8,
            0.0,
            0.002 * 0.8,
            0.001 * 0.8,
            -0.003 * 0.8,
        ];
        assert!(extrapolation(&sideways, &last, 0.01, 100.0).is_some());
        assert_eq!(extrapolation(&sideways, &last, 10.0, 100.0), None);
    }

    /// `α (‖t‖ / ρ̄ + ‖ω‖)`: `1/ρ̄` the mean inverse range of the hits alone, `α` the
    /// level's (halved at half the resolution); the test also bounds λ's change.
    #[test]
    fn image_motion_is_in_pixels_of_the_level() {
        let (_, camera) = crate::servo::test_plane();
        let alpha = camera.intrinsics().alpha_u.max(camera.intrinsics().alpha_v);
        let mut frame = Frame::for_camera(&camera);
        frame.status.fill(PixelStatus::Sky);
        // No hit: any motion may be large, the test never passes.
        assert_eq!(image_motion_px(&camera, &frame, 0.0, 0.0), f64::INFINITY);
        assert!(!converged_in_pixels(
            1.0,
            0.0,
            &camera,
            || mean_inverse_range(&frame),
            0.0,
            0.0
        ));
        // Hits at 1 m and 4 m: a mean inverse range of 0.625 /m; a masked pixel's
        // range, and a hit's without a positive range, are not read.
        frame.status[0] = PixelStatus::Hit;
        frame.range_m[0] = 1.0;
        frame.status[1] = PixelStatus::Hit;
        frame.range_m[1] = 4.0;
        frame.status[2] = PixelStatus::Masked;
        frame.range_m[2] = 0.001;
        frame.status[3] = PixelStatus::Hit;
        frame.range_m[3] = f32::NAN;
        frame.status[4] = PixelStatus::Hit;
        frame.range_m[4] = 0.0;
        let px = image_motion_px(&camera, &frame, 0.02, 0.001);
        assert!((px - alpha * (0.02 * 0.625 + 0.001)).abs() < 1e-12, "{px}");
        // The test: both the image's motion and λ's change below the threshold.
        assert!(converged_in_pixels(
            px as f32 * 1.01,
            0.0,
            &camera,
            || mean_inverse_range(&frame),
            0.02,
            0.001
        ));
        assert!(!converged_in_pixels(
            px as f32 * 0.99,
            0.0,
            &camera,
            || mean_inverse_range(&frame),
            0.02,
            0.001
        ));
        let wide = px as f32 * 1.01;
        assert!(!converged_in_pixels(
            wide,
            -wide,
            &camera,
            || mean_inverse_range(&frame),
            0.02,
            0.001
        ));
        assert!(converged_in_pixels(
            wide,
            -0.99 * wide,
            &camera,
            || mean_inverse_range(&frame),
            0.02,
            0.001
        ));
        // A rotation alone moving the image by more fails whatever the ranges.
        let turn = f64::from(wide) / alpha * 1.01;
        assert!(!converged_in_pixels(
            wide,
            0.0,
            &camera,
            || mean_inverse_range(&frame),
            0.0,
            turn
        ));
        let half = camera.downsampled(2).unwrap();
        let mut small = Frame::for_camera(&half);
        small.status.fill(PixelStatus::Sky);
        small.status[0] = PixelStatus::Hit;
        small.range_m[0] = 2.0;
        let px_half = image_motion_px(&half, &small, 0.02, 0.0);
        let alpha_half = half.intrinsics().alpha_u.max(half.intrinsics().alpha_v);
        assert!((alpha_half - alpha / 2.0).abs() < 1e-9);
        assert!((px_half - alpha_half * 0.01).abs() < 1e-12);
    }
}
