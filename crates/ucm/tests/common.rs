//! Shared proptest strategies and helpers.

use proptest::prelude::*;
pub use test_support::{data_dir, workspace_root as root};
use ucm::{Annulus, Camera, Distortion, Intrinsics, ValidRegion};

/// Random intrinsics with ξ in [0, 1.5] and a full-image region of 640×480 (tests of
/// the geometry must not be filtered by a mask).
pub fn camera_strategy(with_distortion: bool) -> impl Strategy<Value = Camera> {
    (
        100.0..400.0f64,
        100.0..400.0f64,
        250.0..390.0f64,
        180.0..300.0f64,
        0.0..1.5f64,
        -1.0..1.0f64,
        prop::array::uniform5(-0.05..0.05f64),
    )
        .prop_map(move |(au, av, u0, v0, xi, skew, d)| {
            let intrinsics = Intrinsics {
                alpha_u: au,
                alpha_v: av,
                u0,
                v0,
                xi,
                skew,
            };
            let distortion = with_distortion.then_some(Distortion {
                k1: d[0],
                k2: d[1],
                p1: d[2] * 0.1,
                p2: d[3] * 0.1,
                k3: d[4],
            });
            Camera::new(intrinsics, distortion, 640, 480, ValidRegion::Full).unwrap()
        })
}

/// A direction on the unit sphere within `max_off_axis` radians of the optical axis,
/// and a range.
pub fn point_strategy(max_off_axis: f64) -> impl Strategy<Value = [f64; 3]> {
    (0.0..max_off_axis, 0.0..std::f64::consts::TAU, 0.3..50.0f64)
        .prop_map(|(t, p, r)| [r * t.sin() * p.cos(), r * t.sin() * p.sin(), r * t.cos()])
}

/// The largest angle off the optical axis that the camera sees (ξ-domain), minus a
/// margin, capped so that the projection stays in a sane part of the plane.
pub fn max_off_axis(xi: f64) -> f64 {
    let limit = if xi <= 1.0 {
        (-xi).acos()
    } else {
        (-1.0 / xi).acos()
    };
    (limit - 0.25).min(2.2)
}

/// A twist with components in a box.
pub fn twist_strategy() -> impl Strategy<Value = [f64; 6]> {
    prop::array::uniform6(-1.0..1.0f64)
}

/// The fixture camera of the protocols.
pub fn fixture_320() -> Camera {
    Camera::load_toml(root().join("fixtures/omni-320x240.toml")).unwrap()
}

/// A relative error robust to tiny values.
pub fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    let norm: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    diff / norm.max(1e-9)
}

/// An annulus camera of the fixture's geometry at any size (for region tests).
pub fn annulus(inner: f64, outer: f64) -> ValidRegion {
    ValidRegion::Annulus(Annulus {
        center_px: [159.5, 119.5],
        inner_radius_px: inner,
        outer_radius_px: outer,
    })
}
