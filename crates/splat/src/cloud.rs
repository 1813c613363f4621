//! [`PointCloud`]: points laid out for rendering speed.
//!
//! * Each point is stored in 8 bytes ([`PackedPoint`]): its position as three 16-bit
//!   steps from its cell's corner (a step is [`PointCloud::step_m`], the cell's edge
//!   over 65 535: 31 µm in the default 2 m cells), its intensity in 16-bit fixed point.
//!   The corners are `f64` relative to an `f64` origin, so that a georeferenced cloud
//!   (coordinates of 10⁵–10⁶ m) keeps the same precision everywhere. Half the bytes of
//!   `f32` positions: the renderer reads every point it draws from memory, and a cloud
//!   of a city (millions of points) does not fit in the processor's caches.
//! * The intensity is in `[0, 1]`, the luminance of the point's colour (Rec. 709
//!   weights on the stored, gamma-encoded values: `0.2126 R + 0.7152 G + 0.0722 B`),
//!   rounded to 1/65 535 (the renderer's own fixed point).
//! * Points are grouped into cubic cells (visibility culling and level of detail). The
//!   order of the points is therefore **not** the input order: it is sorted by cell and,
//!   within a cell, shuffled deterministically so that any prefix of a cell is a uniform
//!   subsample of it.

use glam::DVec3;

use crate::SplatError;
use crate::rng::SplitMix64;
use rayon::prelude::*;

/// Rec. 709 luminance of an 8-bit-per-channel colour, in `[0, 1]`.
#[inline]
pub fn luminance(rgb: [u8; 3]) -> f32 {
    (0.2126 * f32::from(rgb[0]) + 0.7152 * f32::from(rgb[1]) + 0.0722 * f32::from(rgb[2])) / 255.0
}

/// One point as the renderer reads it (8 bytes): its position as steps of
/// [`PointCloud::step_m`] from its cell's [`Cell::corner_m`] along x, y and z, and its
/// intensity in 16-bit fixed point (`intensity / 65535`, in `[0, 1]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(8))]
pub struct PackedPoint {
    /// Steps from the cell's corner along x, y, z.
    pub steps: [u16; 3],
    /// Intensity, `65535` for 1.
    pub intensity: u16,
}

/// A group of consecutive points of the cloud inside one cubic cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    /// First point.
    pub start: u32,
    /// Number of points.
    pub len: u32,
    /// The cell's lowest corner, relative to the cloud's origin: its points lie at
    /// `corner_m + steps · step_m`.
    pub corner_m: [f64; 3],
    /// Centre of the bounding sphere, relative to the cloud's origin.
    pub center: [f32; 3],
    /// Radius of the bounding sphere, metres.
    pub radius: f32,
}

/// A coloured point cloud ready to render.
#[derive(Clone, Debug)]
pub struct PointCloud {
    origin: DVec3,
    points: Vec<PackedPoint>,
    colors: Option<Vec<[u8; 3]>>,
    cells: Vec<Cell>,
    spacing_m: f32,
    cell_size_m: f32,
    /// The cell's edge over 65 535.
    step_m: f64,
    /// Axis-aligned bounds of the decoded points, world coordinates (set once built).
    bounds: (DVec3, DVec3),
}

/// Steps along a cell's edge: positions are rounded to the edge over this.
const STEPS: f64 = 65_535.0;

/// Largest distance (along any axis) of a point from the cloud's origin, metres: the
/// cells' centres (culling) are `f32` relative to the origin, whose spacing there is
/// 6 cm (the points themselves are exact to a step everywhere).
pub const MAX_OFFSET_M: f64 = 1e6;

/// Smallest edge of the culling / level-of-detail cells, metres.
pub const MIN_CELL_SIZE_M: f32 = 1e-3;

/// Default edge of the culling / level-of-detail cells, metres.
pub const DEFAULT_CELL_SIZE_M: f32 = 2.0;

