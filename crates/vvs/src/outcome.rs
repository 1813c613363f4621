//! What a run returns.

use serde::{Deserialize, Serialize};
use ucm::Isometry3;

/// Why a run diverged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Divergence {
    /// Too few valid pixels see a point (the camera left the scene or is inside a wall).
    NoValidPixels,
    /// The cost grew beyond the configured multiple of its initial value.
    CostExploded,
    /// The camera left the cloud's (enlarged) bounding box.
    LeftBounds,
    /// A NaN or infinite value appeared (cost, pose, λ).
    NotFinite,
    /// The linear system had no usable direction.
    SingularSystem,
}

/// Why a run stopped. Written by its [`StopReason::name`] in files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum StopReason {
    /// The last stage converged (the update fell below the thresholds).
    Converged,
    /// The iteration budget ran out.
    IterationBudget,
    /// The cost stopped decreasing (see `VvsConfig::stall_window`): settled at the
    /// noise floor, or stuck.
    Stalled,
    /// The run diverged.
    Diverged(Divergence),
}

impl StopReason {
    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            StopReason::Converged => "converged",
            StopReason::IterationBudget => "budget",
            StopReason::Stalled => "stalled",
            StopReason::Diverged(Divergence::NoValidPixels) => "diverged:no_valid_pixels",
            StopReason::Diverged(Divergence::CostExploded) => "diverged:cost_exploded",
            StopReason::Diverged(Divergence::LeftBounds) => "diverged:left_bounds",
            StopReason::Diverged(Divergence::NotFinite) => "diverged:not_finite",
            StopReason::Diverged(Divergence::SingularSystem) => "diverged:singular",
        }
    }
}

impl StopReason {
    /// Every reason, in the order of their names' documentation.
    pub const ALL: [StopReason; 8] = [
        StopReason::Converged,
        StopReason::IterationBudget,
        StopReason::Stalled,
        StopReason::Diverged(Divergence::NoValidPixels),
        StopReason::Diverged(Divergence::CostExploded),
        StopReason::Diverged(Divergence::LeftBounds),
        StopReason::Diverged(Divergence::NotFinite),
        StopReason::Diverged(Divergence::SingularSystem),
    ];
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for StopReason {
    type Err = crate::VvsError;

    /// The reason of a [`StopReason::name`].
    fn from_str(text: &str) -> Result<Self, crate::VvsError> {
        StopReason::ALL
            .into_iter()
            .find(|r| r.name() == text.trim())
            .ok_or_else(|| crate::VvsError::UnknownName {
                what: "stop reason",
                text: text.to_string(),
                expected: StopReason::ALL.map(StopReason::name).join(", "),
            })
    }
}

impl TryFrom<String> for StopReason {
    type Error = crate::VvsError;

    fn try_from(text: String) -> Result<Self, crate::VvsError> {
        text.parse()
    }
}

impl From<StopReason> for String {
    fn from(reason: StopReason) -> String {
        reason.name().to_string()
    }
}

/// One iteration, for plots and debugging.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    /// Step (1 or 2; PoVS has one).
    pub stage: u8,
    /// Pyramid level (0: full resolution).
    pub level: u8,
    /// `world_from_camera` before the update, as the paper's `(t, θw)`.
    pub pose: [f64; 6],
    /// Extent λ used at this iteration (0 for PoVS).
    pub lambda: f32,
    /// Mean squared residual.
    pub cost: f64,
    /// Translation of the update, metres.
    pub update_translation_m: f64,
    /// Rotation of the update, radians.
    pub update_rotation_rad: f64,
    /// Wall time of the iteration (render + feature + solve), seconds.
    pub time_s: f64,
    /// Whether the iteration compared with a rendering at its own pose (rendered, or
    /// the frame already rendered there; `false`: it compared the picture warped into
    /// the last rendering, [`crate::VvsConfig::rerender_px`]).
    #[serde(default = "rendered_by_default")]
    pub rendered: bool,
}

/// Histories written before [`IterationRecord::rendered`] rendered at every iteration.
fn rendered_by_default() -> bool {
    true
}

/// The result of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// Final `world_from_camera`.
    pub world_from_camera: Isometry3,
    /// Final λ (0 for PoVS).
    pub lambda: f32,
    /// Final mean squared residual.
    pub cost: f64,
    /// Why it stopped.
    pub stop: StopReason,
    /// Iterations of step 1 and step 2 (PoVS: all in the first).
    pub iterations: [usize; 2],
    /// Per-iteration history (empty if not kept).
    pub history: Vec<IterationRecord>,
    /// Time spent in the stages, seconds (a step 1 shared by
    /// [`crate::Servo::run_methods`] counts in full for every method sharing it; a
    /// global search counts all of its phases).
    pub time_s: f64,
    /// The vignetting coefficients `(c₁, c₂)` estimated with the pose
    /// ([`crate::VvsConfig::vignetting`] only).
    #[serde(default)]
    pub vignetting: Option<[f64; 2]>,
    /// What the global search did ([`crate::Method::Global`] only).
    #[serde(default)]
    pub search: Option<crate::SearchReport>,
}
