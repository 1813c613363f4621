//! Which cells of the cloud a rendering draws, and in which order: field-of-view
//! culling and level of detail ([`Renderer::select_cells`]), and occlusion culling
//! ([`Renderer::occluded`]) against a conservative image rectangle of each cell.

use glam::Vec3;

use crate::PointCloud;

use super::Renderer;
use super::project::{floor_small, limit};
use super::view::View;

#[derive(Clone, Copy, Debug)]
pub(super) struct DrawCell {
    pub(super) start: u32,
    pub(super) count: u32,
    pub(super) spacing_m: f32,
    /// The cell's corner in the camera frame ([`View::in_cell`]).
    pub(super) corner: Vec3,
}

/// A cell in the field of view, before the occlusion test.
#[derive(Clone, Copy, Debug)]
pub(super) struct Candidate {
    pub(super) cell: DrawCell,
    /// Centre in the camera frame.
    center: Vec3,
    /// Bounding radius, metres.
    radius: f32,
    /// Lower bound of the range of its points, metres (the drawing order).
    nearest_m: f32,
}

/// Side of the tiles of the occlusion test, pixels.
const TILE: usize = 8;

/// Tiles along an image side of `pixels`.
pub(super) fn tiles(pixels: usize) -> usize {
    pixels.div_ceil(TILE)
}

impl Renderer {
    /// Magnification (pixels per radian, the larger of radial and tangential) at an
    /// angle `θ` off the optical axis.
    fn magnification(&self, theta: f32) -> f32 {
        let i = self.camera.intrinsics();
        let alpha = i.alpha_u.max(i.alpha_v) as f32;
        let xi = i.xi as f32;
        let c = theta.cos();
        let d = (c + xi).max(1e-3);
        alpha * ((1.0 + xi * c) / (d * d)).max(1.0 / d)
    }

    /// Field-of-view culling and level of detail: fill `self.candidates`, nearest
    /// first.
    #[inline(always)]
    pub(super) fn select_cells(&mut self, cloud: &PointCloud, view: &View) {
        self.candidates.clear();
        let spacing = cloud.spacing_m();
        let lod = self.options.lod_spacing_px;
        for cell in cloud.cells() {
            let c = view.rotation * Vec3::from_array(cell.center) + view.translation;
            let d = c.length();
            let (visible, theta_edge) = if d <= cell.radius {
                (true, self.theta_max)
            } else {
                let theta = (c.z / d).clamp(-1.0, 1.0).acos();
                let beta = (cell.radius / d).min(1.0).asin();
                (
                    theta - beta <= self.theta_max && theta + beta >= self.theta_min,
                    (theta + beta).clamp(self.theta_min, self.theta_max),
                )
            };
            if !visible {
                continue;
            }
            let mut count = cell.len;
            let mut spacing_m = spacing;
            if let Some(target) = lod {
                let nearest = (d - cell.radius).max(1e-3);
                let spacing_px = spacing * self.magnification(theta_edge) / nearest;
                if spacing_px < target {
                    let fraction = (spacing_px / target).powi(2);
                    count = ((cell.len as f32 * fraction).ceil() as u32).clamp(1, cell.len);
                    spacing_m = spacing * (cell.len as f32 / count as f32).sqrt();
                }
            }
            self.candidates.push(Candidate {
                cell: DrawCell {
                    start: cell.start,
                    count,
                    spacing_m,
                    corner: view.corner(cell.corner_m),
                },
                center: c,
                radius: cell.radius,
                nearest_m: (d - cell.radius).max(0.0),
            });
        }
        // Front to back; ties by position in the cloud, so the order is total. Sorted
        // as integers: a non-negative range orders as its bits (a `-0.0` would come
        // last, which only the time could notice: the image does not depend on the
        // order in which cells are drawn).
        self.order.clear();
        self.order.extend(
            self.candidates
                .iter()
                .enumerate()
                .map(|(i, c)| (u64::from(c.nearest_m.to_bits()) << 32) | i as u64),
        );
        self.order.sort_unstable();
    }

