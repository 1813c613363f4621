//! Global localisation inside a prior region (beyond the paper): [`Method::Global`].
//!
//! The paper's rules are local: from ±8 m along the street they converge only where the
//! PGM cost at λ* has no other minimum on the way (`docs/RESULTS.md`: on our city the
//! basin of Rule2 ends near half of the paper's offsets). A robot rarely starts blind,
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
//!    farther than 2λ from it are compared. The [`GlobalConfig::screened`] best
//!    run [`GlobalConfig::descent_iterations`] iterations of step 1 there (λ optimised),
//!    and are ranked again by their cost; descents that end outside the box (grown by
//!    a grid spacing and [`BOX_MARGIN_DEG`], [`PriorBox::holds`]) are dropped, and those
//!    that end within [`GlobalConfig::merge_distance_m`] of a better one as duplicates.
//! 3. **Refinement.** The [`GlobalConfig::refined`] best run
//!    [`GlobalConfig::refine_method`] at full resolution; the outcome with the lowest
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
//! part: both scores below are divided by the fraction of the picture's pixels
//! compared. The screening keeps the [`GlobalConfig::screened`] best by one minus the
//! PGMs' correlation (on a photograph a small, smooth support matches anything in the
//! squared difference) and as many by their mean squared difference (which tells
//! renderings apart whose PGMs differ in contrast alone), and the descents are ranked
//! by the correlation at their end, the picture unturned: their own costs compare
//! pictures normalised over supports of different shapes.
//!
//! The outcome is that of the winning refinement, with a [`SearchReport`] of what the
//! search did and its whole time in `time_s`.

use frame::{AnyImage, Image};
use serde::{Deserialize, Serialize};
use ucm::{Camera, Isometry3};

use crate::{Method, VvsError};

/// Degrees a descent may end beyond the prior box's rotations and still be ranked
/// ([`PriorBox::holds`]; its translations may end a grid spacing beyond).
pub const BOX_MARGIN_DEG: f64 = 5.0;

/// The prior region of a global localisation: how far the initial pose may be from the
/// truth. It is the error model of the paper's protocol: `initial = truth · (t, θw)`
/// with `|t_k| ≤ translation_m[k]` and `|θw_k| ≤ rotation_deg[k]` (the paper's pose
/// vector, in the true camera's frame), so the truth lies at the corner of the box when
/// every offset is at its largest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorBox {
    /// Largest `|tX|, |tY|, |tZ|`, metres.
    pub translation_m: [f64; 3],
    /// Largest `|θwX|, |θwY|, |θwZ|`, degrees.
    pub rotation_deg: [f64; 3],
}

impl Default for PriorBox {
    /// The paper's offsets (§3.1): ±8 m, ±2 m, ±1.5 m and ±10°, ±10°, ±15°.
    fn default() -> Self {
        Self {
            translation_m: [8.0, 2.0, 1.5],
            rotation_deg: [10.0, 10.0, 15.0],
        }
    }
}

impl PriorBox {
    /// Check the box: finite, non-negative, tilts (`θwX`, `θwY`) below 90°, heading
    /// (`θwZ`) at most 180° (180: any heading).
    pub fn validate(&self) -> Result<(), VvsError> {
        let bad = |message: String| {
            Err(VvsError::Config {
                name: "global.prior",
                message,
            })
        };
        for t in self.translation_m {
            if !(0.0..=1e4).contains(&t) {
                return bad(format!("translations must be in [0, 10000] m, got {t}"));
            }
        }
        for r in &self.rotation_deg[..2] {
            if !(0.0..90.0).contains(r) {
                return bad(format!("tilts must be in [0, 90) degrees, got {r}"));
            }
        }
        let heading = self.rotation_deg[2];
        if !(0.0..=180.0).contains(&heading) {
            return bad(format!(
                "the heading must be in [0, 180] degrees, got {heading}"
            ));
        }
        Ok(())
    }

    /// Whether `pose` (`world_from_camera`) could be the truth of a search started at
    /// `initial`: the offset `(t, θw) = pose⁻¹ · initial` within the box grown by
    /// `margin_m` (per axis) and `margin_deg` (any heading at 180°).
    pub fn holds(
        &self,
        initial: &Isometry3,
        pose: &Isometry3,
        margin_m: [f64; 3],
        margin_deg: f64,
    ) -> bool {
        let offset = (pose.inverse() * *initial).to_pose_vector();
        let within_translation =
            (0..3).all(|k| offset[k].abs() <= self.translation_m[k] + margin_m[k]);
        let within_rotation = (0..3).all(|k| {
            (k == 2 && self.rotation_deg[2] >= 180.0)
                || offset[3 + k].abs().to_degrees() <= self.rotation_deg[k] + margin_deg
        });
        within_translation && within_rotation
    }

