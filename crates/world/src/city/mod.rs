//! A synthetic city, deterministic from a seed: the embedded default scene.
//!
//! The paper's Lidar scans are not public, so the project generates its own four
//! streets: a **crossroads** of two streets (`X` and `Y` axes of the world, `Z` up, the
//! ground at `z = 0`, origin at the centre of the crossing), each arm
//! [`CityParams::arm_length_m`] long and [`CityParams::street_width_m`] wide from facade
//! to facade: a road between two raised sidewalks with granite kerbs.
//!
//! * **Facades** line both sides of every arm and close its far end: buildings 5–16 m
//!   wide and 8–20 m high, in brick (running bond, per-brick tint), render (stains,
//!   grain, dirt streaks) or stone blocks, with recessed windows (frames, mullions,
//!   glass reflecting the sky), doors, shopfronts with coloured signs, balconies with
//!   railings, cornices, small setbacks and the side walls that height differences
//!   expose. Widths, heights, floor heights, window sizes and spacings are drawn per
//!   building, so that no window grid repeats along a street (a strictly periodic
//!   facade creates along-street local minima for photometric methods).
//! * **Ground**: asphalt with stains at several scales and patches, worn markings
//!   (edge lines, an irregular dashed centre line, zebra crossings), manhole covers;
//!   sidewalks of paving slabs of varied tint.
//! * **Clutter** at irregular intervals, so that depth varies: trees (trunk and a
//!   noisy crown), street lamps, parked cars.
//!
//! Texture is procedural (value noise at several scales); photographic grey-level
//! textures (`brick.png`, `gravel.png`, `grass.png`, e.g. from `../shared/data/textures`)
//! modulate bricks, asphalt and foliage when [`CityParams::texture_dir`] names a folder
//! that holds them.
//!
//! Surfaces are sampled on a jittered grid of [`CityParams::spacing_m`].

mod texture;

use std::path::PathBuf;
use std::time::Instant;

use glam::{DMat3, DVec3};
use ucm::Isometry3;

use splat::PointCloud;
use splat::rng::{SplitMix64, hash3};

use crate::WorldError;
pub use texture::{ImageTexture, Textures, fbm, value_noise};

/// Smallest point spacing of the city, metres (37 million points with the default
/// streets).
pub const MIN_SPACING_M: f64 = 0.02;

/// Most points a generated city may hold (about 5 GB while it is built).
pub const MAX_POINTS: usize = 60_000_000;

/// About how many points the city of `p` holds: the default city (arms of 60 m,
/// streets 12 m wide) holds 5.9 million at 0.05 m; the count grows with the arms, the
/// street width and the inverse square of the spacing.
fn estimated_points(p: &CityParams) -> f64 {
    6.0e6
        * (p.arm_length_m / 60.0)
        * (p.street_width_m / 12.0).max(1.0)
        * (0.05 / p.spacing_m).powi(2)
}

/// Parameters of the synthetic city.
#[derive(Clone, Debug, PartialEq)]
pub struct CityParams {
    /// Seed: the same seed gives the same city, point for point.
    pub seed: u64,
    /// Distance between neighbouring points on a surface, metres. Default 0.05.
    pub spacing_m: f64,
    /// Facade-to-facade width of every street, metres. Default 12.
    pub street_width_m: f64,
    /// Width of each sidewalk, metres. Default 2.5.
    pub sidewalk_width_m: f64,
    /// Length of each of the four arms from the centre of the crossing, metres.
    /// Default 60.
    pub arm_length_m: f64,
    /// Seed of the point sampling alone (jittered positions, per-point grain): another
    /// value samples the same surfaces anew (the layout, materials and textures come
    /// from `seed`), e.g. for images that play the part of acquired ones. `None`: the
    /// sampling follows `seed`.
    pub sampling_seed: Option<u64>,
    /// Folder of optional photographic textures (`brick.png`, `gravel.png`,
    /// `grass.png`). Default none: procedural texture only.
    pub texture_dir: Option<PathBuf>,
    /// Street clutter: trees, lamps and parked cars along the sidewalks. Default true;
    /// false for the ablation of what sets the convergence domain.
    pub clutter: bool,
    /// Facade detail: windows, doors, shopfronts, signs, shutters, balconies and the
    /// fine texture of the walls (bricks, stones, stains, grain). Default true; false
    /// leaves each building a plain wall of its material's colour with its cornice
    /// (the same layout), for the ablation of what sets the convergence domain.
    pub facade_detail: bool,
}

impl Default for CityParams {
    fn default() -> Self {
        Self {
            seed: 1,
            spacing_m: 0.05,
            street_width_m: 12.0,
            sidewalk_width_m: 2.5,
            arm_length_m: 60.0,
            sampling_seed: None,
            texture_dir: None,
            clutter: true,
            facade_detail: true,
        }
    }
}

/// Height of the sidewalks above the road, metres.
pub const KERB_HEIGHT_M: f64 = 0.12;

/// A generated city.
#[derive(Clone, Debug)]
pub struct City {
    /// The points.
    pub cloud: PointCloud,
    /// The parameters it was generated from.
    pub params: CityParams,
    /// Wall-clock generation time, seconds.
    pub generation_time_s: f64,
}

/// `world_from_camera` of a camera whose optical axis points to the ground (camera
/// `Z` = world `−Z`), at `position`, with its `X` axis along the horizontal direction
/// `heading_rad` (0: world `+X`).
pub fn camera_looking_down(position: DVec3, heading_rad: f64) -> Isometry3 {
    let (s, c) = heading_rad.sin_cos();
    let x = DVec3::new(c, s, 0.0);
    let z = DVec3::NEG_Z;
    let y = z.cross(x);
    Isometry3::from_mat3_translation(DMat3::from_cols(x, y, z), position)
}