    /// Whether every pixel that a point of `candidate` could cover already holds a
    /// range nearer than the cell by more than the depth band (then the cell can
    /// change nothing). Conservative: `false` whenever in doubt. Takes the renderer
    /// mutably for the tiles' cache; the depth buffer holds every thread's minima
    /// between batches.
    #[inline(always)]
    pub(super) fn occluded(&mut self, candidate: &Candidate, view: &View) -> bool {
        let Some([u0, u1, v0, v1]) = self.image_rect(candidate, view) else {
            return false;
        };
        if u0 > u1 || v0 > v1 {
            return true; // entirely outside the region: nothing would be drawn there
        }
        let w = self.region.width;
        // Margins cover the f32 rounding of the points' ranges and of the band test.
        let nearest = candidate.nearest_m * (1.0 - 1e-4) - 1e-3;
        // Whether every pixel is nearer than the cell by more than the band, given the
        // farthest range seen so far (an empty pixel's key is a NaN: false).
        let hides = |farthest: u32| {
            f32::from_bits(farthest) * (1.0 + view.depth_band) * (1.0 + 1e-4) < nearest
        };
        // First the tiles holding the rectangle (each tile's farthest key bounds its
        // pixels'): most occluded cells are decided there, without reading every pixel.
        let tiles_wide = tiles(self.region.width);
        let mut hidden_by_tiles = true;
        'tiles: for tv in v0 / TILE..=v1 / TILE {
            for tu in u0 / TILE..=u1 / TILE {
                if !hides(self.tile_farthest(tv * tiles_wide + tu, tu, tv)) {
                    hidden_by_tiles = false;
                    break 'tiles;
                }
            }
        }
        if hidden_by_tiles {
            return true;
        }
        // Masked pixels hold the key 0: they never raise the farthest.
        let mut farthest = 0u32;
        for row in v0..=v1 {
            let depth = &self.depth[row * w + u0..=row * w + u1];
            farthest = depth.iter().fold(farthest, |f, &d| f.max(d));
            // The farthest range only grows: stop at the first row that decides.
            if !hides(farthest) {
                return false;
            }
        }
        true
    }

    /// The farthest key of the valid pixels of tile `index` (column `tu`, row `tv`),
    /// recomputed if a batch was drawn since.
    #[inline(always)]
    fn tile_farthest(&mut self, index: usize, tu: usize, tv: usize) -> u32 {
        if self.tile_batch[index] != self.batch {
            let (w, h) = (self.region.width, self.region.height);
            let (u0, u1) = (tu * TILE, ((tu + 1) * TILE).min(w));
            let mut farthest = 0u32;
            for row in tv * TILE..((tv + 1) * TILE).min(h) {
                let depth = &self.depth[row * w + u0..row * w + u1];
                farthest = depth.iter().fold(farthest, |f, &d| f.max(d));
            }
            self.tile_farthest[index] = farthest;
            self.tile_batch[index] = self.batch;
        }
        self.tile_farthest[index]
    }

    /// A pixel rectangle `[u0, u1, v0, v1]` (inclusive, clipped to the image; empty if
    /// outside it) holding every pixel that a splat of a point of the candidate's
    /// bounding sphere can cover, or `None` if it cannot be bounded (the sphere holds
    /// the centre, or reaches the edge of the model's domain).
    ///
    /// The sphere's directions form a cone of half-angle `β = asin(R/d)` around the
    /// centre's, at angle `θc` off the axis. For `ξ ≤ 1` (no transcendental function):
    /// the UCM's projection of the unit sphere onto the normalised plane stretches
    /// lengths by at most `max(r'(θ), r(θ)/sin θ)` at angle `θ`, with
    /// `r(θ) = sin θ / (cos θ + ξ)`; both factors increase with `θ` there, so every
    /// direction of the cone lands within `tan β · max(r'(θc + β), r(θc + β)/sin(θc + β))`
    /// of the centre's image (a geodesic of length at most `β ≤ tan β` joins them
    /// inside the cone), and the affine intrinsics stretch that disc by at most their
    /// largest singular value. For `ξ > 1`, see [`Renderer::sector_box`].
    #[inline(always)]
    fn image_rect(&self, candidate: &Candidate, view: &View) -> Option<[usize; 4]> {
        let c = candidate.center;
        let d = c.length();
        if !(d > candidate.radius * 1.01 + 1e-3) {
            return None;
        }
        let xi = view.xi;
        if xi > 1.0 {
            let [u_lo, u_hi, v_lo, v_hi] = self.sector_box(candidate, view)?;
            return clip_rect([u_lo, u_hi, v_lo, v_hi], view.max_width as f32 * 0.5, view);
        }
        // The cone, widened for rounding: sin β, cos β; the centre's cos θc, sin θc.
        let sin_b = (candidate.radius / d * 1.001 + 1e-4).min(1.0);
        let cos_b = (1.0 - sin_b * sin_b).max(0.0).sqrt();
        let cos_c = (c.z / d).clamp(-1.0, 1.0);
        let sin_c = (1.0 - cos_c * cos_c).max(0.0).sqrt();
        // θc + β < π, and cos(θc + β) inside the domain (cos θ + ξ > 0) by a margin.
        let cos_hi = cos_c * cos_b - sin_c * sin_b;
        if !(cos_b > -cos_c) || !(cos_hi + xi > 1e-3) || !(cos_b > 0.0) {
            return None;
        }
        let denominator = cos_hi + xi;
        let radial = (1.0 + xi * cos_hi) / (denominator * denominator);
        let tangential = 1.0 / denominator;
        let radius = sin_b / cos_b * radial.max(tangential) * view.affine_norm * 1.001 + 1e-3;
        // The centre's image.
        let dd = c.z + xi * d;
        let (x, y) = (c.x / dd, c.y / dd);
        let u = view.alpha_u * x + view.skew * y + view.u0;
        let v = view.alpha_v * y + view.v0;
        // Splat half-width: size = spacing · scale · M(θ) / ρ, M increasing in θ for
        // ξ ≤ 1 (see `magnification`).
        let magnification = view.alpha * radial.max(tangential);
        let size = candidate.cell.spacing_m * view.splat_scale * magnification
            / (d - candidate.radius).max(1e-3);
        let half = (size * 0.5 + 1.0).min(view.max_width as f32 * 0.5);
        clip_rect([u - radius, u + radius, v - radius, v + radius], half, view)
    }

    /// The image box `[u_lo, u_hi, v_lo, v_hi]` of the directions of the candidate's
    /// bounding sphere, for any `ξ`: the UCM maps a direction at angle `θ` off the axis
    /// and azimuth `φ` to the normalised point `r(θ) (cos φ, sin φ)` with
    /// `r(θ) = sin θ / (cos θ + ξ)`, increasing over the drawable domain; the cone of
    /// half-angle `β` gives `θ ∈ [θc − β, θc + β]` and `|φ − φc| ≤ asin(sin β / sin θc)`:
    /// an annular sector, whose bounding box the affine intrinsics map to the image.
    /// `None` where the cone reaches the domain's edge.
    fn sector_box(&self, candidate: &Candidate, view: &View) -> Option<[f32; 4]> {
        let c = candidate.center;
        let d = c.length();
        let xi = view.xi;
        let theta_c = (c.z / d).clamp(-1.0, 1.0).acos();
        let beta = (candidate.radius / d).asin() * 1.001 + 1e-4;
        let theta_hi = theta_c + beta;
        // The domain's edge: cos θ + ξ > 0 (ξ ≤ 1), or 1 + ξ cos θ > 0 (ξ > 1).
        let cos_limit = if xi > 1.0 { -1.0 / xi } else { -xi };
        if theta_hi >= std::f32::consts::PI || theta_hi.cos() <= cos_limit + 1e-3 {
            return None;
        }
        let r = |theta: f32| theta.sin() / (theta.cos() + xi);
        let r_hi = r(theta_hi);
        let (mut x0, mut x1, mut y0, mut y1);
        if theta_c <= beta {
            // The cone holds the axis: a disc.
            (x0, x1, y0, y1) = (-r_hi, r_hi, -r_hi, r_hi);
        } else {
            let r_lo = r(theta_c - beta).max(0.0);
            let phi_c = c.y.atan2(c.x);
            let dphi = (beta.sin() / theta_c.sin()).min(1.0).asin();
            let (a0, a1) = (phi_c - dphi, phi_c + dphi);
            (x0, x1, y0, y1) = (
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
            );
            let mut include = |x: f32, y: f32| {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            };
            for a in [a0, a1] {
                let (sin, cos) = a.sin_cos();
                include(r_lo * cos, r_lo * sin);
                include(r_hi * cos, r_hi * sin);
            }
            // Axis directions inside the angular range reach the outer radius.
            for k in -4..=4 {
                let a = k as f32 * std::f32::consts::FRAC_PI_2;
                if a > a0 && a < a1 {
                    let (sin, cos) = a.sin_cos();
                    include(r_hi * cos, r_hi * sin);
                }
            }
        }
        // Image of the box under the affine intrinsics.
        let mut u_lo = f32::INFINITY;
        let mut u_hi = f32::NEG_INFINITY;
        for (x, y) in [(x0, y0), (x0, y1), (x1, y0), (x1, y1)] {
            let u = view.alpha_u * x + view.skew * y + view.u0;
            u_lo = u_lo.min(u);
            u_hi = u_hi.max(u);
        }
        Some([
            u_lo,
            u_hi,
            view.alpha_v * y0 + view.v0,
            view.alpha_v * y1 + view.v0,
        ])
    }
}

