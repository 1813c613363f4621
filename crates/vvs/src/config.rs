//! Configuration of the optimiser: plain structs, (de)serialisable as TOML, every field
//! documented. Defaults are the paper's (§3.1) and `../shared/notes/math.md`'s.

use pgm::PgmJacobian;
use serde::{Deserialize, Serialize};

use crate::VvsError;

/// The largest iteration budget accepted (`max_iterations`): a localisation takes a few
/// hundred iterations; a budget beyond this is a typo, not a setting.
pub const MAX_ITERATIONS: usize = 100_000;

/// The largest PGM sample stride accepted (`pgm_stride`): beyond it the PGM holds too
/// few samples of a picture to mean anything.
pub const MAX_PGM_STRIDE: u32 = 16;

/// Which method aligns the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Photometric omnidirectional visual servoing (the paper's ref. 14, Caron et al. 2013): `e = I(r) − I*`, 6 unknowns.
    Povs,
    /// PGM, the rule of the paper's ref. 10 (Crombez et al. 2019): step 1 with λ starting at `rule0_lambda_factor` × λ*₁ and
    /// optimised; step 2 with λ = λ*₂ constant.
    Rule0,
    /// PGM: step 1 with λ starting at λ*₁, optimised; step 2 with λ = λ*₂ constant.
    Rule1,
    /// PGM: step 1 as Rule1; step 2 with λ starting at λ*₂, optimised.
    Rule2,
    /// Beyond the paper: global localisation inside a prior region
    /// ([`crate::global`], settings in [`VvsConfig::global`]): a low-resolution search
    /// over a grid of the region, then [`crate::GlobalConfig::refine_method`] from the
    /// best low-resolution descent (and up to [`crate::GlobalConfig::refined`] ranked
    /// within [`crate::GlobalConfig::refine_within`] of it). It takes a prior
    /// box, given where it is run ([`crate::Localizer::prior`],
    /// [`crate::Servo::localize_in_box`]); the calls of the local methods refuse it.
    Global,
}

impl Method {
    /// The paper's methods, in its order of presentation: the local ones.
    pub const PAPER: [Method; 4] = [Method::Povs, Method::Rule0, Method::Rule1, Method::Rule2];

    /// Every method: the paper's, then [`Method::Global`].
    pub const ALL: [Method; 5] = [
        Method::Povs,
        Method::Rule0,
        Method::Rule1,
        Method::Rule2,
        Method::Global,
    ];

    /// Short name (`povs`, `rule0`, …).
    pub fn name(self) -> &'static str {
        match self {
            Method::Povs => "povs",
            Method::Rule0 => "rule0",
            Method::Rule1 => "rule1",
            Method::Rule2 => "rule2",
            Method::Global => "global",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = VvsError;

    /// A method by its [`Method::name`], any case (`povs`, `Rule2`, `global`, …).
    fn from_str(text: &str) -> Result<Self, VvsError> {
        Method::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(text.trim()))
            .ok_or_else(|| VvsError::UnknownName {
                what: "method",
                text: text.to_string(),
                expected: "povs, rule0, rule1, rule2, global".into(),
            })
    }
}

/// Robust (M-estimator) weighting of the residuals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Robust {
    /// Tukey's biweight with threshold `c` × the residuals' robust scale
    /// (1.4826 × median absolute deviation); `c` = 4.685 is the usual choice.
    Tukey {
        /// Threshold in robust standard deviations.
        c: f32,
    },
}

/// Which pixels the rendering and the picture are compared on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Support {
    /// Every pixel of the camera's region where the picture holds an intensity; where
    /// the cloud has no point the rendering holds the background (sky) intensity
    /// ([`splat::RenderOptions::background`]). The paper's comparison, and right when
    /// the cloud is complete and the picture's sky is the renderer's.
    #[default]
    Region,
    /// Beyond the paper: only the pixels where the rendering sees a point *and* the
    /// picture holds an intensity, recomputed at every iteration; both pictures are
    /// centred and normalised over them, and are 0 elsewhere, before their features
    /// are taken (the desired feature is then taken again at every iteration). What
    /// the cloud does not hold (its holes, what its scans never saw, the sky) is
    /// unknown, not a grey wall.
    Common,
}

