use std::path::PathBuf;
use std::sync::OnceLock;

use glam::DVec3;
use ucm::Isometry3;
use world::city::{City, CityParams, camera_looking_down};

pub fn fixture() -> ucm::Camera {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    ucm::Camera::load_toml(root.join("fixtures/omni-320x240.toml")).unwrap()
}

pub fn city() -> &'static City {
    static CITY: OnceLock<City> = OnceLock::new();
    CITY.get_or_init(|| City::generate(&CityParams::default()).unwrap())
}

/// The desired pose of the tests: 3 m above the road of the X street, looking down.
pub fn desired_pose() -> Isometry3 {
    camera_looking_down(DVec3::new(-20.0, 0.5, 3.0), 0.0)
}

/// The desired pose moved by `(t, θw)` in its own frame.
pub fn offset(r: [f64; 6]) -> Isometry3 {
    desired_pose() * Isometry3::from_pose_vector(r).unwrap()
}
