//! The tracker on rendered sequences with known ground truth.

use std::ops::ControlFlow;

use frame::Image;
use glam::DVec3;
use ucm::Isometry3;
use vvs::{Method, Servo, StopReason, Tracker, VvsConfig, VvsError};
use world::{Acquisition, camera_looking_down};

use crate::common::*;

/// A camera moving 2 cm per frame along the street, turning slowly.
fn truth(frames: usize) -> Vec<Isometry3> {
    (0..frames)
        .map(|k| {
            let k = k as f64;
            camera_looking_down(DVec3::new(-20.0 + 0.02 * k, 0.5, 3.0), 0.004 * k)
        })
        .collect()
}

fn config() -> VvsConfig {
    VvsConfig {
        keep_history: false,
        ..VvsConfig::default()
    }
}

/// PGMoT and PoT follow measured pictures (the acquisition simulator: vignetting off,
/// gain, noise, blur, another sampling omitted) with 1 frame in 1 and in 3, to
/// millimetres; the tracker uses exactly the frames it should.
#[test]
fn tracks_measured_pictures_one_frame_in_n() {
    let camera = fixture();
    let truth = truth(7);
    let mut servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let acquisition = Acquisition {
        vignetting: 0.0,
        ..Acquisition::default()
    };
    let pictures: Vec<Image> = truth
        .iter()
        .enumerate()
        .map(|(k, pose)| {
            let rendered = servo.render(pose).unwrap();
            acquisition.acquire(&rendered, &camera, k, k as f64 / 30.0)
        })
        .collect();
    for (method, step) in [(Method::Rule2, 1), (Method::Rule2, 3), (Method::Povs, 1)] {
        let servo = Servo::new(
            &city().cloud,
            &camera,
            VvsConfig {
                normalize: true,
                ..config()
            },
        )
        .unwrap();
        let start =
            truth[0] * Isometry3::from_pose_vector([0.02, -0.02, 0.01, 0.0, 0.0, 0.01]).unwrap();
        let mut tracker = Tracker::new(servo, method, start).unwrap();
        let report = tracker
            .track(pictures.iter().map(Some), step, |_| {
                ControlFlow::Continue(())
            })
            .unwrap();
        assert!(!report.lost, "{method:?} N={step}");
        let used: Vec<usize> = report.frames.iter().map(|f| f.frame).collect();
        assert_eq!(used, (0..7).step_by(step).collect::<Vec<_>>());
        for tracked in &report.frames {
            let (dt, dr) = tracked
                .outcome
                .world_from_camera
                .distance_to(&truth[tracked.frame]);
            eprintln!(
                "{method:?} N={step} frame {}: {dt:.4} m, {:.3}°",
                tracked.frame,
                dr.to_degrees()
            );
            assert!(
                dt < 0.01 && dr.to_degrees() < 0.3,
                "{method:?} N={step}: {dt} m"
            );
        }
        let last = report.frames.last().unwrap();
        assert_eq!(tracker.estimate(), last.outcome.world_from_camera);
    }
}

/// The caller's stop and a divergence both lose the track; a lost tracker aligns
/// nothing more; a missing frame and a zero step are typed errors.
#[test]
fn lost_tracks_and_bad_input() {
    let camera = fixture();
    let truth = truth(4);
    let mut servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let frames: Vec<_> = truth.iter().map(|p| servo.render(p).unwrap()).collect();

    // Stopped by the caller after the second aligned frame.
    let mut tracker = Tracker::new(servo, Method::Rule2, truth[0]).unwrap();
    let mut seen = 0;
    let report = tracker
        .track(frames.iter().map(Some), 1, |_| {
            seen += 1;
            if seen == 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap();
    assert!(report.lost);
    assert_eq!(report.frames.len(), 2);

    // A missing frame to be used; a zero step.
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let mut tracker = Tracker::new(servo, Method::Povs, truth[0]).unwrap();
    let gappy = [Some(&frames[0]), None, Some(&frames[2])];
    assert!(matches!(
        tracker.track(gappy, 1, |_| ControlFlow::Continue(())),
        Err(VvsError::MissingFrame(1))
    ));
    let gappy = [Some(&frames[0]), None, Some(&frames[2])];
    assert!(
        tracker
            .track(gappy, 2, |_| ControlFlow::Continue(()))
            .is_ok()
    );
    assert!(matches!(
        tracker.track(frames.iter().map(Some), 0, |_| ControlFlow::Continue(())),
        Err(VvsError::Config { .. })
    ));

    // Diverged: a camera far above the city sees nothing.
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let high = camera_looking_down(DVec3::new(-20.0, 0.5, 500.0), 0.0);
    let mut tracker = Tracker::new(servo, Method::Rule2, high).unwrap();
    let outcome = tracker.align(&frames[0]).unwrap();
    assert!(matches!(outcome.stop, StopReason::Diverged(_)));
    assert!(tracker.is_lost());
    assert_eq!(tracker.estimate(), high, "a diverged pose is not kept");
    assert!(matches!(
        tracker.align(&frames[1]),
        Err(VvsError::TrackLost)
    ));
    let report = tracker
        .track(frames.iter().map(Some), 1, |_| ControlFlow::Continue(()))
        .unwrap();
    assert!(report.lost && report.frames.is_empty());

    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let nan = Isometry3::from_translation(DVec3::new(f64::NAN, 0.0, 0.0));
    assert!(matches!(
        Tracker::new(servo, Method::Rule2, nan),
        Err(VvsError::NonFinitePose)
    ));
}

/// The constant-velocity prediction repeats the last motion between aligned frames:
/// on a steady motion it starts the next frame far closer than the last estimate.
#[test]
fn constant_velocity_predicts_a_steady_motion() {
    let camera = fixture();
    let truth = truth(7);
    let mut servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let frames: Vec<_> = truth.iter().map(|p| servo.render(p).unwrap()).collect();
    let mut tracker = Tracker::new(servo, Method::Rule2, truth[0])
        .unwrap()
        .with_constant_velocity(true);
    assert_eq!(tracker.prediction(), truth[0], "nothing to extrapolate yet");
    let first = tracker.align(&frames[0]).unwrap().world_from_camera;
    assert_eq!(tracker.prediction(), first, "one estimate: no velocity yet");
    let second = tracker.align(&frames[3]).unwrap().world_from_camera;
    let predicted = tracker.prediction();
    let expected = second * (first.inverse() * second);
    let (dt, dr) = predicted.distance_to(&expected);
    assert!(dt < 1e-12 && dr < 1e-12);
    let (from_prediction, _) = predicted.distance_to(&truth[6]);
    let (from_estimate, _) = second.distance_to(&truth[6]);
    eprintln!("frame 6 starts {from_prediction:.4} m away (last estimate: {from_estimate:.4} m)");
    assert!(from_prediction < from_estimate / 5.0);
}
