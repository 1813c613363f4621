//! Shared helpers.

use std::sync::OnceLock;
pub use test_support::workspace_root as root;

use world::city::{City, CityParams};

/// A fixture camera by file name.
pub fn fixture(name: &str) -> ucm::Camera {
    ucm::Camera::load_toml(root().join("fixtures").join(name)).unwrap()
}

/// The default city, generated once per test binary.
pub fn default_city() -> &'static City {
    static CITY: OnceLock<City> = OnceLock::new();
    CITY.get_or_init(|| City::generate(&CityParams::default()).unwrap())
}
