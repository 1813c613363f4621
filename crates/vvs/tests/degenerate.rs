//! Degenerate inputs end with a clear status or a typed error, never a panic.

use frame::{Frame, PixelStatus};
use ucm::Isometry3;
use vvs::{Divergence, Method, Servo, StopReason, VvsConfig, VvsError};

use crate::common::*;

fn short() -> VvsConfig {
    VvsConfig {
        step1_max_iterations: 10,
        max_iterations: 20,
        ..VvsConfig::default()
    }
}

#[test]
fn a_camera_far_above_the_city_sees_nothing() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, short()).unwrap();
    let desired = servo.render(&desired_pose()).unwrap();
    let start = offset([0.0, 0.0, -2000.0, 0.0, 0.0, 0.0]);
    for method in Method::ALL {
        let outcome = servo.run(method, &desired, start).unwrap();
        assert_eq!(
            outcome.stop,
            StopReason::Diverged(Divergence::NoValidPixels),
            "{method:?}"
        );
    }
}

#[test]
fn a_camera_inside_a_building_does_not_report_success() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, short()).unwrap();
    let desired = servo.render(&desired_pose()).unwrap();
    // 9 m across the street: behind the facade, inside the block.
    let start = offset([0.0, -9.0, 0.0, 0.0, 0.0, 0.0]);
    for method in [Method::Povs, Method::Rule2] {
        let outcome = servo.run(method, &desired, start).unwrap();
        let (dt, _) = outcome.world_from_camera.distance_to(&desired_pose());
        assert!(dt > 1.0, "{method:?}: {dt}");
        assert_ne!(outcome.stop, StopReason::Converged, "{method:?}");
    }
}

#[test]
fn an_all_black_desired_image_ends_with_a_clear_status() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, short()).unwrap();
    let mut desired = Frame::for_camera(&camera);
    for (k, s) in desired.status.iter_mut().enumerate() {
        *s = if camera.valid_pixels()[k] {
            PixelStatus::Hit
        } else {
            PixelStatus::Masked
        };
        desired.range_m[k] = 5.0;
    }
    for method in Method::ALL {
        let outcome = servo.run(method, &desired, desired_pose()).unwrap();
        // It cannot match a black image: no false success.
        assert!(outcome.cost > 1e-3, "{method:?}: cost {}", outcome.cost);
        assert_ne!(outcome.stop, StopReason::Converged, "{method:?}");
    }
}

#[test]
fn invalid_input_is_a_typed_error() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, short()).unwrap();
    let desired = servo.render(&desired_pose()).unwrap();
    let nan = Isometry3 {
        translation: glam::DVec3::NAN,
        ..Isometry3::IDENTITY
    };
    for method in [Method::Rule2, Method::Global] {
        assert!(matches!(
            servo.run(method, &desired, nan),
            Err(VvsError::NonFinitePose)
        ));
        assert!(matches!(
            servo.run(method, &Frame::new(4, 4), desired_pose()),
            Err(VvsError::DesiredSize { .. })
        ));
    }
    let lying_box = vvs::PriorBox {
        translation_m: [f64::INFINITY, 0.0, 0.0],
        rotation_deg: [0.0; 3],
    };
    assert!(matches!(
        servo.localize_in_box(&desired, desired_pose(), &lying_box),
        Err(VvsError::Config { .. })
    ));
    let bad = VvsConfig {
        gain: 0.0,
        ..VvsConfig::default()
    };
    assert!(matches!(
        Servo::new(&city().cloud, &camera, bad),
        Err(VvsError::Config { name: "gain", .. })
    ));
}
