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
        let bad_point = first_index(positions, |p| {
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
        if let Some(index) = first_index(intensities, |i| !i.is_finite()) {
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
        let key = |p: &DVec3| ((*p - origin) * inv).to_array().map(floor_to_i64);
        let Layout {
            order,
            cell_keys,
            starts,
        } = Layout::new(positions, &key);

        // Each point rounded to a step of its cell (clamped: the cell's key was floored
        // in f64), in that order.
        let cell_m = f64::from(cell_size_m);
        let step_m = cell_m / STEPS;
        let corner_of = |k: &[i64; 3]| DVec3::new(k[0] as f64, k[1] as f64, k[2] as f64) * cell_m;
        let end_of = |c: usize| starts.get(c + 1).copied().unwrap_or(n);
        let mut points = vec![PackedPoint::default(); n];
        split_by_cell(&mut points, &starts)
            .into_par_iter()
            .enumerate()
            .for_each(|(c, cell_points)| {
                let corner = corner_of(&cell_keys[c]);
                for (point, &i) in cell_points.iter_mut().zip(&order[starts[c]..end_of(c)]) {
                    let i = i as usize;
                    let steps = (positions[i] - origin - corner) / step_m;
                    *point = PackedPoint {
                        steps: steps.to_array().map(nearest_step),
                        intensity: fixed_intensity(intensities[i]),
                    };
                }
            });
        let sorted_colors = colors
            .as_ref()
            .map(|c| order.par_iter().map(|&i| c[i as usize]).collect::<Vec<_>>());
        let cells_and_bounds: Vec<(Cell, DVec3, DVec3)> = starts
            .par_iter()
            .enumerate()
            .map(|(c, &start)| {
                let end = end_of(c);
                let corner = corner_of(&cell_keys[c]);
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
        let cells: Vec<&Cell> = self.cells.iter().filter(|c| c.len > 1).collect();
        if cells.is_empty() {
            return self.cell_size_m * 0.5;
        }
        // The sample drawn first (the generator's order), the searches on rayon's
        // threads.
        let samples: Vec<(&Cell, u64)> = (0..2000)
            .map(|_| {
                let cell = cells[rng.below(cells.len() as u64) as usize];
                let point = rng.below(u64::from(cell.len.min(4096)));
                (cell, point)
            })
            .collect();
        let mut distances: Vec<f32> = samples
            .par_iter()
            .filter_map(|&(cell, point)| {
                let range = cell.start as usize..(cell.start + cell.len.min(4096)) as usize;
                let pts = &self.points[range];
                let a = pts[point as usize].steps;
                // Squared distances in steps (exact integers).
                let best = pts
                    .iter()
                    .map(|b| {
                        (0..3)
                            .map(|k| (i64::from(a[k]) - i64::from(b.steps[k])).pow(2))
                            .sum::<i64>()
                    })
                    .filter(|&d| d > 0)
                    .min()?;
                Some(((best as f64).sqrt() * self.step_m) as f32)
            })
            .collect();
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

    /// A copy with one point in `keep_one_in` of each cell (its first `⌈len / k⌉`, a
    /// uniform random sample of it), laid out again in cells of `cell_size_m`, its
    /// spacing `√k` times this one's: what a low-resolution camera needs of the cloud
    /// (its renderings draw as many points a pixel, from fewer and larger cells, the
    /// level of detail's per-cell work being most of a small image's time). Positions
    /// are rounded to the new cells' steps (kept within [`MAX_OFFSET_M`] of the origin);
    /// colours follow their points. A cell of fewer than `k` points keeps one, drawn with
    /// the copy's wider spacing (larger splats).
    ///
    /// Errors: `keep_one_in` 0, or a cell size below [`MIN_CELL_SIZE_M`] or not finite.
    pub fn thinned(&self, keep_one_in: u32, cell_size_m: f32) -> Result<Self, SplatError> {
        if keep_one_in == 0 {
            return Err(SplatError::Parameter {
                name: "keep_one_in",
                message: "must be >= 1, got 0".into(),
            });
        }
        let kept = |cell: &Cell| {
            let start = cell.start as usize;
            start..start + cell.len.div_ceil(keep_one_in) as usize
        };
        let count: usize = self.cells.iter().map(|c| kept(c).len()).sum();
        let (mut positions, mut intensities) =
            (Vec::with_capacity(count), Vec::with_capacity(count));
        let mut colors = self.colors.as_ref().map(|_| Vec::with_capacity(count));
        for cell in &self.cells {
            for i in kept(cell) {
                let (p, intensity) = self.decode(cell, &self.points[i]);
                // A point placed to the step may lie half a step past the limit.
                positions.push(
                    self.origin + p.clamp(DVec3::splat(-MAX_OFFSET_M), DVec3::splat(MAX_OFFSET_M)),
                );
                intensities.push(intensity);
                if let (Some(out), Some(all)) = (colors.as_mut(), self.colors.as_ref()) {
                    out.push(all[i]);
                }
            }
        }
        Self::build(
            self.origin,
            &positions,
            &intensities,
            colors,
            Some(self.spacing_m * (keep_one_in as f32).sqrt()),
            cell_size_m,
        )
    }
}

/// An intensity in `[0, 1]` (clamped) in 16-bit fixed point, rounded as the renderer
/// rounds it (`⌊65535 i + 0.5⌋` in `f32`).
fn fixed_intensity(intensity: f32) -> u16 {
    (intensity.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

/// The points' order in a cloud: by cell (cells in the order of their integer
/// coordinates x, then y, then z) and, within a cell, by a random key drawn from the
/// point's index (ties, which a 64-bit key all but never has, by the index).
struct Layout {
    /// Input index of each point, in the cloud's order.
    order: Vec<u32>,
    /// Integer coordinates of each cell, in order.
    cell_keys: Vec<[i64; 3]>,
    /// First point of each cell in `order`.
    starts: Vec<usize>,
}

/// The shuffle's random keys: the generator's sequence, point by point.
const SHUFFLE_SEED: u64 = 0x5EED_CE11;

/// A grid of at most this many cells per point (or 2²⁰ cells) is laid out by counting;
/// a sparser one by sorting (the same order).
const DENSE_CELLS_PER_POINT: usize = 4;

impl Layout {
    fn new(positions: &[DVec3], key: &(impl Fn(&DVec3) -> [i64; 3] + Sync)) -> Self {
        let n = positions.len();
        let (lo, hi) = positions
            .par_iter()
            .map(|p| {
                let k = key(p);
                (k, k)
            })
            .reduce(
                || ([i64::MAX; 3], [i64::MIN; 3]),
                |(lo, hi), (l, h)| {
                    (
                        std::array::from_fn(|a| lo[a].min(l[a])),
                        std::array::from_fn(|a| hi[a].max(h[a])),
                    )
                },
            );
        match dense_grid(lo, hi, n) {
            Some((dims, cells)) => Self::counted(positions, key, lo, dims, cells),
            None => Self::sorted(positions, key),
        }
    }

    /// By sorting every point's (cell, random key, index).
    fn sorted(positions: &[DVec3], key: &(impl Fn(&DVec3) -> [i64; 3] + Sync)) -> Self {
        let mut keyed: Vec<([i64; 3], u64, u32)> = positions
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                (
                    key(p),
                    SplitMix64::nth_value(SHUFFLE_SEED, i as u64),
                    i as u32,
                )
            })
            .collect();
        // Every key holds the point's index, so any sort gives the same order: sorted
        // on rayon's threads.
        keyed.par_sort_unstable();
        let starts: Vec<usize> = (0..keyed.len())
            .into_par_iter()
            .filter(|&i| i == 0 || keyed[i].0 != keyed[i - 1].0)
            .collect();
        Self {
            cell_keys: starts.iter().map(|&s| keyed[s].0).collect(),
            order: keyed.into_iter().map(|(.., i)| i).collect(),
            starts,
        }
    }

    /// By counting the points of each cell of the bounding grid (`cells` of them,
    /// `dims` along x, y, z from `lo`), placing them, then sorting each cell by its
    /// random keys.
    fn counted(
        positions: &[DVec3],
        key: &(impl Fn(&DVec3) -> [i64; 3] + Sync),
        lo: [i64; 3],
        dims: [usize; 3],
        cells: usize,
    ) -> Self {
        use std::sync::atomic::{AtomicU32, Ordering};
        let n = positions.len();
        // The grid cell of each point: x, then y, then z, as the cells are ordered.
        let linear: Vec<u32> = positions
            .par_iter()
            .map(|p| {
                let k = key(p);
                let [x, y, z] = std::array::from_fn(|a| (k[a] - lo[a]) as usize);
                ((x * dims[1] + y) * dims[2] + z) as u32
            })
            .collect();
        let counts: Vec<AtomicU32> = (0..cells).map(|_| AtomicU32::new(0)).collect();
        linear.par_iter().for_each(|&c| {
            counts[c as usize].fetch_add(1, Ordering::Relaxed);
        });
        // The occupied cells, their keys and first points; `next` becomes each grid
        // cell's next free slot.
        let mut next: Vec<u32> = counts.into_iter().map(AtomicU32::into_inner).collect();
        let (mut starts, mut cell_keys) = (Vec::new(), Vec::new());
        let mut start = 0u32;
        for (c, slot) in next.iter_mut().enumerate() {
            let count = *slot;
            if count > 0 {
                starts.push(start as usize);
                let (x, y, z) = (c / (dims[1] * dims[2]), c / dims[2] % dims[1], c % dims[2]);
                cell_keys.push([lo[0] + x as i64, lo[1] + y as i64, lo[2] + z as i64]);
            }
            *slot = start;
            start += count;
        }
        let mut keyed = vec![(0u64, 0u32); n];
        for (i, &c) in linear.iter().enumerate() {
            let slot = &mut next[c as usize];
            keyed[*slot as usize] = (SplitMix64::nth_value(SHUFFLE_SEED, i as u64), i as u32);
            *slot += 1;
        }
        drop(linear);
        split_by_cell(&mut keyed, &starts)
            .into_par_iter()
            .for_each_init(
                || (Vec::new(), Vec::new()),
                |(scratch, counts), cell| sort_random_keys(cell, scratch, counts),
            );
        Self {
            order: keyed.into_iter().map(|(_, i)| i).collect(),
            cell_keys,
            starts,
        }
    }
}

/// The dimensions and number of cells of the grid from cell `lo` to cell `hi` (the
/// points' smallest and largest cell coordinates), if `n` points may be laid out by
/// counting its cells (at most [`DENSE_CELLS_PER_POINT`] cells per point, or 2²⁰, and
/// at most `u32::MAX`).
fn dense_grid(lo: [i64; 3], hi: [i64; 3], n: usize) -> Option<([usize; 3], usize)> {
    let dims: [usize; 3] = std::array::from_fn(|a| {
        usize::try_from(hi[a].saturating_sub(lo[a]))
            .unwrap_or(usize::MAX)
            .saturating_add(1)
    });
    let cells = dims[0]
        .checked_mul(dims[1])
        .and_then(|c| c.checked_mul(dims[2]))
        .filter(|&c| c <= (DENSE_CELLS_PER_POINT * n).max(1 << 20) && c <= u32::MAX as usize)?;
    Some((dims, cells))
}

/// `items` cut into the runs that begin at `starts` (increasing, the first 0).
fn split_by_cell<'a, T>(mut items: &'a mut [T], starts: &[usize]) -> Vec<&'a mut [T]> {
    let mut runs = Vec::with_capacity(starts.len());
    for (c, &start) in starts.iter().enumerate() {
        let len = starts.get(c + 1).map_or(items.len(), |&next| next - start);
        let (run, rest) = items.split_at_mut(len);
        runs.push(run);
        items = rest;
    }
    runs
}

/// The index of the first item of `items` for which `test` holds, runs of items on
/// rayon's threads (`position_first` item by item consults the other threads at each).
fn first_index<T: Sync>(items: &[T], test: impl Fn(&T) -> bool + Sync) -> Option<usize> {
    const RUN: usize = 1 << 16;
    items
        .par_chunks(RUN)
        .enumerate()
        .find_map_first(|(k, run)| run.iter().position(&test).map(|i| k * RUN + i))
}

/// `⌊x⌋` of a finite `x` of magnitude below 2⁶³ (the positions were checked), without
/// a call to the C library where the target has no rounding instruction.
#[inline(always)]
fn floor_to_i64(x: f64) -> i64 {
    let t = x as i64; // toward zero
    if t as f64 > x { t - 1 } else { t }
}

/// The step nearest `x` (halves away from zero, as `f64::round`), clamped to
/// `[0, 65 535]`.
#[inline(always)]
fn nearest_step(x: f64) -> u16 {
    // Rounding commutes with a clamp to integers.
    let x = x.clamp(0.0, STEPS);
    let t = x as u32; // x ≥ 0: the floor
    (if x - f64::from(t) >= 0.5 { t + 1 } else { t }) as u16
}

/// Sort a cell's (random key, index) pairs: by the keys' leading bits into about one
/// bucket per pair, then each bucket on its own. The order of `sort_unstable`; linear
/// time expected (the keys are uniform), `m log m` at worst (every key in one bucket).
fn sort_random_keys(cell: &mut [(u64, u32)], scratch: &mut Vec<(u64, u32)>, counts: &mut Vec<u32>) {
    let m = cell.len();
    if m <= 32 {
        cell.sort_unstable();
        return;
    }
    let bits = usize::BITS - (m - 1).leading_zeros();
    let shift = 64 - bits;
    counts.clear();
    counts.resize((1 << bits) + 1, 0);
    for &(key, _) in cell.iter() {
        counts[(key >> shift) as usize + 1] += 1;
    }
    for b in 1..counts.len() {
        counts[b] += counts[b - 1];
    }
    scratch.clear();
    scratch.resize(m, (0, 0));
    for &pair in cell.iter() {
        let slot = &mut counts[(pair.0 >> shift) as usize];
        scratch[*slot as usize] = pair;
        *slot += 1;
    }
    cell.copy_from_slice(scratch);
    // Each bucket now ends where the next begins: pairs of different buckets are in
    // order, each bucket is sorted alone.
    let mut start = 0;
    for &end in &counts[..1 << bits] {
        let end = end as usize;
        if end - start > 1 {
            cell[start..end].sort_unstable();
        }
        start = end;
    }
}

#[cfg(test)]
mod tests {
    //! The layout's fast paths against the plain ones.

    use proptest::prelude::*;

    use super::*;

    proptest! {
        /// Counting the points of each cell gives the order of sorting them, on grids
        /// of one cell to many (clustered: hundreds of points in a cell), with points on
        /// cell boundaries and repeated points.
        #[test]
        fn counting_lays_out_as_sorting(
            points in prop::collection::vec(
                (prop::array::uniform3(0.0f64..1.0), prop::array::uniform3(0u8..4)),
                1..3000,
            ),
            spread_m in prop::sample::select(vec![2.0f64, 10.0, 80.0]),
            cell_m in prop::sample::select(vec![1.0f64, 2.0, 7.5]),
        ) {
            // Whole quarters of a metre: many points exactly on a boundary, and repeats.
            let positions: Vec<DVec3> = points
                .iter()
                .map(|(u, q)| {
                    DVec3::from_array(std::array::from_fn(|a| {
                        (u[a] * spread_m).floor() - spread_m * 0.5 + f64::from(q[a]) * 0.25
                    }))
                })
                .collect();
            let origin = DVec3::new(-3.0, 0.5, 1.0);
            let key = |p: &DVec3| ((*p - origin) / cell_m).to_array().map(floor_to_i64);
            let keys: Vec<[i64; 3]> = positions.iter().map(key).collect();
            let lo = std::array::from_fn(|a| keys.iter().map(|k| k[a]).min().unwrap());
            let hi = std::array::from_fn(|a| keys.iter().map(|k| k[a]).max().unwrap());
            let (dims, cells) = dense_grid(lo, hi, positions.len()).expect("a dense grid");
            let counted = Layout::counted(&positions, &key, lo, dims, cells);
            let sorted = Layout::sorted(&positions, &key);
            prop_assert_eq!(&counted.order, &sorted.order);
            prop_assert_eq!(&counted.cell_keys, &sorted.cell_keys);
            prop_assert_eq!(&counted.starts, &sorted.starts);
            prop_assert_eq!(&Layout::new(&positions, &key).order, &sorted.order);
            for p in &positions {
                let floored = ((*p - origin) / cell_m).floor();
                prop_assert_eq!(key(p), [floored.x as i64, floored.y as i64, floored.z as i64]);
            }
        }

        /// The rounding helpers are `floor` and `round` (then clamped).
        #[test]
        fn rounding_helpers_match_the_library(x in -1e9f64..1e9, y in -10.0f64..70_000.0) {
            prop_assert_eq!(floor_to_i64(x), x.floor() as i64);
            prop_assert_eq!(nearest_step(y), y.round().clamp(0.0, STEPS) as u16);
            let half = y.floor() + 0.5;
            prop_assert_eq!(nearest_step(half), half.round().clamp(0.0, STEPS) as u16);
        }
    }

    /// A cell's pairs sorted by buckets of their keys' leading bits are sorted as by
    /// `sort_unstable`: uniform keys, keys sharing their leading bits (one bucket) and
    /// repeated keys, from just past the plain sort's size to 10⁵ pairs.
    #[test]
    fn random_keys_are_sorted_as_by_the_library() {
        let mut rng = SplitMix64::new(3);
        let (mut scratch, mut counts) = (Vec::new(), Vec::new());
        for m in [33usize, 34, 100, 1000, 4097, 100_000] {
            for kind in 0..3 {
                let mut pairs: Vec<(u64, u32)> = (0..m as u32)
                    .map(|i| {
                        let key = match kind {
                            0 => rng.next_u64(),
                            1 => rng.next_u64() >> 40, // every key in the first bucket
                            _ => rng.below(7) << 61,   // a few repeated keys
                        };
                        (key, i)
                    })
                    .collect();
                let mut expected = pairs.clone();
                expected.sort_unstable();
                sort_random_keys(&mut pairs, &mut scratch, &mut counts);
                assert_eq!(pairs, expected, "{m} pairs, kind {kind}");
            }
        }
    }

    /// The first matching item is found whichever runs of items the threads take.
    #[test]
    fn first_index_is_the_first() {
        let mut items = vec![0u8; 300_000];
        assert_eq!(first_index(&items, |&v| v != 0), None);
        for &k in &[250_000usize, 70_000, 65_536, 65_535, 3] {
            items[k] = 1;
            assert_eq!(first_index(&items, |&v| v != 0), Some(k));
        }
    }

    /// A sparse grid (two far clusters) is laid out by sorting (it is no dense grid),
    /// every point once.
    #[test]
    fn a_sparse_grid_is_laid_out_by_sorting() {
        assert!(dense_grid([0; 3], [9_000_000; 3], 1000).is_none());
        assert!(dense_grid([0; 3], [99; 3], 1000).is_some());
        let mut positions: Vec<DVec3> = (0..500)
            .map(|i| DVec3::splat(f64::from(i) * 0.01))
            .collect();
        positions.extend((0..500).map(|i| DVec3::splat(9.0e5 + f64::from(i) * 0.01)));
        let key = |p: &DVec3| (*p * 10.0).to_array().map(floor_to_i64);
        let layout = Layout::new(&positions, &key);
        let mut seen = layout.order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..1000).collect::<Vec<u32>>());
        assert_eq!(layout.order, Layout::sorted(&positions, &key).order);
    }
}