impl City {
    /// Generate the city. Errors on invalid parameters or unreadable textures.
    pub fn generate(params: &CityParams) -> Result<Self, WorldError> {
        let started = Instant::now();
        let p = params;
        let check = |name: &'static str, ok: bool, value: f64, range: String| {
            if ok {
                Ok(())
            } else {
                Err(WorldError::Parameter {
                    name,
                    message: format!("{value} is outside {range}"),
                })
            }
        };
        check(
            "spacing_m",
            p.spacing_m.is_finite() && p.spacing_m >= MIN_SPACING_M && p.spacing_m <= 1.0,
            p.spacing_m,
            format!("[{MIN_SPACING_M}, 1] m"),
        )?;
        check(
            "street_width_m",
            p.street_width_m.is_finite() && p.street_width_m >= 4.0 && p.street_width_m <= 60.0,
            p.street_width_m,
            "[4, 60] m".into(),
        )?;
        check(
            "sidewalk_width_m",
            p.sidewalk_width_m.is_finite()
                && p.sidewalk_width_m >= 0.5
                && p.sidewalk_width_m < p.street_width_m * 0.4,
            p.sidewalk_width_m,
            format!("[0.5, 0.4 × street_width_m = {}) m", p.street_width_m * 0.4),
        )?;
        check(
            "arm_length_m",
            p.arm_length_m.is_finite()
                && p.arm_length_m >= p.street_width_m
                && p.arm_length_m <= 500.0,
            p.arm_length_m,
            format!("[street_width_m = {}, 500] m", p.street_width_m),
        )?;
        let estimate = estimated_points(p);
        if estimate > MAX_POINTS as f64 {
            return Err(WorldError::Parameter {
                name: "spacing_m",
                message: format!(
                    "a city of {} m arms sampled every {} m would hold about {:.0} million \
                     points, more than the {} million allowed (memory): use a larger spacing \
                     or shorter arms",
                    p.arm_length_m,
                    p.spacing_m,
                    estimate / 1e6,
                    MAX_POINTS / 1_000_000
                ),
            });
        }
        let textures = match &p.texture_dir {
            Some(dir) => Textures::from_dir(dir)?,
            None => Textures::default(),
        };
        let mut g = Generator {
            params: p.clone(),
            textures,
            rng: SplitMix64::new(p.seed),
            positions: Vec::new(),
            colors: Vec::new(),
        };
        g.ground();
        g.facades();
        if p.clutter {
            g.clutter();
        }
        let intensities: Vec<f32> = g.colors.iter().map(|&c| splat::luminance(c)).collect();
        let cloud = PointCloud::from_points(
            DVec3::ZERO,
            &g.positions,
            &intensities,
            Some(std::mem::take(&mut g.colors)),
            Some(p.spacing_m as f32),
        )?;
        Ok(Self {
            cloud,
            params: params.clone(),
            generation_time_s: started.elapsed().as_secs_f64(),
        })
    }
}

type Rgb = [f64; 3];