impl PointCloud {
    /// Build a cloud from world positions and per-point intensities in `[0, 1]`
    /// (clamped), with optional 8-bit colours. `origin` is subtracted from every
    /// position (pass the cloud's minimum corner or centre for georeferenced data).
    /// `spacing_m` is the typical distance between neighbouring points on a surface
    /// (it sizes the splats); `None` estimates it from the data.
    ///
    /// Errors: no point, a non-finite coordinate or intensity, a point farther than
    /// [`MAX_OFFSET_M`] from `origin`, attribute lengths that differ, more than
    /// `u32::MAX` points.
    pub fn from_points(
        origin: DVec3,
        positions: &[DVec3],
        intensities: &[f32],
        colors: Option<Vec<[u8; 3]>>,
        spacing_m: Option<f32>,
    ) -> Result<Self, SplatError> {
        Self::build(
            origin,
            positions,
            intensities,
            colors,
            spacing_m,
            DEFAULT_CELL_SIZE_M,
        )
    }

    /// As [`PointCloud::from_points`], with the cell size of the spatial index (at
    /// least [`MIN_CELL_SIZE_M`]). Positions are rounded to the cell's edge over
    /// 65 535: 31 µm in 2 m cells, 1.5 mm in 100 m cells.
    pub fn build(
        origin: DVec3,
        positions: &[DVec3],
        intensities: &[f32],
        colors: Option<Vec<[u8; 3]>>,
        spacing_m: Option<f32>,
        cell_size_m: f32,
    ) -> Result<Self, SplatError> {
        let n = positions.len();
        if n == 0 {
            return Err(SplatError::EmptyCloud);
        }
        if n > u32::MAX as usize {
            return Err(SplatError::TooManyPoints(n));
        }
        if intensities.len() != n {
            return Err(SplatError::AttributeLength {
                what: "intensities",
                got: intensities.len(),
                expected: n,
            });
        }
        if let Some(c) = &colors
            && c.len() != n
        {
            return Err(SplatError::AttributeLength {
                what: "colors",
                got: c.len(),
                expected: n,
            });
        }
        if !(cell_size_m.is_finite() && cell_size_m >= MIN_CELL_SIZE_M) {
            return Err(SplatError::Parameter {
                name: "cell_size_m",
                message: format!("must be finite and >= {MIN_CELL_SIZE_M} m, got {cell_size_m}"),
            });
        }
        if !origin.is_finite() {
            return Err(SplatError::Parameter {
                name: "origin",
                message: format!("the cloud's origin {origin} is not finite"),
            });
        }
        // The first bad point, found on rayon's threads.
        let bad_point = positions.par_iter().position_first(|p| {
            !(p.is_finite() && (*p - origin).abs().max_element() <= MAX_OFFSET_M)
        });
        if let Some(index) = bad_point {
            let p = positions[index];
            if !p.is_finite() {
                return Err(SplatError::NonFinitePoint {
                    index,
                    value: p.to_array(),
                });
            }
            let offset = (p - origin).abs().max_element();
            return Err(SplatError::Parameter {
                name: "positions",
                message: format!(
                    "point {index} at {p} lies {offset:.3e} m from the origin {origin}; \
                     cells are located in f32 relative to the origin and must stay \
                     within {MAX_OFFSET_M:.0e} m of it"
                ),
            });
        }
        if let Some(index) = intensities.iter().position(|i| !i.is_finite()) {
            return Err(SplatError::Parameter {
                name: "intensities",
                message: format!("intensity of point {index} is {}", intensities[index]),
            });
        }
        if let Some(s) = spacing_m
            && !(s.is_finite() && s > 0.0)
        {
            return Err(SplatError::Parameter {
                name: "spacing_m",
                message: format!("must be finite and > 0, got {s}"),
            });
        }

        // Cell key of every point, then a stable order: by cell, shuffled within.
        let inv = 1.0 / f64::from(cell_size_m);
        let key = |p: &DVec3| {
            let c = ((*p - origin) * inv).floor();
            (c.x as i64, c.y as i64, c.z as i64)
        };
        // The shuffle's random keys: the generator's sequence, point by point.
        const SHUFFLE_SEED: u64 = 0x5EED_CE11;
        let mut order: Vec<(i64, i64, i64, u64, u32)> = positions
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let (x, y, z) = key(p);
                (
                    x,
                    y,
                    z,
                    SplitMix64::nth_value(SHUFFLE_SEED, i as u64),
                    i as u32,
                )
            })
            .collect();
        // Every key holds the point's index, so any sort gives the same order: sorted
        // on rayon's threads.
        order.par_sort_unstable();

        // Each point rounded to a step of its cell (clamped: the cell's key was floored
        // in f64), in that order.
        let cell_m = f64::from(cell_size_m);
        let step_m = cell_m / STEPS;
        let cell_of = |o: &(i64, i64, i64, u64, u32)| (o.0, o.1, o.2);
        let corner_of =
            |o: &(i64, i64, i64, u64, u32)| DVec3::new(o.0 as f64, o.1 as f64, o.2 as f64) * cell_m;
        let points: Vec<PackedPoint> = order
            .par_iter()
            .map(|o| {
                let i = o.4 as usize;
                let steps = ((positions[i] - origin - corner_of(o)) / step_m)
                    .round()
                    .clamp(DVec3::ZERO, DVec3::splat(STEPS));
                PackedPoint {
                    steps: steps.to_array().map(|s| s as u16),
                    intensity: fixed_intensity(intensities[i]),
                }
            })
            .collect();
        let sorted_colors = colors.as_ref().map(|c| {
            order
                .par_iter()
                .map(|o| c[o.4 as usize])
                .collect::<Vec<_>>()
        });
        // The cells: runs of one key.
        let starts: Vec<usize> = (0..n)
            .into_par_iter()
            .filter(|&i| i == 0 || cell_of(&order[i]) != cell_of(&order[i - 1]))
            .collect();
        let cells_and_bounds: Vec<(Cell, DVec3, DVec3)> = starts
            .par_iter()
            .enumerate()
            .map(|(c, &start)| {
                let end = starts.get(c + 1).copied().unwrap_or(n);
                let corner = corner_of(&order[start]);
                let mut lo = DVec3::splat(f64::INFINITY);
                let mut hi = DVec3::splat(f64::NEG_INFINITY);
                for point in &points[start..end] {
                    // As `decode` places it.
                    let steps = DVec3::from_array(point.steps.map(f64::from));
                    let p = corner + steps * step_m;
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                let center = (lo + hi) * 0.5;
                // The centre is kept in `f32` (and placed in the camera frame in `f32`):
                // a margin of 1 mm, or four of its roundings if more (a cell over about
                // 2 km from the origin), so that the sphere holds every point.
                let margin = 1e-3f32.max(4.0 * center.abs().max_element() as f32 * f32::EPSILON);
                let cell = Cell {
                    start: start as u32,
                    len: (end - start) as u32,
                    corner_m: corner.to_array(),
                    center: center.as_vec3().to_array(),
                    radius: ((hi - lo).length() * 0.5) as f32 + margin,
                };
                (cell, lo, hi)
            })
            .collect();
        let (lo, hi) = cells_and_bounds.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), (_, l, h)| (lo.min(*l), hi.max(*h)),
        );
        let cells = cells_and_bounds.into_iter().map(|(c, ..)| c).collect();
        let mut cloud = Self {
            origin,
            points,
            colors: sorted_colors,
            cells,
            spacing_m: 0.0,
            cell_size_m,
            step_m,
            bounds: (origin + lo, origin + hi),
        };
        cloud.spacing_m = match spacing_m {
            Some(s) => s,
            None => cloud.estimate_spacing(),
        };
        Ok(cloud)
    }

    /// Median nearest-neighbour distance of a deterministic sample of points (searched
    /// within their cell).
    fn estimate_spacing(&self) -> f32 {
        let mut rng = SplitMix64::new(17);
        let mut distances = Vec::new();
        let cells: Vec<&Cell> = self.cells.iter().filter(|c| c.len > 1).collect();
        if cells.is_empty() {
            return self.cell_size_m * 0.5;
        }
        for _ in 0..2000 {
            let cell = cells[rng.below(cells.len() as u64) as usize];
            let range = cell.start as usize..(cell.start + cell.len.min(4096)) as usize;
            let pts = &self.points[range];
            let a = pts[rng.below(pts.len() as u64) as usize].steps;
            // Squared distances in steps (exact integers).
            let best = pts
                .iter()
                .map(|b| {
                    (0..3)
                        .map(|k| (i64::from(a[k]) - i64::from(b.steps[k])).pow(2))
                        .sum::<i64>()
                })
                .filter(|&d| d > 0)
                .min();
            if let Some(best) = best {
                distances.push(((best as f64).sqrt() * self.step_m) as f32);
            }
        }
        if distances.is_empty() {
            return self.cell_size_m * 0.5;
        }
        distances.sort_unstable_by(f32::total_cmp);
        distances[distances.len() / 2]
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Always false: an empty cloud cannot be built.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The origin subtracted from every position.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The points as the renderer reads them, cell after cell ([`PointCloud::cells`]).
    pub fn points(&self) -> &[PackedPoint] {
        &self.points
    }

    /// The step of the points' positions, metres: a cell's edge over 65 535.
    pub fn step_m(&self) -> f64 {
        self.step_m
    }

    /// Every point as its position relative to [`PointCloud::origin`] and its
    /// intensity in `[0, 1]`, in point order.
    pub fn decoded(&self) -> impl Iterator<Item = (DVec3, f32)> + '_ {
        self.cells.iter().flat_map(move |cell| {
            let range = cell.start as usize..(cell.start + cell.len) as usize;
            self.points[range].iter().map(move |p| self.decode(cell, p))
        })
    }

    /// Point `i`'s position relative to [`PointCloud::origin`] and its intensity
    /// (`None` past the last point).
    pub fn point(&self, i: usize) -> Option<(DVec3, f32)> {
        let p = self.points.get(i)?;
        // The last cell starting at or before `i`.
        let cell = &self.cells[self.cells.partition_point(|c| c.start as usize <= i) - 1];
        Some(self.decode(cell, p))
    }

    fn decode(&self, cell: &Cell, p: &PackedPoint) -> (DVec3, f32) {
        let steps = DVec3::new(
            f64::from(p.steps[0]),
            f64::from(p.steps[1]),
            f64::from(p.steps[2]),
        );
        (
            DVec3::from_array(cell.corner_m) + steps * self.step_m,
            f32::from(p.intensity) / 65535.0,
        )
    }

    /// Per-point 8-bit colours, if the source had colour.
    pub fn colors(&self) -> Option<&[[u8; 3]]> {
        self.colors.as_deref()
    }

    /// The spatial cells, in point order.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// Typical point spacing on a surface, metres (sizes the splats).
    pub fn spacing_m(&self) -> f32 {
        self.spacing_m
    }

    /// Override the point spacing (must be finite and > 0).
    pub fn set_spacing_m(&mut self, spacing_m: f32) -> Result<(), SplatError> {
        if !(spacing_m.is_finite() && spacing_m > 0.0) {
            return Err(SplatError::Parameter {
                name: "spacing_m",
                message: format!("must be finite and > 0, got {spacing_m}"),
            });
        }
        self.spacing_m = spacing_m;
        Ok(())
    }

    /// World position of point `i` (panics past the last point).
    pub fn world_position(&self, i: usize) -> DVec3 {
        let (p, _) = self.point(i).expect("a point of the cloud");
        self.origin + p
    }

    /// Axis-aligned bounds `(min, max)` of the points, in world coordinates.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }
}

/// An intensity in `[0, 1]` (clamped) in 16-bit fixed point, rounded as the renderer
/// rounds it (`⌊65535 i + 0.5⌋` in `f32`).
fn fixed_intensity(intensity: f32) -> u16 {
    (intensity.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}
