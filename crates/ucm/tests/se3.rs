//! SE(3): exp/log round trips (near 0 and near π), pose vectors, composition.

use glam::DVec3;
use proptest::prelude::*;
use std::f64::consts::PI;
use ucm::Isometry3;
use ucm::se3::{quat_from_rotation_vector, rotation_vector_from_quat};

fn axis_angle_strategy(min_angle: f64, max_angle: f64) -> impl Strategy<Value = DVec3> {
    (0.0..PI, 0.0..2.0 * PI, min_angle..max_angle)
        .prop_map(|(t, p, a)| DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos()) * a)
}

fn close_isometries(a: &Isometry3, b: &Isometry3, tol: f64) -> bool {
    let (dt, dr) = a.distance_to(b);
    dt <= tol && dr <= tol
}

proptest! {
    #[test]
    fn log_of_exp_is_identity(
        t in prop::array::uniform3(-5.0..5.0f64),
        w in prop_oneof![
            axis_angle_strategy(0.0, 1e-6),
            axis_angle_strategy(1e-6, 1e-2),
            axis_angle_strategy(1e-2, PI - 1e-2),
            axis_angle_strategy(PI - 1e-2, PI - 1e-7),
        ],
    ) {
        let v = [t[0], t[1], t[2], w.x, w.y, w.z];
        let back = Isometry3::exp(v).unwrap().log();
        for k in 0..6 {
            prop_assert!((back[k] - v[k]).abs() < 1e-9 * (1.0 + v[k].abs()) * if w.length() > PI - 1e-3 { 1e3 } else { 1.0 },
                "component {k}: {} vs {}", back[k], v[k]);
        }
    }

    #[test]
    fn exp_of_log_is_identity(
        t in prop::array::uniform3(-50.0..50.0f64),
        w in prop_oneof![
            axis_angle_strategy(0.0, 1e-7),
            axis_angle_strategy(0.0, PI),
            axis_angle_strategy(PI - 1e-6, PI),
        ],
    ) {
        let iso = Isometry3::from_pose_vector([t[0], t[1], t[2], w.x, w.y, w.z]).unwrap();
        let back = Isometry3::exp(iso.log()).unwrap();
        prop_assert!(close_isometries(&back, &iso, 1e-8), "{back:?} vs {iso:?}");
    }

    #[test]
    fn rotation_vector_round_trip(w in prop_oneof![
        axis_angle_strategy(0.0, 1e-9),
        axis_angle_strategy(1e-9, PI - 1e-9),
    ]) {
        let back = rotation_vector_from_quat(quat_from_rotation_vector(w));
        prop_assert!((back - w).length() < 1e-12 * (1.0 + w.length()) + 1e-15);
    }

    #[test]
    fn pose_vector_round_trip(t in prop::array::uniform3(-100.0..100.0f64), w in axis_angle_strategy(0.0, PI - 1e-9)) {
        let r = [t[0], t[1], t[2], w.x, w.y, w.z];
        let back = Isometry3::from_pose_vector(r).unwrap().to_pose_vector();
        for k in 0..6 {
            prop_assert!((back[k] - r[k]).abs() < 1e-9, "{back:?} vs {r:?}");
        }
    }

    #[test]
    fn inverse_composes_to_identity(t in prop::array::uniform3(-10.0..10.0f64), w in axis_angle_strategy(0.0, PI)) {
        let a = Isometry3::from_pose_vector([t[0], t[1], t[2], w.x, w.y, w.z]).unwrap();
        prop_assert!(close_isometries(&(a * a.inverse()), &Isometry3::IDENTITY, 1e-12));
        let p = DVec3::new(1.0, -2.0, 3.0);
        prop_assert!((a.inverse().transform_point(a * p) - p).length() < 1e-12);
    }

    /// exp(v) is the flow of the twist: for a small step, a point of the world seen from
    /// the moved camera moves by −υ − ω × X (the convention of the interaction matrices).
    #[test]
    fn exp_is_the_flow_of_the_twist(v in prop::array::uniform6(-1.0..1.0f64), p in prop::array::uniform3(-5.0..5.0f64)) {
        let x = DVec3::from_array(p);
        let h = 1e-6;
        let step = |s: f64| Isometry3::exp(v.map(|c| c * s)).unwrap().inverse().transform_point(x);
        let numeric = (step(h) - step(-h)) / (2.0 * h);
        let upsilon = DVec3::new(v[0], v[1], v[2]);
        let omega = DVec3::new(v[3], v[4], v[5]);
        let analytic = -upsilon - omega.cross(x);
        prop_assert!((numeric - analytic).length() < 1e-7 * (1.0 + analytic.length()));
    }
}

#[test]
fn exp_of_translation_and_half_turn() {
    let a = Isometry3::exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]).unwrap();
    assert_eq!(a.translation, DVec3::new(1.0, 2.0, 3.0));
    // A half turn about Z: the pose vector angle is π (the axis sign is arbitrary).
    let half = Isometry3::from_pose_vector([0.0, 0.0, 0.0, 0.0, 0.0, PI]).unwrap();
    assert!((half.angle_rad() - PI).abs() < 1e-12);
    let p = half.transform_point(DVec3::X);
    assert!((p - DVec3::NEG_X).length() < 1e-12);
    let w = DVec3::from_slice(&half.to_pose_vector()[3..]);
    assert!((w.length() - PI).abs() < 1e-12 && w.x.abs() < 1e-12 && w.y.abs() < 1e-12);
}

#[test]
fn non_finite_pose_is_an_error() {
    assert!(Isometry3::from_pose_vector([0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]).is_err());
    assert!(Isometry3::exp([0.0, 0.0, 0.0, f64::INFINITY, 0.0, 0.0]).is_err());
}