/// Every setting of the optimiser.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VvsConfig {
    /// Control gain μ of `[vᵀ, λ̇]ᵀ = −μ [L_G J_λ]⁺ e`. Paper: 0.2.
    pub gain: f64,
    /// λ* of step 1 (pixels): the extent of the desired PGM. Paper: 15.
    pub lambda_star_step1: f32,
    /// λ* of step 2 (pixels). Paper: 1.
    pub lambda_star_step2: f32,
    /// Rule0's initial λ of step 1 as a multiple of λ*₁. Paper (ref. 10): 2.
    pub rule0_lambda_factor: f32,
    /// Iteration budget of step 1. Paper: 120.
    pub step1_max_iterations: usize,
    /// Total iteration budget (both steps, or PoVS). Paper: 250.
    pub max_iterations: usize,
    /// PGM interaction matrix.
    pub jacobian: PgmJacobian,
    /// A stage has converged when an iteration moves the camera by less than this
    /// (metres)…
    pub converged_translation_m: f64,
    /// …and rotates it by less than this (radians), and changes λ by less than 1e-4 px.
    pub converged_rotation_rad: f64,
    /// A stage has stalled (and ends) when the lowest cost of its last `stall_window`
    /// iterations is not at least `stall_relative_decrease` below the lowest before
    /// them: rendering noise keeps the update above the thresholds above once the
    /// pose has settled (or is stuck). 0 turns the test off.
    pub stall_window: usize,
    /// The stall test's window in step 1's stages when a step 2 follows (`None`:
    /// `stall_window`): those stages only bring the pose into the next one's basin,
    /// which takes fewer iterations than settling at the optimum. 0 turns the test
    /// off there. A global search's refinements ignore it (their start, a
    /// low-resolution descent's end, may lie a grid spacing away).
    pub intermediate_stall_window: Option<usize>,
    /// Relative decrease of the cost the last `stall_window` iterations must achieve.
    pub stall_relative_decrease: f64,
    /// Beyond the paper (`None`: off): a stage has also converged when its last update
    /// moves the image by less than this many pixels of its pyramid level,
    /// `α (‖t‖ / ρ̄ + ‖ω‖)`, and changes λ by less than this many pixels: `α` the larger
    /// focal length of the level's camera, `1/ρ̄` the mean inverse range of the
    /// rendering's hits, `t` and `ω` the update's translation and rotation. Scale-free,
    /// unlike the thresholds in metres and radians above: a motion far below a pixel is
    /// not an error the image can show. The pixels are a pinhole's at the optical axis:
    /// a unified camera magnifies some directions more (up to 3.4 times at 120° off the
    /// axis for ξ = 0.9). Like the thresholds above it bounds the last step, not the
    /// distance left: with a gain below 1 or damping, a stage ends about that step
    /// divided by the gain away; and it ignores the vignetting's coefficients. Every
    /// stage but the global search's low-resolution descents (ranked after a set
    /// number of iterations).
    pub converged_px: Option<f32>,
    /// Beyond the paper (`None`: off, every iteration renders): a PGM stage on the
    /// common support renders only when the pose has moved the image by more than this
    /// many pixels of its level per pixel of λ (at least 1) since the last rendering
    /// (`α (‖t‖ / ρ̄ + ‖ω‖)`, as `converged_px` measures: a PGM of extent λ pixels
    /// changes little, and its `L_G` holds, over a motion of λ pixels), or λ by more
    /// than a fifth; in between, the picture is
    /// warped into the last rendering through its ranges, both are transformed on their
    /// common support, and the step takes that rendering's `L_G` and `J_λ` (the inverse
    /// compositional scheme: the residual from the picture itself, warped bilinearly
    /// through the rendering's ranges without occlusion; the Jacobian the last
    /// rendering's).
    /// Brightness stages (PoVS), the paper's support and the vignetting model render
    /// at every iteration.
    pub rerender_px: Option<f32>,
    /// With `rerender_px`: a method's last stage (step 2) ends on a rendered iteration. A
    /// stop met on a warped iteration (a step or a stall measured against the warp's
    /// approximation) renders at the next iteration, where the stop is tested again:
    /// the outcome's cost and last step compare the picture with a rendering at its
    /// pose. It costs about one rendering per localisation (a third more time for the
    /// localiser, half more per tracked frame) and moves the end by about 0.05 pixel:
    /// 1 mm instead of 3 mm from the truth on renderings, the same on photographs
    /// (`docs/RESULTS.md`, "Speed"). Off by default.
    pub end_on_rendering: bool,
    /// Divergence: the cost exceeds this multiple of the stage's initial cost.
    pub divergence_cost_factor: f64,
    /// Divergence: fewer than this fraction of the valid pixels see a point.
    pub min_hit_fraction: f64,
    /// Divergence: the camera leaves the cloud's bounding box enlarged by this (m).
    pub bounds_margin_m: f64,
    /// Beyond the paper (off by default): Levenberg–Marquardt damping `η`, solving
    /// `(JᵀJ + η diag(JᵀJ)) x = Jᵀe`.
    pub levenberg_marquardt: Option<f64>,
    /// Beyond the paper (`None`: off): in a method's last stage (step 2, or PoVS), an
    /// update that continues the last one (the cosine of the two above 0.9) and is
    /// shorter by a ratio `r` in (0.5, 1) is lengthened by `1 / (1 − r)`, at most this
    /// many times. Where Gauss–Newton converges linearly, each step `r` times the last
    /// (on a photograph the rendering's `L_G` overestimates the cost's curvature along
    /// a valley, `r` about 0.9), the steps left sum to the last one times `r / (1 − r)`:
    /// the lengthened update jumps to their end, and the convergence tests then measure
    /// it, an estimate of the distance left rather than one step of a crawl. Translations
    /// and rotations are compared as image motions (the translation over the
    /// rendering's mean range, as `converged_px`; a warped iteration's update is in the
    /// last rendering's frame, a second-order difference). Only the pose's update is
    /// lengthened, not λ's or the vignetting's. At least 1 (1: nothing lengthened).
    pub extrapolate_steps: Option<f64>,
    /// Beyond the paper (off by default): robust weighting of the residuals.
    pub robust: Option<Robust>,
    /// Beyond the paper (1: off): coarse-to-fine image pyramid. With `n` levels, step 1
    /// first runs at 1/2^(n−1) of the resolution with λ*₁ / 2^(n−1), then at each finer
    /// level (λ is in pixels, so it scales with the image); the coarse stages share
    /// step 1's budget (each at most `step1_max_iterations / stages`).
    pub pyramid_levels: u32,
    /// Beyond the paper (`None`: off): coarse to fine within step 1. Each of step 1's
    /// stages (λ*₁, then the λ schedule) runs at the coarsest of the `pyramid_levels`
    /// levels at which its λ* (pixels: halved at each level) stays at least this many
    /// pixels, in place of the pyramid's own stages; step 2 runs at full resolution.
    /// A wide PGM changes little from one pixel to the next, and a level of half the
    /// resolution renders and transforms about a third of the pixels' work.
    pub coarse_min_lambda_px: Option<f32>,
    /// Beyond the paper (empty: off): a λ schedule, extra step-1 stages at full
    /// resolution after λ*₁, each with its own desired extent λ* (decreasing, pixels),
    /// λ starting at λ* and optimised, sharing step 1's budget like the pyramid's.
    pub lambda_schedule: Vec<f32>,
    /// Centre and normalise the brightness of both images (§4, for real images).
    pub normalize: bool,
    /// Which pixels are compared.
    pub support: Support,
    /// PGM sample stride (1: every pixel).
    pub pgm_stride: u32,
    /// From this λ (pixels) up, the PGM's correlations use recursive filters (cost
    /// independent of λ, within 2.2e-4 of the exact kernels; see
    /// [`pgm::PgmOptions::recursive_from_lambda`]); below it, and always if it is
    /// infinite (`inf` in TOML), the exact kernels truncated at 4λ. Default 3.
    pub pgm_recursive_from_lambda: f32,
    /// The PGM's Convolved Jacobian on the recursive path keeps one row in
    /// `max(1, ⌊q λ⌋)` of its vertical pass and interpolates cubics between them (`q` this
    /// value; `G` and `J_λ` stay exact; see
    /// [`pgm::PgmOptions::interaction_row_step_lambdas`]); 0: every row. Default 0.2.
    pub pgm_interaction_row_step_lambdas: f32,
    /// Renderer level of detail (pixels between drawn points), `None` for every point.
    pub lod_spacing_px: Option<f32>,
    /// Beyond the paper: the settings of [`Method::Global`].
    pub global: crate::GlobalConfig,
    /// Beyond the paper (off by default): estimate a radial vignetting of the desired
    /// picture with the pose, as two more unknowns ([`crate::vignetting`]).
    pub vignetting: bool,
    /// Keep the per-iteration history in the outcome.
    pub keep_history: bool,
    /// Render and transform each image on rayon's threads. The results are the same
    /// either way; turn it off when the caller already keeps every thread busy with
    /// runs of its own (as `bench-conv` does).
    pub parallel: bool,
}