fn mix(a: Rgb, b: Rgb, t: f64) -> Rgb {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

fn scale(c: Rgb, k: f64) -> Rgb {
    [c[0] * k, c[1] * k, c[2] * k]
}

fn to_u8(c: Rgb) -> [u8; 3] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

#[derive(Clone, Copy, Debug)]
enum Material {
    Brick { base: Rgb, mortar: Rgb },
    Render { base: Rgb },
    Stone { base: Rgb },
}

/// An opening in a wall, in the wall's `(s, t)` metres.
#[derive(Clone, Copy, Debug)]
struct Opening {
    s0: f64,
    s1: f64,
    t0: f64,
    t1: f64,
    kind: OpeningKind,
}

#[derive(Clone, Copy, Debug)]
enum OpeningKind {
    Window { frame: Rgb, mullion: bool },
    Shop { frame: Rgb },
    Door { color: Rgb },
}

impl Opening {
    fn contains(&self, s: f64, t: f64) -> bool {
        s >= self.s0 && s < self.s1 && t >= self.t0 && t < self.t1
    }
}

struct Generator {
    params: CityParams,
    textures: Textures,
    rng: SplitMix64,
    positions: Vec<DVec3>,
    colors: Vec<[u8; 3]>,
}

impl Generator {
    /// Sample the parallelogram `origin + s û + t v̂`, `s ∈ [0, |u|)`, `t ∈ [0, |v|)`, on a
    /// jittered grid; `shade(s, t)` gives the colour, or `None` for a hole.
    fn patch(
        &mut self,
        origin: DVec3,
        u: DVec3,
        v: DVec3,
        shade: &mut dyn FnMut(f64, f64, &mut SplitMix64) -> Option<Rgb>,
    ) {
        let step = self.params.spacing_m;
        let (lu, lv) = (u.length(), v.length());
        if lu <= 0.0 || lv <= 0.0 {
            return;
        }
        let (du, dv) = (u / lu, v / lv);
        let nu = (lu / step).round().max(1.0) as usize;
        let nv = (lv / step).round().max(1.0) as usize;
        let (su, sv) = (lu / nu as f64, lv / nv as f64);
        for j in 0..nv {
            for i in 0..nu {
                let s = (i as f64 + 0.5 + 0.8 * (self.rng.unit() - 0.5)) * su;
                let t = (j as f64 + 0.5 + 0.8 * (self.rng.unit() - 0.5)) * sv;
                if let Some(c) = shade(s, t, &mut self.rng) {
                    self.positions.push(origin + du * s + dv * t);
                    self.colors.push(to_u8(c));
                }
            }
        }
    }

    fn seed(&self, label: u64) -> u64 {
        splat::rng::mix64(self.params.seed ^ label.wrapping_mul(0x2545_F491_4F6C_DD1D))
    }

    // ----------------------------------------------------------------- ground

    fn ground(&mut self) {
        let p = self.params.clone();
        let half = p.street_width_m / 2.0;
        let road = half - p.sidewalk_width_m;
        let l = p.arm_length_m;
        let seed = self.seed(1);
        // Dashes of the centre lines: irregular lengths and gaps.
        let mut dashes = Vec::new();
        for axis in 0..2 {
            let mut x = -l;
            while x < l {
                let len = self.rng.uniform(2.2, 3.6);
                dashes.push((axis, x, x + len));
                x += len + self.rng.uniform(3.5, 7.0);
            }
        }
        let manholes: Vec<(f64, f64)> = (0..10)
            .map(|k| {
                let along = self.rng.uniform(-l + 3.0, l - 3.0);
                let across = self.rng.uniform(-road + 0.8, road - 0.8);
                if k % 2 == 0 {
                    (along, across)
                } else {
                    (across, along)
                }
            })
            .collect();
        let patches: Vec<(f64, f64, f64, f64)> = (0..14)
            .map(|k| {
                let along = self.rng.uniform(-l, l);
                let across = self.rng.uniform(-road, road);
                let (a, b) = (self.rng.uniform(0.8, 3.5), self.rng.uniform(0.6, 2.0));
                if k % 2 == 0 {
                    (along, across, a, b)
                } else {
                    (across, along, b, a)
                }
            })
            .collect();
        let slab = [self.rng.uniform(0.3, 0.5), self.rng.uniform(0.3, 0.6)];
        // Every layout draw of the shared stream is above: from here on it only samples.
        if let Some(sampling) = p.sampling_seed {
            self.rng = SplitMix64::new(splat::rng::mix64(sampling ^ 0x5A4D_504C_494E_4721));
        }
        let gravel = self.textures.gravel.clone();

        let shade = |x: f64, y: f64, rng: &mut SplitMix64| -> (Rgb, f64) {
            let on_road = x.abs() <= road || y.abs() <= road;
            if on_road {
                let mut g = 0.30
                    + 0.10 * fbm(seed, x, y, 0.15, 3)
                    + 0.06 * fbm(seed ^ 1, x, y, 1.3, 3)
                    + 0.05 * fbm(seed ^ 2, x, y, 9.0, 2)
                    + 0.025 * (rng.unit() - 0.5);
                if let Some(t) = &gravel {
                    g += 0.25 * t.detail(x, y);
                }
                let mut c = [g, g * 1.01, g * 1.03];
                for &(px, py, a, b) in &patches {
                    if (x - px).abs() < a / 2.0 && (y - py).abs() < b / 2.0 {
                        c = scale(c, 0.72);
                    }
                }
                for &(mx, my) in &manholes {
                    let r = (x - mx).hypot(y - my);
                    if r < 0.35 {
                        let ring = if r > 0.3 {
                            0.6
                        } else {
                            0.75 + 0.1 * ((x - mx) * 25.0).sin().signum()
                        };
                        c = scale(
                            [0.22, 0.22, 0.23],
                            ring + 0.2 * fbm(seed ^ 3, x, y, 20.0, 1),
                        );
                    }
                }
                // Markings, worn.
                let wear = 0.55 + 0.9 * fbm(seed ^ 4, x, y, 2.5, 3);
                let paint = |c: Rgb| mix(c, [0.92, 0.92, 0.88], wear.clamp(0.0, 1.0));
                let x_street = y.abs() <= road && x.abs() > road;
                let y_street = x.abs() <= road && y.abs() > road;
                let (along, across, axis) = if x_street { (x, y, 0) } else { (y, x, 1) };
                if x_street || y_street {
                    if (across.abs() - (road - 0.3)).abs() < 0.075 {
                        c = paint(c);
                    }
                    if across.abs() < 0.075
                        && dashes
                            .iter()
                            .any(|&(a, s0, s1)| a == axis && along >= s0 && along < s1)
                    {
                        c = paint(c);
                    }
                    let d = along.abs() - (half + 1.0);
                    if (0.0..3.0).contains(&d)
                        && across.abs() < road - 0.5
                        && (across + road).rem_euclid(1.0) < 0.5
                    {
                        c = paint(c);
                    }
                }
                (c, 0.0)
            } else {
                // Paving slabs: joints and per-slab tint.
                let (sx, sy) = (slab[0], slab[1]);
                let (ix, iy) = ((x / sx).floor(), (y / sy).floor());
                let tint = 0.08 * (hash3(seed ^ 5, ix as i64, iy as i64, 0) - 0.5);
                let joint = (x / sx - ix).min(1.0 - (x / sx - ix)) * sx < 0.008
                    || (y / sy - iy).min(1.0 - (y / sy - iy)) * sy < 0.008;
                let g = 0.58
                    + tint
                    + 0.06 * fbm(seed ^ 6, x, y, 0.4, 3)
                    + 0.04 * fbm(seed ^ 7, x, y, 12.0, 2)
                    + 0.02 * (rng.unit() - 0.5);
                let c = if joint {
                    scale([g, g, g * 0.97], 0.6)
                } else {
                    [g * 1.02, g, g * 0.95]
                };
                (c, KERB_HEIGHT_M)
            }
        };

        // X street over its whole length, Y street outside the crossing.
        let step = p.spacing_m;
        let emit = |g: &mut Generator, x0: f64, x1: f64, y0: f64, y1: f64| {
            let nx = ((x1 - x0) / step).round().max(1.0) as usize;
            let ny = ((y1 - y0) / step).round().max(1.0) as usize;
            let (sx, sy) = ((x1 - x0) / nx as f64, (y1 - y0) / ny as f64);
            for j in 0..ny {
                for i in 0..nx {
                    let x = x0 + (i as f64 + 0.5 + 0.8 * (g.rng.unit() - 0.5)) * sx;
                    let y = y0 + (j as f64 + 0.5 + 0.8 * (g.rng.unit() - 0.5)) * sy;
                    let (c, z) = shade(x, y, &mut g.rng);
                    g.positions.push(DVec3::new(x, y, z));
                    g.colors.push(to_u8(c));
                }
            }
        };
        emit(self, -l, l, -half, half);
        emit(self, -half, half, half, l);
        emit(self, -half, half, -l, -half);

        // Kerbs: vertical granite faces along the sidewalks' edges.
        let kseed = self.seed(2);
        let mut kerb = |s: f64, _t: f64, rng: &mut SplitMix64| {
            let g = 0.5 + 0.08 * fbm(kseed, s, 0.0, 1.5, 2) + 0.05 * (rng.unit() - 0.5);
            Some([g, g, g * 1.02])
        };
        let h = DVec3::new(0.0, 0.0, KERB_HEIGHT_M);
        for sign in [-1.0, 1.0] {
            for side in [-1.0, 1.0] {
                // Along X, for |x| in [road, l], at y = side·road.
                let a = DVec3::new(sign * road, side * road, 0.0);
                let b = DVec3::new(sign * l, side * road, 0.0);
                self.patch(a, b - a, h, &mut kerb);
                // Along Y.
                let a = DVec3::new(side * road, sign * road, 0.0);
                let b = DVec3::new(side * road, sign * l, 0.0);
                self.patch(a, b - a, h, &mut kerb);
            }
        }
    }

    // ---------------------------------------------------------------- facades

    fn facades(&mut self) {
        let p = self.params.clone();
        let half = p.street_width_m / 2.0;
        let l = p.arm_length_m;
        let mut line = 0u64;
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                // Facade along X in quadrant (sx, sy), facing the street (normal −sy·Y).
                let start = DVec3::new(sx * half, sy * half, 0.0);
                let dir = DVec3::new(sx, 0.0, 0.0);
                let normal = DVec3::new(0.0, -sy, 0.0);
                self.facade_line(line, start, dir, normal, l - half);
                line += 1;
                // Facade along Y, facing the street (normal −sx·X).
                let dir = DVec3::new(0.0, sy, 0.0);
                let normal = DVec3::new(-sx, 0.0, 0.0);
                self.facade_line(line, start, dir, normal, l - half);
                line += 1;
            }
        }
        // The far ends of the four arms.
        for (start, dir, normal) in [
            (DVec3::new(l, -half, 0.0), DVec3::Y, DVec3::NEG_X),
            (DVec3::new(-l, half, 0.0), DVec3::NEG_Y, DVec3::X),
            (DVec3::new(half, l, 0.0), DVec3::NEG_X, DVec3::NEG_Y),
            (DVec3::new(-half, -l, 0.0), DVec3::X, DVec3::Y),
        ] {
            self.facade_line(line, start, dir, normal, 2.0 * half);
            line += 1;
        }
    }

    /// Buildings along a line from `start`, direction `dir`, facing `normal`.
    fn facade_line(&mut self, line: u64, start: DVec3, dir: DVec3, normal: DVec3, length: f64) {
        let mut rng = SplitMix64::new(self.seed(100 + line));
        let mut s = 0.0;
        let mut previous: Option<(f64, f64)> = None; // (height, setback)
        let mut index = 0u64;
        while s < length - 0.01 {
            let mut width = rng.uniform(5.0, 16.0);
            if length - s - width < 4.0 {
                width = length - s;
            }
            let height = rng.uniform(8.0, 20.0);
            let setback = if rng.chance(0.3) {
                rng.uniform(0.1, 0.6)
            } else {
                0.0
            };
            let origin = start + dir * s - normal * setback;
            self.building(line * 1000 + index, origin, dir, normal, width, height);
            // Side walls exposed by height or setback differences.
            if let Some((h0, b0)) = previous {
                let base = start + dir * s;
                if (h0 - height).abs() > 0.3 {
                    let (lo, hi) = (h0.min(height), h0.max(height));
                    let depth = 8.0;
                    let back = if h0 > height { b0 } else { setback };
                    let a = base - normal * back + DVec3::Z * lo;
                    let seed = self.seed(7000 + line * 1000 + index);
                    self.patch(a, -normal * depth, DVec3::Z * (hi - lo), &mut |u, v, r| {
                        let g = 0.55 + 0.1 * fbm(seed, u, v, 0.5, 3) + 0.03 * (r.unit() - 0.5);
                        Some([g, g * 0.97, g * 0.92])
                    });
                }
                if (b0 - setback).abs() > 0.05 {
                    let (front, back) = (b0.min(setback), b0.max(setback));
                    let a = base - normal * front;
                    let seed = self.seed(8000 + line * 1000 + index);
                    self.patch(
                        a,
                        -normal * (back - front),
                        DVec3::Z * h0.min(height),
                        &mut |u, v, r| {
                            let g = 0.5 + 0.1 * fbm(seed, u, v, 1.0, 2) + 0.03 * (r.unit() - 0.5);
                            Some([g, g, g])
                        },
                    );
                }
            }
            previous = Some((height, setback));
            s += width;
            index += 1;
        }
    }

    fn random_material(rng: &mut SplitMix64) -> Material {
        match rng.below(10) {
            0..=3 => {
                let bases = [
                    [0.55, 0.27, 0.18],
                    [0.62, 0.38, 0.25],
                    [0.72, 0.6, 0.42],
                    [0.45, 0.22, 0.17],
                ];
                let base = bases[rng.below(4) as usize];
                Material::Brick {
                    base: scale(base, rng.uniform(0.85, 1.15)),
                    mortar: scale([0.75, 0.73, 0.68], rng.uniform(0.85, 1.1)),
                }
            }
            4..=7 => {
                let bases = [
                    [0.88, 0.84, 0.74],
                    [0.8, 0.72, 0.6],
                    [0.75, 0.78, 0.8],
                    [0.86, 0.7, 0.55],
                    [0.7, 0.72, 0.62],
                    [0.93, 0.9, 0.86],
                ];
                Material::Render {
                    base: scale(bases[rng.below(6) as usize], rng.uniform(0.85, 1.08)),
                }
            }
            _ => Material::Stone {
                base: scale([0.78, 0.74, 0.64], rng.uniform(0.85, 1.1)),
            },
        }
    }

    /// One building: wall with openings, recessed glazing, doors, shopfronts, balconies,
    /// cornice.
    fn building(
        &mut self,
        id: u64,
        origin: DVec3,
        dir: DVec3,
        normal: DVec3,
        width: f64,
        height: f64,
    ) {
        let mut rng = SplitMix64::new(self.seed(10_000 + id));
        let seed = self.seed(20_000 + id);
        let material = Self::random_material(&mut rng);
        let ground_floor = rng.uniform(3.2, 4.4);
        let floor_h = rng.uniform(2.75, 3.6);
        let floors = (((height - ground_floor - 0.9) / floor_h).floor().max(0.0)) as usize;
        let window_w = rng.uniform(0.8, 1.5);
        let window_h = rng.uniform(1.2, 1.9).min(floor_h - 0.9);
        let sill = rng.uniform(0.7, 1.0).min(floor_h - window_h - 0.2);
        let bay = rng.uniform(2.2, 4.4).max(window_w + 0.8);
        let columns = (((width - 1.0) / bay).floor().max(1.0)) as usize;
        let margin = (width - columns as f64 * bay) / 2.0;
        let frame: Rgb = [
            [0.95, 0.95, 0.93],
            [0.2, 0.2, 0.22],
            [0.45, 0.3, 0.2],
            [0.35, 0.45, 0.35],
        ][rng.below(4) as usize];
        let mullion = rng.chance(0.6);
        let shop = rng.chance(0.55);
        let balconies = rng.chance(0.35);
        let shutters = !balconies && rng.chance(0.3);
        let shutter_color: Rgb = [
            [0.25, 0.4, 0.3],
            [0.6, 0.55, 0.45],
            [0.3, 0.35, 0.5],
            [0.55, 0.25, 0.2],
        ][rng.below(4) as usize];

        let mut openings = Vec::new();
        for f in 0..floors {
            let t0 = ground_floor + f as f64 * floor_h + sill;
            for c in 0..columns {
                if rng.chance(0.04) {
                    continue;
                }
                let centre = margin + (c as f64 + 0.5) * bay + rng.uniform(-0.08, 0.08);
                openings.push(Opening {
                    s0: centre - window_w / 2.0,
                    s1: centre + window_w / 2.0,
                    t0,
                    t1: t0 + window_h,
                    kind: OpeningKind::Window { frame, mullion },
                });
            }
        }
        // Ground floor: a door, and shop windows or ordinary windows.
        let door_w = rng.uniform(1.0, 1.8);
        let door_s = rng.uniform(0.5, (width - door_w - 0.5).max(0.6));
        let door_color: Rgb = scale(
            [
                [0.35, 0.22, 0.12],
                [0.15, 0.2, 0.3],
                [0.5, 0.1, 0.1],
                [0.2, 0.2, 0.2],
            ][rng.below(4) as usize],
            rng.uniform(0.8, 1.2),
        );
        openings.push(Opening {
            s0: door_s,
            s1: door_s + door_w,
            t0: 0.0,
            t1: rng.uniform(2.2, 2.7).min(ground_floor - 0.3),
            kind: OpeningKind::Door { color: door_color },
        });
        let mut sign = None;
        if shop {
            let s0 = if door_s > width / 2.0 {
                0.6
            } else {
                door_s + door_w + 0.5
            };
            let s1 = if door_s > width / 2.0 {
                door_s - 0.5
            } else {
                width - 0.6
            };
            if s1 - s0 > 1.5 {
                openings.push(Opening {
                    s0,
                    s1,
                    t0: 0.45,
                    t1: ground_floor - 0.8,
                    kind: OpeningKind::Shop { frame },
                });
                let hue: Rgb = [
                    [0.7, 0.1, 0.1],
                    [0.1, 0.3, 0.6],
                    [0.9, 0.75, 0.2],
                    [0.15, 0.45, 0.2],
                    [0.1, 0.1, 0.1],
                ][rng.below(5) as usize];
                sign = Some((
                    s0,
                    s1,
                    ground_floor - 0.7,
                    ground_floor - 0.15,
                    hue,
                    rng.next_u64(),
                ));
            }
        }
        if !shop {
            let t0 = 1.0;
            let mut s = margin;
            while s + window_w < width - 0.3 {
                if !(s + window_w > door_s - 0.2 && s < door_s + door_w + 0.2) {
                    openings.push(Opening {
                        s0: s,
                        s1: s + window_w,
                        t0,
                        t1: (t0 + window_h).min(ground_floor - 0.4),
                        kind: OpeningKind::Window { frame, mullion },
                    });
                }
                s += bay * rng.uniform(0.9, 1.1);
            }
        }

        // Without facade detail: the same layout draws, then a plain wall.
        let detail = self.params.facade_detail;
        let (balconies, shutters) = if detail {
            (balconies, shutters)
        } else {
            openings.clear();
            sign = None;
            (false, false)
        };
        let brick = self.textures.brick.clone();
        let wall_color = move |s: f64, t: f64, rng: &mut SplitMix64| -> Rgb {
            if !detail {
                return match material {
                    Material::Brick { base, .. }
                    | Material::Render { base }
                    | Material::Stone { base } => base,
                };
            }
            let grain = 0.03 * (rng.unit() - 0.5);
            match material {
                Material::Brick { base, mortar } => {
                    let (bw, bh) = (0.225, 0.075);
                    let row = (t / bh).floor();
                    let offset = if row as i64 % 2 == 0 { 0.0 } else { bw / 2.0 };
                    let col = ((s + offset) / bw).floor();
                    let (fs, ft) = ((s + offset) / bw - col, t / bh - row);
                    let in_mortar = fs * bw < 0.012 || ft * bh < 0.012;
                    let tint = 0.85 + 0.3 * hash3(seed, col as i64, row as i64, 1);
                    let mut c = if in_mortar { mortar } else { scale(base, tint) };
                    let mut k = 1.0 + 0.12 * fbm(seed, s, t, 0.3, 3) + grain;
                    if let Some(tex) = &brick {
                        k += 0.6 * tex.detail(s, t);
                    }
                    c = scale(c, k);
                    c
                }
                Material::Render { base } => {
                    let stain =
                        0.10 * fbm(seed, s, t, 0.25, 4) + 0.05 * fbm(seed ^ 9, s, t, 3.0, 3);
                    // Dirt streaks running down.
                    let streak = 0.06 * (fbm(seed ^ 11, s * 6.0, t * 0.3, 1.0, 2)).min(0.0);
                    scale(base, 1.0 + stain + streak + grain)
                }
                Material::Stone { base } => {
                    let (bw, bh) = (
                        0.6 + 0.2 * hash3(seed, (t / 0.42).floor() as i64, 0, 2),
                        0.42,
                    );
                    let row = (t / bh).floor();
                    let col = ((s + row * 0.27) / bw).floor();
                    let (fs, ft) = ((s + row * 0.27) / bw - col, t / bh - row);
                    let joint = fs * bw < 0.01 || ft * bh < 0.01;
                    let tint = 0.9 + 0.2 * hash3(seed, col as i64, row as i64, 3);
                    let k = if joint {
                        0.7
                    } else {
                        tint * (1.0 + 0.08 * fbm(seed, s, t, 2.0, 3)) + grain
                    };
                    scale(base, k)
                }
            }
        };

        // The wall, with holes at the openings, and shutters or sign painted on it.
        let wall_openings = openings.clone();
        self.patch(origin, dir * width, DVec3::Z * height, &mut |s, t, rng| {
            if wall_openings.iter().any(|o| o.contains(s, t)) {
                return None;
            }
            if let Some((s0, s1, t0, t1, hue, k)) = sign
                && s >= s0
                && s < s1
                && t >= t0
                && t < t1
            {
                // A sign: plain colour with a few light letters.
                let letter = hash3(k, (s / 0.25).floor() as i64, 0, 0) > 0.45
                    && (t - t0) > 0.12
                    && (t1 - t) > 0.12
                    && ((s - s0) / 0.25).fract() < 0.7;
                return Some(if letter { [0.95, 0.95, 0.9] } else { hue });
            }
            if shutters {
                for o in &wall_openings {
                    if let OpeningKind::Window { .. } = o.kind {
                        let w = (o.s1 - o.s0) / 2.0;
                        let beside = (s >= o.s0 - w && s < o.s0) || (s >= o.s1 && s < o.s1 + w);
                        if beside && t >= o.t0 && t < o.t1 {
                            let slat = if ((t - o.t0) / 0.06).fract() < 0.3 {
                                0.8
                            } else {
                                1.0
                            };
                            return Some(scale(shutter_color, slat));
                        }
                    }
                }
            }
            Some(wall_color(s, t, rng))
        });

        // Openings: recessed glazing or door, with reveals.
        for o in &openings {
            let depth = match o.kind {
                OpeningKind::Door { .. } => 0.25,
                _ => 0.18,
            };
            let back = origin - normal * depth + dir * o.s0 + DVec3::Z * o.t0;
            let (w, h) = (o.s1 - o.s0, o.t1 - o.t0);
            let kind = o.kind;
            let gseed = seed ^ (o.s0 * 1000.0) as u64;
            self.patch(back, dir * w, DVec3::Z * h, &mut |s, t, rng| {
                Some(match kind {
                    OpeningKind::Window { frame, mullion } => {
                        let edge = s < 0.06 || w - s < 0.06 || t < 0.06 || h - t < 0.06;
                        let bar =
                            mullion && ((s - w / 2.0).abs() < 0.03 || (t - h * 0.62).abs() < 0.03);
                        if edge || bar {
                            frame
                        } else {
                            // Glass reflecting a brighter sky at the top.
                            let g = 0.12
                                + 0.25 * (t / h)
                                + 0.12 * fbm(gseed, s, t, 1.5, 2)
                                + 0.02 * (rng.unit() - 0.5);
                            [g * 0.9, g, g * 1.1]
                        }
                    }
                    OpeningKind::Shop { frame } => {
                        let edge = s < 0.08 || w - s < 0.08 || t < 0.08 || h - t < 0.08;
                        if edge {
                            frame
                        } else {
                            // Goods behind the glass: blotches of colour.
                            let v = fbm(gseed, s, t, 1.2, 3);
                            let g = 0.2 + 0.3 * (v + 0.5) + 0.03 * (rng.unit() - 0.5);
                            [g * (1.0 + v), g, g * (1.0 - v)]
                        }
                    }
                    OpeningKind::Door { color } => {
                        let panel = ((s / w * 2.0).fract() - 0.5).abs() > 0.42
                            || ((t / h * 3.0).fract() - 0.5).abs() > 0.45;
                        let k = if panel { 0.75 } else { 1.0 } + 0.05 * (rng.unit() - 0.5);
                        scale(color, k)
                    }
                })
            });
            // Reveals (top, bottom, sides).
            let front = origin + dir * o.s0 + DVec3::Z * o.t0;
            let reveal =
                |s: f64, t: f64, rng: &mut SplitMix64| Some(scale(wall_color(s, t, rng), 0.8));
            let mut reveal = reveal;
            self.patch(front, -normal * depth, dir * w, &mut reveal);
            self.patch(front + DVec3::Z * h, -normal * depth, dir * w, &mut reveal);
            self.patch(front, -normal * depth, DVec3::Z * h, &mut reveal);
            self.patch(front + dir * w, -normal * depth, DVec3::Z * h, &mut reveal);
        }

        // Balconies: a slab and a railing in front of some upper windows.
        if balconies {
            for o in openings
                .iter()
                .filter(|o| matches!(o.kind, OpeningKind::Window { .. }) && o.t0 > ground_floor)
            {
                if !rng.chance(0.7) {
                    continue;
                }
                let depth = rng.uniform(0.7, 1.1);
                let (s0, s1) = (o.s0 - 0.35, o.s1 + 0.35);
                let base = origin + dir * s0 + DVec3::Z * (o.t0 - 0.05);
                let w = s1 - s0;
                let slab_color = scale([0.7, 0.7, 0.68], rng.uniform(0.85, 1.1));
                // Slab top, underside and edge.
                self.patch(base, dir * w, normal * depth, &mut |_, _, r| {
                    Some(scale(slab_color, 1.0 + 0.04 * (r.unit() - 0.5)))
                });
                self.patch(
                    base - DVec3::Z * 0.15,
                    dir * w,
                    normal * depth,
                    &mut |_, _, r| Some(scale(slab_color, 0.6 + 0.04 * (r.unit() - 0.5))),
                );
                self.patch(
                    base - DVec3::Z * 0.15 + normal * depth,
                    dir * w,
                    DVec3::Z * 0.15,
                    &mut |_, _, _| Some(slab_color),
                );
                // Railing: top bar and vertical bars (dark metal).
                let rail = base + normal * depth;
                self.patch(
                    rail + DVec3::Z * 0.95,
                    dir * w,
                    DVec3::Z * 0.05,
                    &mut |_, _, _| Some([0.12, 0.12, 0.13]),
                );
                let mut s = 0.0;
                while s < w {
                    self.patch(
                        rail + dir * s,
                        dir * 0.025,
                        DVec3::Z * 0.95,
                        &mut |_, _, _| Some([0.1, 0.1, 0.11]),
                    );
                    s += 0.12;
                }
            }
        }

        // Cornice: a protruding band at the top (front and underside).
        let cornice_h = rng.uniform(0.3, 0.6);
        let out = rng.uniform(0.15, 0.35);
        let top = origin + DVec3::Z * (height - cornice_h) + normal * out;
        let cornice_color = match material {
            Material::Render { base } | Material::Stone { base } => scale(base, 1.05),
            Material::Brick { .. } => [0.82, 0.8, 0.75],
        };
        self.patch(top, dir * width, DVec3::Z * cornice_h, &mut |s, t, r| {
            let mould = if (t / cornice_h * 3.0).fract() < 0.15 {
                0.8
            } else {
                1.0
            };
            Some(scale(
                cornice_color,
                mould + 0.05 * fbm(seed ^ 13, s, t, 2.0, 2) + 0.02 * (r.unit() - 0.5),
            ))
        });
        self.patch(top, dir * width, -normal * out, &mut |_, _, r| {
            Some(scale(cornice_color, 0.55 + 0.03 * (r.unit() - 0.5)))
        });
    }

    // ---------------------------------------------------------------- clutter

    fn clutter(&mut self) {
        let p = self.params.clone();
        let half = p.street_width_m / 2.0;
        let road = half - p.sidewalk_width_m;
        let l = p.arm_length_m;
        let mut rng = SplitMix64::new(self.seed(3));
        // For each of the eight sidewalks: trees and lamps at irregular intervals,
        // cars parked along the kerb.
        for axis in 0..2 {
            for side in [-1.0, 1.0] {
                for sign in [-1.0, 1.0] {
                    let place = |along: f64, across: f64| {
                        if axis == 0 {
                            DVec3::new(sign * along, side * across, 0.0)
                        } else {
                            DVec3::new(side * across, sign * along, 0.0)
                        }
                    };
                    let heading = if axis == 0 {
                        0.0
                    } else {
                        std::f64::consts::FRAC_PI_2
                    };
                    let mut s = half + rng.uniform(1.0, 6.0);
                    while s < l - 2.0 {
                        let across = road + rng.uniform(0.5, 0.8);
                        if rng.chance(0.55) {
                            self.tree(place(s, across) + DVec3::Z * KERB_HEIGHT_M, &mut rng);
                        } else {
                            self.lamp(place(s, across) + DVec3::Z * KERB_HEIGHT_M, &mut rng);
                        }
                        s += rng.uniform(7.0, 16.0);
                    }
                    let mut s = half + rng.uniform(4.0, 10.0);
                    while s < l - 5.0 {
                        if rng.chance(0.6) {
                            let across = road - rng.uniform(1.0, 1.2);
                            self.car(place(s, across), heading, &mut rng);
                        }
                        s += rng.uniform(5.0, 9.0);
                    }
                }
            }
        }
    }

    fn cylinder(&mut self, base: DVec3, radius: f64, height: f64, color: Rgb, seed: u64) {
        let step = self.params.spacing_m;
        let n_around = ((std::f64::consts::TAU * radius / step).ceil() as usize).max(6);
        let n_up = (height / step).ceil().max(1.0) as usize;
        for j in 0..n_up {
            for i in 0..n_around {
                let a = (i as f64 + self.rng.unit()) / n_around as f64 * std::f64::consts::TAU;
                let z = (j as f64 + self.rng.unit()) / n_up as f64 * height;
                let k =
                    1.0 + 0.15 * fbm(seed, a * radius, z, 3.0, 2) + 0.03 * (self.rng.unit() - 0.5);
                self.positions
                    .push(base + DVec3::new(radius * a.cos(), radius * a.sin(), z));
                self.colors.push(to_u8(scale(color, k)));
            }
        }
    }

    fn tree(&mut self, base: DVec3, rng: &mut SplitMix64) {
        let seed = rng.next_u64();
        let trunk_h = rng.uniform(2.2, 3.2);
        self.cylinder(
            base,
            rng.uniform(0.1, 0.18),
            trunk_h + 0.5,
            [0.3, 0.24, 0.18],
            seed,
        );
        let (rx, rz) = (rng.uniform(1.4, 2.6), rng.uniform(1.6, 2.8));
        let centre = base + DVec3::Z * (trunk_h + rz * 0.8);
        let area = 4.0 * std::f64::consts::PI * rx * rz;
        let n = (area / self.params.spacing_m.powi(2)) as usize;
        let leaf =
            [[0.22, 0.36, 0.14], [0.3, 0.42, 0.18], [0.18, 0.3, 0.16]][rng.below(3) as usize];
        let grass = self.textures.grass.clone();
        for _ in 0..n {
            let z = self.rng.uniform(-1.0, 1.0);
            let a = self.rng.uniform(0.0, std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            let bump =
                1.0 + 0.25 * fbm(seed, a * 2.0, z * 2.0, 1.0, 3) + 0.08 * (self.rng.unit() - 0.5);
            let d = DVec3::new(r * a.cos() * rx, r * a.sin() * rx, z * rz) * bump;
            let mut k =
                0.75 + 0.5 * (z * 0.5 + 0.5) + 0.3 * fbm(seed ^ 1, a * 4.0, z * 4.0, 1.0, 2);
            if let Some(t) = &grass {
                k += 0.8 * t.detail(a * rx, z * rz);
            }
            self.positions.push(centre + d);
            self.colors.push(to_u8(scale(leaf, k)));
        }
    }

    fn lamp(&mut self, base: DVec3, rng: &mut SplitMix64) {
        let seed = rng.next_u64();
        let h = rng.uniform(4.5, 6.5);
        let color =
            [[0.2, 0.22, 0.2], [0.45, 0.45, 0.47], [0.15, 0.18, 0.25]][rng.below(3) as usize];
        self.cylinder(base, 0.07, h, color, seed);
        // The head: a small box.
        let head = base + DVec3::new(-0.25, -0.15, h);
        let w = DVec3::new(0.5, 0.0, 0.0);
        let d = DVec3::new(0.0, 0.3, 0.0);
        let z = DVec3::new(0.0, 0.0, 0.2);
        let mut dark = |_: f64, _: f64, _: &mut SplitMix64| Some(color);
        let mut light = |_: f64, _: f64, _: &mut SplitMix64| Some([0.95, 0.93, 0.8]);
        self.patch(head, w, d, &mut light);
        self.patch(head + z, w, d, &mut dark);
        self.patch(head, w, z, &mut dark);
        self.patch(head + d, w, z, &mut dark);
        self.patch(head, d, z, &mut dark);
        self.patch(head + w, d, z, &mut dark);
    }

    fn car(&mut self, centre: DVec3, heading: f64, rng: &mut SplitMix64) {
        let (len, width) = (rng.uniform(3.8, 4.8), rng.uniform(1.65, 1.9));
        let paint: Rgb = [
            [0.7, 0.1, 0.1],
            [0.1, 0.15, 0.4],
            [0.85, 0.85, 0.85],
            [0.1, 0.1, 0.1],
            [0.5, 0.5, 0.52],
            [0.2, 0.35, 0.25],
            [0.8, 0.7, 0.3],
        ][rng.below(7) as usize];
        let (s, c) = heading.sin_cos();
        let ax = DVec3::new(c, s, 0.0);
        let ay = DVec3::new(-s, c, 0.0);
        let seed = rng.next_u64();
        let boxed = |g: &mut Generator,
                     x0: f64,
                     x1: f64,
                     z0: f64,
                     z1: f64,
                     w: f64,
                     color: Rgb,
                     glass: bool| {
            let o = centre + ax * x0 - ay * (w / 2.0) + DVec3::Z * z0;
            let (dx, dy, dz) = (ax * (x1 - x0), ay * w, DVec3::Z * (z1 - z0));
            let mut body = |u: f64, v: f64, r: &mut SplitMix64| {
                let k = 1.0 + 0.06 * fbm(seed, u, v, 2.0, 2) + 0.03 * (r.unit() - 0.5);
                Some(scale(color, k))
            };
            let mut window = |u: f64, v: f64, r: &mut SplitMix64| {
                let g = 0.15 + 0.1 * fbm(seed ^ 3, u, v, 1.0, 2) + 0.02 * (r.unit() - 0.5);
                Some(if v < 0.04 || v > z1 - z0 - 0.04 {
                    color
                } else {
                    [g, g, g * 1.1]
                })
            };
            let side: &mut dyn FnMut(f64, f64, &mut SplitMix64) -> Option<Rgb> =
                if glass { &mut window } else { &mut body };
            g.patch(o, dx, dz, side);
            g.patch(o + dy, dx, dz, side);
            g.patch(o, dy, dz, side);
            g.patch(o + dx, dy, dz, side);
            g.patch(o + dz, dx, dy, &mut body);
        };
        boxed(self, -len / 2.0, len / 2.0, 0.3, 0.95, width, paint, false);
        boxed(
            self,
            -len * 0.25,
            len * 0.22,
            0.95,
            1.45,
            width * 0.9,
            paint,
            true,
        );
        // Wheels: dark blocks.
        for (x, y) in [(-0.32, -0.5), (-0.32, 0.5), (0.32, -0.5), (0.32, 0.5)] {
            let o =
                centre + ax * (x * len - 0.32) + ay * (y * width - if y < 0.0 { 0.0 } else { 0.2 });
            self.patch(o, ax * 0.64, DVec3::Z * 0.62, &mut |_, _, r| {
                Some(scale([0.06, 0.06, 0.06], 1.0 + 0.2 * r.unit()))
            });
            self.patch(o + ay * 0.2, ax * 0.64, DVec3::Z * 0.62, &mut |_, _, r| {
                Some(scale([0.06, 0.06, 0.06], 1.0 + 0.2 * r.unit()))
            });
        }
    }
}