/// The pixel rectangle of an image box `[u_lo, u_hi, v_lo, v_hi]` of projections,
/// widened by splats of half-width `half` (and 2 pixels of margin), clipped to the
/// region and counted from its first pixel (empty if outside it); `None` if the box is
/// not finite.
#[inline(always)]
fn clip_rect(image_box: [f32; 4], half: f32, view: &View) -> Option<[usize; 4]> {
    if !image_box.iter().all(|x| x.is_finite()) {
        return None;
    }
    let [u_lo, u_hi, v_lo, v_hi] = image_box;
    let pad = half + 2.0;
    let clip = |lo: f32, hi: f32, origin: i32, n: i32| -> (usize, usize) {
        // Limited to just outside the region first, so that floor_small applies.
        let (first, last) = (origin as f32 - 2.0, (origin + n) as f32 + 1.0);
        let lo = (floor_small(limit(lo - pad, first, last)) - origin).max(0);
        let hi = -floor_small(-limit(hi + pad, first, last)) - origin;
        let hi = hi.min(n - 1);
        if lo > hi {
            (1, 0)
        } else {
            (lo as usize, hi as usize)
        }
    };
    let [origin_u, origin_v] = view.origin;
    let (u0, u1) = clip(u_lo, u_hi, origin_u, view.width);
    let (v0, v1) = clip(v_lo, v_hi, origin_v, view.height);
    Some([u0, u1, v0, v1])
}

