//! Shared set-up of the criterion benchmarks in `benches/benches/`: the fixture cameras
//! and deterministic synthetic inputs, so that every bench measures the same thing.
#![deny(missing_docs)]

use std::path::{Path, PathBuf};

/// The workspace root.
pub fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("benches/ lives in the workspace root")
        .to_path_buf()
}

/// A fixture camera by file name (`omni-320x240.toml` or `omni-640x480.toml`).
pub fn fixture_camera(name: &str) -> ucm::Camera {
    let path = project_root().join("fixtures").join(name);
    ucm::Camera::load_toml(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A small deterministic generator (SplitMix64), so that bench inputs do not depend
/// on a random crate's version.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` points around a catadioptric camera looking down (Z to the ground), 2–30 m
/// away, most of them in its field of view.
pub fn points_around_camera(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| {
            let azimuth = rng.uniform(0.0, std::f64::consts::TAU);
            let off_nadir = rng.uniform(0.6, 2.2);
            let range = rng.uniform(2.0, 30.0);
            [
                (range * off_nadir.sin() * azimuth.cos()) as f32,
                (range * off_nadir.sin() * azimuth.sin()) as f32,
                (range * off_nadir.cos()) as f32,
            ]
        })
        .collect()
}