    /// The half-extents, along the initial camera's axes, of the positions the truth
    /// can take relative to the initial pose: the largest `|p_k|` of
    /// `p = translation of (t, θw)⁻¹ = −R(θw)ᵀ t` over the box (a box of 8 m turned by
    /// 15° reaches 4 m across). For a fixed rotation `|p_k|` is largest at a corner of
    /// the translation box (it is linear in `t`); the rotations are sampled on a grid
    /// of at least 11 values per axis, corners included, at most 2° apart.
    pub fn position_extent_m(&self) -> [f64; 3] {
        let r = self.rotation_deg.map(f64::to_radians);
        let steps = self
            .rotation_deg
            .map(|d| (d.ceil() as usize).clamp(10, 180)); // 2d / 2° steps
        let t = self.translation_m;
        let sample = |k: usize, i: usize| r[k] * (2.0 * i as f64 / steps[k] as f64 - 1.0);
        let mut extent = [0.0f64; 3];
        for (i, j, l) in (0..=steps[0])
            .flat_map(|i| (0..=steps[1]).flat_map(move |j| (0..=steps[2]).map(move |l| (i, j, l))))
        {
            let rotation = [sample(0, i), sample(1, j), sample(2, l)];
            let Ok(turn) =
                Isometry3::from_pose_vector([0.0, 0.0, 0.0, rotation[0], rotation[1], rotation[2]])
            else {
                continue; // not finite: refused by `validate`
            };
            let inverse = turn.inverse();
            for corner in 0..8u32 {
                let sign = |k: u32| if corner >> k & 1 == 1 { -1.0 } else { 1.0 };
                let p = inverse.transform_vector(glam::DVec3::new(
                    sign(0) * t[0],
                    sign(1) * t[1],
                    sign(2) * t[2],
                ));
                for (e, v) in extent.iter_mut().zip([p.x, p.y, p.z]) {
                    *e = e.max(v.abs());
                }
            }
        }
        extent
    }

    /// Grid nodes along each axis for at most `spacing_m` between them
    /// (`⌈2e / spacing⌉ + 1`, or 1 where the extent `e` is 0).
    fn axis_counts(&self, spacing_m: [f64; 3]) -> Result<[usize; 3], VvsError> {
        self.validate()?;
        let extent = self.position_extent_m();
        let mut counts = [1usize; 3];
        let mut total = 1.0f64;
        for k in 0..3 {
            let s = spacing_m[k];
            if !(s > 0.0 && s.is_finite()) {
                return Err(VvsError::Config {
                    name: "global.grid_spacing_m",
                    message: format!("must be > 0, got {s}"),
                });
            }
            let n = if extent[k] > 0.0 {
                (2.0 * extent[k] / s - 1e-9).ceil().max(1.0) + 1.0
            } else {
                1.0
            };
            total *= n;
            if total > MAX_CANDIDATES as f64 {
                return Err(VvsError::Config {
                    name: "global.grid_spacing_m",
                    message: format!(
                        "the prior box {:?} m, {:?}° would need more than {MAX_CANDIDATES} candidates at {spacing_m:?} m",
                        self.translation_m, self.rotation_deg
                    ),
                });
            }
            counts[k] = n as usize;
        }
        Ok(counts)
    }

    /// The candidate positions (in the initial camera's frame) of a grid covering
    /// [`Self::position_extent_m`] with at most `spacing_m` between nodes: along each
    /// axis `n = ⌈2e / spacing⌉ + 1` nodes from `−e` to `e` (one node at 0 when `e` is
    /// 0). Ordered X-major, then Y, then Z. Errors on an invalid box or spacing, or
    /// past [`MAX_CANDIDATES`] nodes.
    pub fn grid(&self, spacing_m: [f64; 3]) -> Result<Vec<[f64; 3]>, VvsError> {
        let counts = self.axis_counts(spacing_m)?;
        let extent = self.position_extent_m();
        let axis = |k: usize| -> Vec<f64> {
            let n = counts[k];
            if n == 1 {
                return vec![0.0];
            }
            let e = extent[k];
            (0..n)
                .map(|i| -e + 2.0 * e * i as f64 / (n - 1) as f64)
                .collect()
        };
        let (xs, ys, zs) = (axis(0), axis(1), axis(2));
        let mut out = Vec::with_capacity(xs.len() * ys.len() * zs.len());
        for &x in &xs {
            for &y in &ys {
                for &z in &zs {
                    out.push([x, y, z]);
                }
            }
        }
        Ok(out)
    }