impl Default for VvsConfig {
    fn default() -> Self {
        Self {
            gain: 0.2,
            lambda_star_step1: 15.0,
            lambda_star_step2: 1.0,
            rule0_lambda_factor: 2.0,
            step1_max_iterations: 120,
            max_iterations: 250,
            jacobian: PgmJacobian::Convolved,
            converged_translation_m: 2e-5,
            converged_rotation_rad: 2e-5,
            stall_window: 10,
            intermediate_stall_window: None,
            stall_relative_decrease: 0.01,
            converged_px: None,
            rerender_px: None,
            end_on_rendering: false,
            divergence_cost_factor: 1e3,
            min_hit_fraction: 0.02,
            bounds_margin_m: 5.0,
            levenberg_marquardt: None,
            extrapolate_steps: None,
            robust: None,
            pyramid_levels: 1,
            coarse_min_lambda_px: None,
            lambda_schedule: Vec::new(),
            normalize: false,
            support: Support::Region,
            pgm_stride: 1,
            pgm_recursive_from_lambda: 3.0,
            pgm_interaction_row_step_lambdas: 0.2,
            lod_spacing_px: splat::RenderOptions::default().lod_spacing_px,
            global: crate::GlobalConfig::default(),
            vignetting: false,
            keep_history: true,
            parallel: true,
        }
    }
}

