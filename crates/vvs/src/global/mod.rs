//! Global localisation inside a prior region (beyond the paper): [`Method::Global`].
//!
//! The paper's rules are local: from ±8 m along the street they converge only where the
//! PGM cost at λ* has no other minimum on the way (`docs/RESULTS.md`: on our city the
//! basin of Rule2 ends 2 m along the street, a quarter of the paper's 8 m). A robot rarely starts blind,
//! though: a GPS fix and a compass bound its pose to a box. Inside such a box this
//! search finds the pose in three phases, every one deterministic:
//!
//! 1. **Candidates.** The positions the truth can take relative to the initial pose
//!    (the box's translation corners, turned by the box's rotation corners, see
//!    [`PriorBox`]) are covered by a regular grid of at most
//!    [`GlobalConfig::grid_spacing_m`] between nodes; each node keeps the initial
//!    orientation (the paper's rules recover ±10°/±10°/±15° from a start whose
//!    position is close enough: `docs/RESULTS.md`); when the box's heading range
//!    (rotation about the optical axis, `θwZ`) exceeds
//!    [`GlobalConfig::heading_spacing_deg`] (15°), every node takes every heading of
//!    the box at most that far apart: a robot with a GPS fix and no compass gives
//!    `rotation_deg[2] = 180`. Likewise tilts beyond [`GlobalConfig::tilt_spacing_deg`]
//!    (10°) are tried that far apart.
//! 2. **Screening and descents, at low resolution.** Every candidate is scored by the
//!    PGM cost at λ*₁ on an image [`GlobalConfig::search_downsampling`] times smaller
//!    (λ scaled alike, so the same angular blur). Orientations cost no rendering: a
//!    central camera turned about its centre sees the same rays, so each node is
//!    rendered once and compared with the desired image turned back by each heading
//!    and tilt (resampled once per orientation, [`turned_about_optical_axis`],
//!    [`turned`]); a tilt leaves part of the field unobserved, and only the samples
//!    farther than 2λ from it are compared (on the common support, candidates whose
//!    coverage alone puts both scores beyond the `2 screened`-th best of each list so
//!    far are not compared: the same candidates are kept). The
//!    [`GlobalConfig::screened`] best run [`GlobalConfig::descent_iterations`]
//!    iterations of step 1 there (λ optimised),
//!    and are ranked again by their cost (with [`GlobalConfig::prune_after_iterations`],
//!    every descent first runs that many iterations and only the
//!    [`GlobalConfig::pruned_to`] best run on: the `Localizer`'s default, 3 then the 10
//!    best, measured in `docs/RESULTS.md`, "Nothing lost on renderings"); descents that
//!    end outside the box (grown by a grid spacing and [`BOX_MARGIN_DEG`],
//!    [`PriorBox::holds`]) are dropped, and those that end within
//!    [`GlobalConfig::merge_distance_m`] (at most a quarter of the smallest grid
//!    spacing) of a better one as duplicates.
//! 3. **Refinement.** The best, and up to [`GlobalConfig::refined`] in all ranked
//!    within [`GlobalConfig::refine_within`] of it, run
//!    [`GlobalConfig::refine_method`] at full resolution, every stage to the full stall
//!    window (a descent's pose may lie a grid spacing from the optimum along a shallow
//!    valley; [`crate::VvsConfig::intermediate_stall_window`] is for starts already in
//!    the next stage's basin, and a search ignores it); the outcome with the lowest
//!    final cost wins (a diverged one only when every one diverged; if every node
//!    diverged already at low resolution, the initial pose itself is refined, and the
//!    outcome says how it ends).
//!
//! The defaults were chosen by measurement on a second city (seed 2, not the default
//! city of the protocols): from the paper's offsets, 112 of 112 runs converged with
//! 20 descents and 1 refinement (40 descents and 3 refinements: the same, twice the
//! time). Costs are compared as the mean squared residual each run reports; with Tukey
//! weighting (`VvsConfig::robust`) each run weighs its own residuals, so the ranking
//! is then approximate.
//!
//! On the common support ([`crate::Support::Common`], the `Localizer`'s) each candidate
//! is compared on the pixels its rendering and the picture share, so scores of
//! candidates that see different parts of the picture must not favour the smaller
//! part: each score is the fraction of the picture left unexplained, the pixels not
//! compared counting as unexplained (`1 − c·r`, `c` the fraction of the picture's
//! pixels compared, `r` how well the samples compared agree). The screening keeps the
//! [`GlobalConfig::screened`] best with `r` the PGMs' correlation (on a photograph a
//! small, smooth support matches anything in the squared difference) and as many with
//! `r` their coefficient of determination, one minus their mean squared difference
//! over the picture's variance (which tells renderings apart whose PGMs differ in
//! contrast alone), and the descents are ranked by the first at their end, the picture
//! unturned: their own costs compare pictures normalised over supports of different
//! shapes. (Dividing each shortfall by `c` instead let candidates above the roofs or
//! below the street, seeing a flat patch, win twice the paper's box: `docs/RESULTS.md`.)
//! Scores are ≥ 0 (`r ≤ 1`); a candidate whose either PGM is flat on the samples
//! compared has none.
//!
//! The outcome is that of the winning refinement, with a [`SearchReport`] of what the
//! search did and its whole time in `time_s`.