    /// The headings (rotations about the optical axis, radians) a search with at most
    /// `spacing_deg` between them tries: `[0]` without a spacing or when the box's
    /// heading range is within it (the rules recover that much: the paper's ±15°);
    /// otherwise `2m + 1` values `iθ/m`, `|i| ≤ m = ⌈θ / spacing⌉` (`θ = rotation_deg[2]`:
    /// the initial heading and both ends included), and at 180° `⌈360 / spacing⌉`
    /// values around the circle from 0. Sorted by magnitude (0 first). Errors on an
    /// invalid box or spacing, or past [`MAX_HEADINGS`] headings.
    pub fn headings_rad(&self, spacing_deg: Option<f64>) -> Result<Vec<f64>, VvsError> {
        self.validate()?;
        let theta = self.rotation_deg[2];
        let Some(spacing) = spacing_deg.filter(|&s| theta > s) else {
            return Ok(vec![0.0]);
        };
        let count = if theta >= 180.0 {
            360.0 / spacing
        } else {
            2.0 * (theta / spacing).ceil() + 1.0
        };
        if !(spacing > 0.0 && count <= MAX_HEADINGS as f64) {
            return Err(VvsError::Config {
                name: "global.heading_spacing_deg",
                message: format!(
                    "{spacing}° between headings over ±{theta}° would need more than {MAX_HEADINGS} headings"
                ),
            });
        }
        let mut out: Vec<f64> = if theta >= 180.0 {
            let n = (360.0 / spacing - 1e-9).ceil().max(1.0) as usize;
            (0..n)
                .map(|i| {
                    let d = 360.0 * i as f64 / n as f64;
                    if d > 180.0 { d - 360.0 } else { d }
                })
                .collect()
        } else {
            let m = (theta / spacing - 1e-9).ceil().max(1.0) as i64;
            (-m..=m).map(|i| theta * i as f64 / m as f64).collect()
        };
        out.sort_by(|a, b| a.abs().total_cmp(&b.abs()).then(a.total_cmp(b)));
        Ok(out.into_iter().map(f64::to_radians).collect())
    }
}

impl PriorBox {
    /// The tilts (`θwX` for `k` = 0, `θwY` for 1, radians) a search with at most
    /// `spacing_deg` between them tries: `[0]` without a spacing or when the box's tilt
    /// range is within it; otherwise `2m + 1` values `iθ/m`, `|i| ≤ m = ⌈θ / spacing⌉`,
    /// sorted by magnitude.
    pub fn tilts_rad(&self, k: usize, spacing_deg: Option<f64>) -> Result<Vec<f64>, VvsError> {
        self.validate()?;
        let theta = self.rotation_deg[k.min(1)];
        let Some(spacing) = spacing_deg.filter(|&s| theta > s) else {
            return Ok(vec![0.0]);
        };
        if !(spacing > 0.0 && 2.0 * (theta / spacing).ceil() + 1.0 <= MAX_HEADINGS as f64) {
            return Err(VvsError::Config {
                name: "global.tilt_spacing_deg",
                message: format!("{spacing}° between tilts over ±{theta}° is too many"),
            });
        }
        let m = (theta / spacing - 1e-9).ceil().max(1.0) as i64;
        let mut out: Vec<f64> = (-m..=m).map(|i| theta * i as f64 / m as f64).collect();
        out.sort_by(|a, b| a.abs().total_cmp(&b.abs()).then(a.total_cmp(b)));
        Ok(out.into_iter().map(f64::to_radians).collect())
    }
}

/// `picture` as the camera would see it turned by `angle_rad` about its optical axis
/// (`world_from_camera · Rz(angle)`): each pixel takes the bilinear interpolation of
/// `picture` where its ray, turned by the angle, meets the image. Pixels whose four
/// neighbours there are not all observed (outside the valid region, or unobserved) are
/// not observed. Exact up to the interpolation for any camera model: turning about the
/// optical axis changes no ray, only which pixel sees it.
pub fn turned_about_optical_axis(
    picture: &impl AnyImage,
    camera: &Camera,
    angle_rad: f64,
) -> Result<Image, VvsError> {
    let (sin, cos) = angle_rad.sin_cos();
    resampled_by_rays(picture, camera, |ray| {
        [
            cos * ray[0] - sin * ray[1],
            sin * ray[0] + cos * ray[1],
            ray[2],
        ]
    })
}