impl VvsConfig {
    /// Check every field against its documented range.
    pub fn validate(&self) -> Result<(), VvsError> {
        let bad = |name: &'static str, message: String| Err(VvsError::Config { name, message });
        if !(self.gain > 0.0 && self.gain <= 1.0) {
            return bad("gain", format!("must be in (0, 1], got {}", self.gain));
        }
        // Rule0's starting extent (factor × λ*₁) is checked when Rule0 runs.
        if !(self.rule0_lambda_factor > 0.0 && self.rule0_lambda_factor.is_finite()) {
            return bad(
                "rule0_lambda_factor",
                format!("must be > 0, got {}", self.rule0_lambda_factor),
            );
        }
        for (name, l) in [
            ("lambda_star_step1", self.lambda_star_step1),
            ("lambda_star_step2", self.lambda_star_step2),
        ] {
            if !pgm::LAMBDA_RANGE.contains(&l) {
                return bad(name, format!("{l} is outside [0.5, 40] px"));
            }
        }
        if self.max_iterations > MAX_ITERATIONS {
            return bad(
                "max_iterations",
                format!(
                    "{} exceeds the cap of {MAX_ITERATIONS}",
                    self.max_iterations
                ),
            );
        }
        if self.step1_max_iterations >= self.max_iterations {
            return bad(
                "step1_max_iterations",
                format!(
                    "{} leaves step 2 no iteration of max_iterations = {}",
                    self.step1_max_iterations, self.max_iterations
                ),
            );
        }
        for (name, v) in [
            ("converged_translation_m", self.converged_translation_m),
            ("converged_rotation_rad", self.converged_rotation_rad),
            ("divergence_cost_factor", self.divergence_cost_factor),
            ("bounds_margin_m", self.bounds_margin_m),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return bad(name, format!("must be > 0, got {v}"));
            }
        }
        if !(0.0..1.0).contains(&self.min_hit_fraction) {
            return bad(
                "min_hit_fraction",
                format!("must be in [0, 1), got {}", self.min_hit_fraction),
            );
        }
        if let Some(eta) = self.levenberg_marquardt
            && !(eta >= 0.0 && eta.is_finite())
        {
            return bad("levenberg_marquardt", format!("must be >= 0, got {eta}"));
        }
        if let Some(cap) = self.extrapolate_steps
            && !(cap >= 1.0 && cap.is_finite())
        {
            return bad("extrapolate_steps", format!("must be >= 1, got {cap}"));
        }
        if let Some(Robust::Tukey { c }) = self.robust
            && !(c > 0.0 && c.is_finite())
        {
            return bad("robust", format!("Tukey c must be > 0, got {c}"));
        }
        if let Some(px) = self.converged_px
            && !(px > 0.0 && px.is_finite())
        {
            return bad("converged_px", format!("must be > 0, got {px}"));
        }
        if let Some(px) = self.rerender_px
            && !(px > 0.0 && px.is_finite())
        {
            return bad("rerender_px", format!("must be > 0, got {px}"));
        }
        if !(0.0..1.0).contains(&self.stall_relative_decrease) {
            return bad(
                "stall_relative_decrease",
                format!("must be in [0, 1), got {}", self.stall_relative_decrease),
            );
        }
        if !(1..=4).contains(&self.pyramid_levels) {
            return bad(
                "pyramid_levels",
                format!("must be in 1..=4, got {}", self.pyramid_levels),
            );
        }
        // The pyramid's own stages (coarse to fine places λ*₁ at a level that keeps
        // it in range).
        let coarsest = self.lambda_star_step1 / (1u32 << (self.pyramid_levels - 1)) as f32;
        if self.coarse_min_lambda_px.is_none() && !pgm::LAMBDA_RANGE.contains(&coarsest) {
            return bad(
                "pyramid_levels",
                format!("λ*₁ at the coarsest level would be {coarsest} px, outside [0.5, 40]"),
            );
        }
        for &l in &self.lambda_schedule {
            if !pgm::LAMBDA_RANGE.contains(&l) {
                return bad("lambda_schedule", format!("{l} is outside [0.5, 40] px"));
            }
        }
        if let Some(l) = self.coarse_min_lambda_px
            && !pgm::LAMBDA_RANGE.contains(&l)
        {
            return bad(
                "coarse_min_lambda_px",
                format!("{l} is outside [0.5, 40] px"),
            );
        }
        let coarse_stages = match self.coarse_min_lambda_px {
            Some(_) => 1,
            None => self.pyramid_levels as usize,
        };
        let stages = coarse_stages + self.lambda_schedule.len();
        if self.step1_max_iterations < stages {
            return bad(
                "step1_max_iterations",
                format!(
                    "{} iterations cannot cover {stages} step-1 stages",
                    self.step1_max_iterations
                ),
            );
        }
        self.global.validate()?;
        if !(1..=MAX_PGM_STRIDE).contains(&self.pgm_stride) {
            return bad(
                "pgm_stride",
                format!("must be in 1..={MAX_PGM_STRIDE}, got {}", self.pgm_stride),
            );
        }
        if !(self.pgm_recursive_from_lambda > 0.0) {
            return bad(
                "pgm_recursive_from_lambda",
                format!("must be > 0, got {}", self.pgm_recursive_from_lambda),
            );
        }
        let q = self.pgm_interaction_row_step_lambdas;
        if !(q >= 0.0 && q.is_finite()) {
            return bad(
                "pgm_interaction_row_step_lambdas",
                format!("must be >= 0 and finite, got {q}"),
            );
        }
        Ok(())
    }

    /// Parse a TOML configuration (missing fields take their defaults; unknown fields
    /// are errors) and validate it.
    pub fn from_toml_str(text: &str) -> Result<Self, VvsError> {
        let config: Self = toml::from_str(text).map_err(|e| VvsError::ConfigFile(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// This configuration with the fields of `overrides` (a TOML table of
    /// [`VvsConfig`] fields, as in a protocol's or a sequence's `[vvs]`) replaced, then
    /// validated: a table (`global`) merges key by key, any other value
    /// replaces the field; fields the table does not name keep this configuration's
    /// values. The one way the project layers settings.
    pub fn with_overrides(&self, overrides: &toml::Table) -> Result<VvsConfig, VvsError> {
        fn merge(base: &mut toml::Table, overrides: &toml::Table) {
            for (key, value) in overrides {
                match (base.get_mut(key), value) {
                    (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
                    _ => {
                        base.insert(key.clone(), value.clone());
                    }
                }
            }
        }
        let mut table =
            toml::Table::try_from(self).map_err(|e| VvsError::ConfigFile(e.to_string()))?;
        merge(&mut table, overrides);
        let mut config: VvsConfig = table
            .try_into()
            .map_err(|e: toml::de::Error| VvsError::ConfigFile(e.to_string()))?;
        // TOML has no `None`: an absent optional field reads as its default, which for
        // the level of detail is not `None`.
        if !overrides.contains_key("lod_spacing_px") {
            config.lod_spacing_px = self.lod_spacing_px;
        }
        config.validate()?;
        Ok(config)
    }

    /// The configuration as TOML.
    pub fn to_toml_string(&self) -> Result<String, VvsError> {
        toml::to_string_pretty(self).map_err(|e| VvsError::ConfigFile(e.to_string()))
    }
}