#[cfg(test)]
mod tests {
    //! The occlusion test's rectangle against the splats it must hold.

    use glam::{DMat3, DVec3, Vec3};
    use proptest::prelude::*;

    use super::*;
    use crate::render::project::project_steps;
    use crate::render::tests::{regions, test_setup};

    proptest! {
        /// The occlusion test's rectangle of a cell holds every pixel that a splat of a
        /// point of the cell's bounding sphere covers: the disc bound (ξ ≤ 1) and the
        /// annular sector (ξ > 1), for random intrinsics, spheres and splat sizes.
        #[test]
        fn image_rect_holds_every_splat(
            seed in any::<u64>(),
            alpha_u in 50.0f32..400.0,
            aspect in 0.8f32..1.25,
            skew in -3.0f32..3.0,
            xi in 0.0f32..2.0,
            direction in prop::array::uniform3(-1.0f32..1.0),
            distance_m in 0.5f32..200.0,
            radius_m in 0.02f32..3.0,
            spacing_m in 0.005f32..0.3,
            splat_scale in 0.5f32..3.0,
            max_radius in 0u32..12,
            region in regions(),
        ) {
            let (camera, options) = test_setup(alpha_u, aspect, skew, xi, splat_scale, max_radius);
            let renderer = Renderer::new(camera.clone(), options).unwrap();
            // Steps of a metre from the cloud's origin: points are where they are.
            let view = View::new(&camera, &options, region, DMat3::IDENTITY, DVec3::ZERO, 1.0);
            let center = Vec3::from_array(direction).normalize_or(Vec3::Z) * distance_m;
            let candidate = Candidate {
                cell: DrawCell { start: 0, count: 1, spacing_m, corner: Vec3::ZERO },
                center,
                radius: radius_m,
                nearest_m: (distance_m - radius_m).max(0.0),
            };
            let Some([ru0, ru1, rv0, rv1]) = renderer.image_rect(&candidate, &view) else {
                return Ok(()); // no bound claimed
            };
            let footprint = spacing_m * view.alpha * splat_scale;
            let mut rng = crate::rng::SplitMix64::new(seed);
            for _ in 0..256 {
                // A point of the sphere (its surface included).
                let offset = Vec3::new(
                    rng.unit() as f32 * 2.0 - 1.0,
                    rng.unit() as f32 * 2.0 - 1.0,
                    rng.unit() as f32 * 2.0 - 1.0,
                );
                let offset = offset.clamp_length_max(1.0) * radius_m;
                let p = center + offset;
                let Some(splat) = project_steps(p, 32_768, footprint, &view, &camera) else {
                    continue;
                };
                splat.for_each_pixel(&view, |k| {
                    let (u, v) = (k % region.width, k / region.width);
                    assert!(
                        (ru0..=ru1).contains(&u) && (rv0..=rv1).contains(&v),
                        "pixel ({u}, {v}) of a splat of {p} outside [{ru0}, {ru1}] x [{rv0}, {rv1}]"
                    );
                });
            }
        }
    }
}
