//! Procedural texture: value noise, fractal sums, and optional photographic textures.

use std::path::Path;

use crate::WorldError;
use splat::rng::hash3;

/// Smooth value noise in `[0, 1]` at `(x, y)` (unit lattice), seeded.
pub fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (xi, yi) = (xf as i64, yf as i64);
    let (tx, ty) = (x - xf, y - yf);
    let s = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (s(tx), s(ty));
    let h = |dx: i64, dy: i64| hash3(seed, xi + dx, yi + dy, 0);
    let a = h(0, 0) + (h(1, 0) - h(0, 0)) * sx;
    let b = h(0, 1) + (h(1, 1) - h(0, 1)) * sx;
    a + (b - a) * sy
}

/// Fractal sum of `octaves` of value noise, base `frequency` (cycles per metre),
/// centred on 0, amplitude about ±0.5.
pub fn fbm(seed: u64, x: f64, y: f64, frequency: f64, octaves: u32) -> f64 {
    let mut sum = 0.0;
    let mut amplitude = 0.5;
    let mut f = frequency;
    let mut norm = 0.0;
    for o in 0..octaves {
        sum +=
            amplitude * (value_noise(seed.wrapping_add(u64::from(o) * 7919), x * f, y * f) - 0.5);
        norm += amplitude;
        amplitude *= 0.5;
        f *= 2.03;
    }
    sum / norm
}

/// A grey-level photograph used as a tiling texture.
#[derive(Clone, Debug)]
pub struct ImageTexture {
    width: usize,
    height: usize,
    values: Vec<f32>,
    mean: f32,
    /// Metres covered by the texture's width.
    pub size_m: f64,
}

impl ImageTexture {
    /// Read a PNG (converted to grey levels) that tiles over `size_m` metres.
    pub fn load(path: &Path, size_m: f64) -> Result<Self, WorldError> {
        let image = image::open(path)
            .map_err(|source| WorldError::Texture {
                path: path.to_owned(),
                source,
            })?
            .into_luma8();
        let (w, h) = image.dimensions();
        let values: Vec<f32> = image.pixels().map(|p| f32::from(p.0[0]) / 255.0).collect();
        let mean = values.iter().sum::<f32>() / values.len().max(1) as f32;
        Ok(Self {
            width: w as usize,
            height: h as usize,
            values,
            mean,
            size_m,
        })
    }

    /// Deviation from the texture's mean at `(s, t)` metres (tiling), about ±0.3.
    pub fn detail(&self, s: f64, t: f64) -> f64 {
        let scale = self.width as f64 / self.size_m;
        let i = ((s * scale).floor() as i64).rem_euclid(self.width as i64) as usize;
        let j = ((t * scale).floor() as i64).rem_euclid(self.height as i64) as usize;
        f64::from(self.values[j * self.width + i] - self.mean)
    }
}

/// The optional photographic textures of a city.
#[derive(Clone, Debug, Default)]
pub struct Textures {
    /// Modulates brick facades.
    pub brick: Option<ImageTexture>,
    /// Modulates the asphalt.
    pub gravel: Option<ImageTexture>,
    /// Modulates tree crowns and verges.
    pub grass: Option<ImageTexture>,
}

impl Textures {
    /// Read `brick.png`, `gravel.png` and `grass.png` from a folder, each if present.
    /// The folder itself must exist.
    pub fn from_dir(dir: &Path) -> Result<Self, WorldError> {
        if !dir.is_dir() {
            return Err(WorldError::Io {
                path: dir.to_owned(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "not a folder"),
            });
        }
        let load = |name: &str, size_m: f64| -> Result<Option<ImageTexture>, WorldError> {
            let path = dir.join(name);
            if path.exists() {
                ImageTexture::load(&path, size_m).map(Some)
            } else {
                Ok(None)
            }
        };
        Ok(Self {
            brick: load("brick.png", 1.6)?,
            gravel: load("gravel.png", 1.2)?,
            grass: load("grass.png", 1.0)?,
        })
    }
}
