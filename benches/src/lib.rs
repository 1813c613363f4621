//! Shared set-up of the criterion benchmarks in `benches/benches/` and of the
//! measurement examples in `benches/examples/` (the renderer's level of detail and
//! occlusion culling against references): the fixture cameras, street views and
//! deterministic synthetic inputs, so that every bench measures the same thing.
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

/// `n` points around a catadioptric camera looking down (Z to the ground), 2–30 m
/// away, most of them in its field of view.
pub fn points_around_camera(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = splat::rng::SplitMix64::new(seed);
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

/// Street views of the synthetic city, `(x, y, height, heading_rad)` of a camera
/// looking down: along the X street, low and high, near the crossing, in the Y street.
/// The first five are the views of the `occlusion` example's published figures.
pub const STREET_VIEWS: [(f64, f64, f64, f64); 7] = [
    (-20.0, 0.5, 3.0, 0.0),
    (-28.0, 2.5, 4.5, 0.0),
    (-12.0, -1.5, 1.5, 0.2),
    (0.4, -38.0, 3.0, 1.57),
    (-2.0, 0.0, 3.0, 0.3),
    (30.0, 1.0, 2.0, 0.1),
    (0.0, 25.0, 3.5, 1.4),
];

/// `camera_from_world` of a street view.
pub fn camera_from_world((x, y, z, heading): (f64, f64, f64, f64)) -> ucm::Isometry3 {
    world::city::camera_looking_down(glam::DVec3::new(x, y, z), heading).inverse()
}
