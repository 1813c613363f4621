//! [`PriorBox`]: the region a global search covers, its grid of positions and its
//! orientations.

use serde::{Deserialize, Serialize};
use ucm::Isometry3;

use super::{MAX_CANDIDATES, MAX_HEADINGS};
use crate::VvsError;

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
                name: "prior",
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
