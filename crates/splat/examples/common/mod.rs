//! What the examples share.

use glam::DVec3;
use world::city::camera_looking_down;

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
    camera_looking_down(DVec3::new(x, y, z), heading).inverse()
}