mod prior;
mod search;
mod select;

pub(crate) use search::SearchWorker;
mod turn;

use serde::{Deserialize, Serialize};

pub use prior::{BOX_MARGIN_DEG, PriorBox};
pub use turn::{turned, turned_about_optical_axis};

use crate::{Method, VvsError};

/// Settings of [`Method::Global`] (`VvsConfig::global`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GlobalConfig {
    /// Largest distance between grid nodes along the initial camera's X, Y, Z, metres.
    pub grid_spacing_m: [f64; 3],
    /// Largest angle between the headings tried at each node, degrees, when the box's
    /// heading range `±rotation_deg[2]` exceeds it (default 15°, measured; `None`, or a
    /// box within ±15°: every node keeps the initial heading, which the rules correct
    /// within about ±19°).
    pub heading_spacing_deg: Option<f64>,
    /// Largest angle between the tilts (`θwX`, `θwY`) tried at each node, degrees,
    /// when the box's tilt range exceeds it (default 10°, measured; `None`, or a box
    /// within ±10°: every node keeps the initial tilts).
    pub tilt_spacing_deg: Option<f64>,
    /// The screening and the descents run on images this many times smaller (λ*₁ too).
    pub search_downsampling: u32,
    /// Beyond the paper (default false): the screening and the descents (with
    /// `search_downsampling` above 1) render a copy of the cloud with one point in
    /// `search_downsampling²` of each cell, laid out in cells of `search_cell_size_m`
    /// ([`splat::PointCloud::thinned`], made at a servo's first search): an image with
    /// that many times fewer pixels, with that many times fewer points a pixel as the
    /// full resolution has of the cloud, whatever the camera's resolution; its
    /// rendering's time went to the cells' work more than to the points. The
    /// refinements render the cloud itself. Its spacing is the cloud's times
    /// `search_downsampling`, so a cell with fewer points than that keeps one with larger
    /// splats.
    pub thin_search_cloud: bool,
    /// The thinned copy's cells' edge, metres (with `thin_search_cloud`).
    pub search_cell_size_m: f32,
    /// Candidates kept after screening, each then descends. On the common support
    /// ([`crate::Support::Common`]) this many by each of two scores (the fraction of
    /// the picture the PGMs' correlation, or their coefficient of determination,
    /// leaves unexplained), so up to twice as many descents.
    pub screened: usize,
    /// Iterations of each low-resolution descent.
    pub descent_iterations: usize,
    /// Pruned descents (0: off; else below [`GlobalConfig::descent_iterations`]):
    /// every descent first runs this many iterations, then only the
    /// [`GlobalConfig::pruned_to`] best, ranked as the descents are at their end, run
    /// on to `descent_iterations` in a new stage from where they stopped (λ kept; its
    /// stall test and divergence reference start again there); the others, and those
    /// that diverged, are dropped.
    pub prune_after_iterations: usize,
    /// Descents that run on after [`GlobalConfig::prune_after_iterations`].
    pub pruned_to: usize,
    /// Descents ending this close to a better one are duplicates (metres; at most a
    /// quarter of the smallest of [`GlobalConfig::grid_spacing_m`], so that in a small
    /// box two basins a few grid nodes apart stay distinct).
    pub merge_distance_m: f64,
    /// The most descents refined at full resolution (the best one always).
    pub refined: usize,
    /// The descents after the best are refined only when their rank is within this
    /// fraction of the best's (`rank ≤ best · (1 + refine_within)`): where the
    /// low-resolution ranking cannot tell two basins apart, the full-resolution costs
    /// do (`docs/RESULTS.md`, 7-Scenes' `global`); where it can, one refinement is run
    /// (infinite: always [`GlobalConfig::refined`]; ranks are ≥ 0, a best of 0 refines
    /// only its ties).
    pub refine_within: f64,
    /// The method that refines them (a PGM rule or PoVS).
    pub refine_method: Method,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        Self {
            grid_spacing_m: [2.0, 2.0, 1.5],
            heading_spacing_deg: Some(15.0),
            tilt_spacing_deg: Some(10.0),
            search_downsampling: 4,
            thin_search_cloud: false,
            search_cell_size_m: 4.0,
            screened: 20,
            descent_iterations: 10,
            prune_after_iterations: 0,
            pruned_to: 10,
            merge_distance_m: 0.5,
            refined: 1,
            refine_within: 0.25,
            refine_method: Method::Rule2,
        }
    }
}

/// The most candidates (grid nodes × orientations) a search may have (a bound on its
/// time; they take 24 bytes each).
pub const MAX_CANDIDATES: usize = 1_000_000;

/// The most headings a search may try at each node (0.1° apart around the circle).
pub const MAX_HEADINGS: usize = 3600;

