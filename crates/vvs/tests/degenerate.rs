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
    for method in Method::PAPER {
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

/// Pictures with nothing to align to are refused, not localised to a pose that
/// "stalls" with a low cost: black, white, one grey, nothing observed, a NaN.
#[test]
fn a_desired_image_without_content_is_a_typed_error() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, short()).unwrap();
    let uniform = |value: f32| {
        let mut desired = Frame::for_camera(&camera);
        for (k, s) in desired.status.iter_mut().enumerate() {
            *s = if camera.valid_pixels()[k] {
                PixelStatus::Hit
            } else {
                PixelStatus::Masked
            };
            desired.range_m[k] = 5.0;
            desired.intensity[k] = value;
        }
        desired
    };
    let valid = camera.valid_pixels().iter().filter(|&&v| v).count();
    for value in [0.0, 1.0, 0.5] {
        for method in Method::ALL {
            let outcome = match method {
                Method::Global => servo.localize_in_box(
                    &uniform(value),
                    desired_pose(),
                    &vvs::PriorBox::default(),
                ),
                local => servo.run(local, &uniform(value), desired_pose()),
            };
            match outcome {
                Err(VvsError::UniformDesired { value: v, observed }) => {
                    assert_eq!((v, observed), (value, valid));
                }
                other => panic!("{method:?}, {value}: {other:?}"),
            }
        }
    }
    // One pixel off by a level is a picture: it runs.
    let mut almost = uniform(0.5);
    let k = camera.valid_pixels().iter().position(|&v| v).unwrap();
    almost.intensity[k] = 0.5 + 1.0 / 255.0;
    servo.run(Method::Rule2, &almost, desired_pose()).unwrap();
    let mut unseen = uniform(0.5);
    unseen.status.fill(PixelStatus::Masked);
    assert!(matches!(
        servo.run(Method::Povs, &unseen, desired_pose()),
        Err(VvsError::EmptyDesired)
    ));
    let mut nan = servo.render(&desired_pose()).unwrap();
    nan.intensity[k] = f32::NAN;
    assert!(matches!(
        servo.run(Method::Rule2, &nan, desired_pose()),
        Err(VvsError::NonFiniteDesired { index }) if index == k
    ));
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
    let paper_box = vvs::PriorBox::default();
    assert!(matches!(
        servo.run(Method::Rule2, &desired, nan),
        Err(VvsError::NonFinitePose)
    ));
    assert!(matches!(
        servo.localize_in_box(&desired, nan, &paper_box),
        Err(VvsError::NonFinitePose)
    ));
    assert!(matches!(
        servo.run(Method::Rule2, &Frame::new(4, 4), desired_pose()),
        Err(VvsError::DesiredSize { .. })
    ));
    assert!(matches!(
        servo.localize_in_box(&Frame::new(4, 4), desired_pose(), &paper_box),
        Err(VvsError::DesiredSize { .. })
    ));
    // Buffers a caller shortened (they are public fields): typed errors, not panics.
    for what in ["intensity", "range_m", "status"] {
        let mut shortened = desired.clone();
        match what {
            "intensity" => shortened.intensity.truncate(10),
            "range_m" => shortened.range_m.truncate(10),
            _ => shortened.status.truncate(10),
        }
        let expected = |e: Option<VvsError>| matches!(e, Some(VvsError::Frame(frame::FrameError::Length { what: w, got: 10, .. })) if w == what);
        let run = servo.run(Method::Rule2, &shortened, desired_pose()).err();
        assert!(expected(run), "{what}");
        let search = servo
            .localize_in_box(&shortened, desired_pose(), &paper_box)
            .err();
        assert!(expected(search), "{what}");
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