/// `picture` as the camera would see it turned by `rotation` about its centre
/// (`world_from_camera · rotation`), where the turned camera's field overlaps the
/// original one (elsewhere not observed): [`turned_about_optical_axis`] for any
/// rotation (a central camera's rays do not depend on its orientation).
pub fn turned(
    picture: &impl AnyImage,
    camera: &Camera,
    rotation: glam::DQuat,
) -> Result<Image, VvsError> {
    resampled_by_rays(picture, camera, |ray| {
        rotation.mul_vec3(glam::DVec3::from_array(ray)).to_array()
    })
}

/// Each pixel of the result takes the bilinear interpolation of `picture` where the
/// ray `turn(ray of the pixel)` meets the image.
fn resampled_by_rays(
    picture: &impl AnyImage,
    camera: &Camera,
    turn: impl Fn([f64; 3]) -> [f64; 3],
) -> Result<Image, VvsError> {
    if picture.width() != camera.width() || picture.height() != camera.height() {
        return Err(VvsError::DesiredSize {
            got_width: picture.width(),
            got_height: picture.height(),
            width: camera.width(),
            height: camera.height(),
        });
    }
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let source = picture.intensity();
    let valid = camera.valid_pixels();
    let observed = |k: usize| valid[k] && picture.is_observed(k);
    let mut intensity = vec![0.0f32; w * h];
    let mut seen = vec![false; w * h];
    for (k, (value, seen)) in intensity.iter_mut().zip(&mut seen).enumerate() {
        if !valid[k] {
            continue;
        }
        let Ok(ray) = camera.unproject([(k % w) as f64, (k / w) as f64]) else {
            continue;
        };
        // The turned camera's ray in the frame of the camera before the turn.
        let Ok([u, v]) = camera.project_unbounded(turn(ray)) else {
            continue;
        };
        let (u0, v0) = (u.floor(), v.floor());
        if !(u0 >= 0.0 && v0 >= 0.0 && u0 + 1.0 < w as f64 && v0 + 1.0 < h as f64) {
            continue;
        }
        let (i, j) = (u0 as usize, v0 as usize);
        let corners = [
            j * w + i,
            j * w + i + 1,
            (j + 1) * w + i,
            (j + 1) * w + i + 1,
        ];
        if !corners.iter().all(|&c| observed(c)) {
            continue;
        }
        let (fu, fv) = ((u - u0) as f32, (v - v0) as f32);
        let [a, b, c, d] = corners.map(|c| source[c]);
        *value = (a * (1.0 - fu) + b * fu) * (1.0 - fv) + (c * (1.0 - fu) + d * fu) * fv;
        *seen = true;
    }
    Ok(Image::from_parts(
        camera.width(),
        camera.height(),
        intensity,
        seen,
    )?)
}

/// Settings of [`Method::Global`] (`VvsConfig::global`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GlobalConfig {
    /// The prior region searched when the method is run through `Servo::run`.
    pub prior: PriorBox,
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
    /// Candidates kept after screening, each then descends. On the common support
    /// ([`crate::Support::Common`]) this many by each of two scores (the PGMs'
    /// correlation and their mean squared difference, each divided by the fraction
    /// of the picture compared), so up to twice as many descents.
    pub screened: usize,
    /// Iterations of each low-resolution descent.
    pub descent_iterations: usize,
    /// Descents ending this close to a better one are duplicates (metres).
    pub merge_distance_m: f64,
    /// Descents refined at full resolution.
    pub refined: usize,
    /// The method that refines them (a PGM rule or PoVS).
    pub refine_method: Method,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        Self {
            prior: PriorBox::default(),
            grid_spacing_m: [2.0, 2.0, 1.5],
            heading_spacing_deg: Some(15.0),
            tilt_spacing_deg: Some(10.0),
            search_downsampling: 4,
            screened: 20,
            descent_iterations: 10,
            merge_distance_m: 0.5,
            refined: 1,
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
        for (name, v) in [
            ("global.screened", self.screened),
            ("global.descent_iterations", self.descent_iterations),
            ("global.refined", self.refined),
        ] {
            if v == 0 {
                return bad(name, "must be >= 1".into());
            }
        }
        if !(self.merge_distance_m >= 0.0 && self.merge_distance_m.is_finite()) {
            return bad(
                "global.merge_distance_m",
                format!("must be >= 0, got {}", self.merge_distance_m),
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
    /// Items of the phase in all.
    pub total: usize,
}