impl GlobalConfig {
    /// Check every field against its documented range. The prior box and the number of
    /// candidates it needs are checked when a search runs (they do not concern the
    /// other methods).
    pub fn validate(&self) -> Result<(), VvsError> {
        let bad = |name: &'static str, message: String| Err(VvsError::Config { name, message });
        for s in self.grid_spacing_m {
            if !(s > 0.0 && s.is_finite()) {
                return bad("global.grid_spacing_m", format!("must be > 0, got {s}"));
            }
        }
        if let Some(s) = self.heading_spacing_deg
            && !(s > 0.0 && s <= 360.0)
        {
            return bad(
                "global.heading_spacing_deg",
                format!("must be in (0, 360], got {s}"),
            );
        }
        if let Some(s) = self.tilt_spacing_deg
            && !(s > 0.0 && s <= 180.0)
        {
            return bad(
                "global.tilt_spacing_deg",
                format!("must be in (0, 180], got {s}"),
            );
        }
        if !(1..=16).contains(&self.search_downsampling) {
            return bad(
                "global.search_downsampling",
                format!("must be in 1..=16, got {}", self.search_downsampling),
            );
        }
        if !(self.search_cell_size_m.is_finite()
            && (0.1..=1000.0).contains(&self.search_cell_size_m))
        {
            return bad(
                "global.search_cell_size_m",
                format!("must be in [0.1, 1000] m, got {}", self.search_cell_size_m),
            );
        }
        // Counts of candidates at most MAX_CANDIDATES (a search keeps lists of them), of
        // iterations at most the servo's cap.
        for (name, v, cap) in [
            ("global.screened", self.screened, MAX_CANDIDATES),
            (
                "global.descent_iterations",
                self.descent_iterations,
                crate::config::MAX_ITERATIONS,
            ),
            ("global.refined", self.refined, MAX_CANDIDATES),
            ("global.pruned_to", self.pruned_to, MAX_CANDIDATES),
        ] {
            if !(1..=cap).contains(&v) {
                return bad(name, format!("must be in 1..={cap}, got {v}"));
            }
        }
        if self.prune_after_iterations >= self.descent_iterations && self.prune_after_iterations > 0
        {
            return bad(
                "global.prune_after_iterations",
                format!(
                    "must be 0 (off) or below descent_iterations ({}), got {}",
                    self.descent_iterations, self.prune_after_iterations
                ),
            );
        }
        if !(self.merge_distance_m >= 0.0 && self.merge_distance_m.is_finite()) {
            return bad(
                "global.merge_distance_m",
                format!("must be >= 0, got {}", self.merge_distance_m),
            );
        }
        if !(self.refine_within >= 0.0) {
            return bad(
                "global.refine_within",
                format!("must be >= 0, got {}", self.refine_within),
            );
        }
        if self.refine_method == Method::Global {
            return bad("global.refine_method", "must be a local method".into());
        }
        Ok(())
    }
}

/// What a global search did (in [`crate::Outcome::search`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchReport {
    /// Grid nodes screened.
    pub candidates: usize,
    /// Low-resolution descents run.
    pub descents: usize,
    /// Descents that ran on after [`GlobalConfig::prune_after_iterations`] (0 without
    /// pruning).
    pub continued: usize,
    /// Full-resolution refinements run.
    pub refinements: usize,
    /// Iterations of every low-resolution descent together.
    pub descent_iterations: usize,
    /// Position of the winning node in the initial camera's frame, metres (`None`:
    /// every node diverged and the initial pose itself was refined).
    pub chosen_node_m: Option<[f64; 3]>,
    /// Heading at which the winning node started, relative to the initial pose,
    /// degrees (0 without heading search; `None` when `chosen_node_m` is `None`).
    pub chosen_heading_deg: Option<f64>,
    /// Rank of the winner among the refinements (0: the best descent).
    pub chosen_rank: usize,
    /// Final cost of every refinement, in rank order (infinite: diverged).
    pub refined_costs: Vec<f64>,
    /// Wall time of each phase, seconds: screening (with the desired image's
    /// preparation), low-resolution descents, full-resolution refinements.
    pub phase_times_s: [f64; 3],
}

/// A phase of a global search.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SearchPhase {
    /// The cost of every grid node at low resolution.
    Screening,
    /// Low-resolution descents from the best nodes.
    Descents,
    /// Full-resolution refinements of the best descents.
    Refinements,
}

impl SearchPhase {
    /// The phase's name, lower case.
    pub fn name(self) -> &'static str {
        match self {
            SearchPhase::Screening => "screening",
            SearchPhase::Descents => "descents",
            SearchPhase::Refinements => "refinements",
        }
    }
}

/// Where a global search stands, given to a progress callback
/// ([`crate::Servo::localize_in_box_with_progress`]) after each node screened, each
/// descent and each refinement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SearchProgress {
    /// The phase.
    pub phase: SearchPhase,
    /// Items of the phase done.
    pub done: usize,
    /// Items of the phase in all (the descents' phase: the descents, and as many as
    /// may run on after [`GlobalConfig::prune_after_iterations`]: fewer do when some
    /// diverged; its last report has `done = total`).
    pub total: usize,
}
