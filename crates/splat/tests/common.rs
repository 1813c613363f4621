//! Shared helpers.

use std::path::PathBuf;
use std::sync::OnceLock;

use splat::city::{City, CityParams};

/// The workspace root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A fixture camera by file name.
pub fn fixture(name: &str) -> ucm::Camera {
    ucm::Camera::load_toml(root().join("fixtures").join(name)).unwrap()
}

/// The shared real data (`PGM_DATA_DIR`, else `../shared/data` beside the checkout);
/// `None` (skipped, with a message) only outside CI.
pub fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("PGM_DATA_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else if std::env::var_os("CI").is_some() {
        panic!("PGM_DATA_DIR ({}) is not a folder in CI", dir.display());
    } else {
        eprintln!(
            "skipped: no data folder at {} (set PGM_DATA_DIR)",
            dir.display()
        );
        None
    }
}

/// The default city, generated once per test binary.
pub fn default_city() -> &'static City {
    static CITY: OnceLock<City> = OnceLock::new();
    CITY.get_or_init(|| City::generate(&CityParams::default()).unwrap())
}

/// A temporary folder unique to this process and name.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("splat-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
