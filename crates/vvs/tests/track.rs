//! The tracker on rendered sequences with known ground truth.

use std::ops::ControlFlow;

use frame::Image;
use glam::DVec3;
use ucm::Isometry3;
use vvs::{
    Localizer, Method, Prediction, PriorBox, Recovery, Servo, StopReason, Tracker, VvsConfig,
    VvsError,
};
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

/// The pictures `camera` takes at `truth`, 30 a second: rendered, then acquired (the
/// acquisition simulator without vignetting).
fn measured_pictures(camera: &ucm::Camera, truth: &[Isometry3]) -> Vec<Image> {
    let mut servo = Servo::new(&city().cloud, camera, config()).unwrap();
    let acquisition = Acquisition {
        vignetting: 0.0,
        ..Acquisition::default()
    };
    truth
        .iter()
        .enumerate()
        .map(|(k, pose)| {
            let rendered = servo.render(pose).unwrap();
            acquisition
                .acquire(&rendered, camera, k, k as f64 / 30.0)
                .unwrap()
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
    let pictures = measured_pictures(&camera, &truth);
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
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    assert!(matches!(
        Tracker::new(servo, Method::Global, truth[0]),
        Err(VvsError::GlobalWithoutPrior)
    ));
}

/// The predictions extrapolate the last two estimates: the last one itself, the whole
/// last motion repeated, or its translation alone with the last orientation.
#[test]
fn predictions_extrapolate_the_last_two_estimates() {
    let previous = Isometry3::from_pose_vector([1.0, -2.0, 0.5, 0.1, -0.2, 0.3]).unwrap();
    let estimate =
        previous * Isometry3::from_pose_vector([0.2, 0.05, -0.01, 0.02, -0.03, 0.05]).unwrap();
    for prediction in [
        Prediction::Last,
        Prediction::ConstantVelocity,
        Prediction::ConstantTranslation,
    ] {
        assert_eq!(
            prediction.predict(estimate, None),
            estimate,
            "{prediction:?}"
        );
        // Its name is the one settings files use.
        let written = toml::Value::try_from(prediction).unwrap();
        assert_eq!(written.as_str(), Some(prediction.name()));
    }
    assert_eq!(Prediction::default(), Prediction::Last);
    assert_eq!(Prediction::Last.predict(estimate, Some(previous)), estimate);
    let velocity = Prediction::ConstantVelocity.predict(estimate, Some(previous));
    let (dt, dr) = velocity.distance_to(&(estimate * (previous.inverse() * estimate)));
    assert!(dt < 1e-12 && dr < 1e-12);
    let translation = Prediction::ConstantTranslation.predict(estimate, Some(previous));
    assert_eq!(translation.rotation, estimate.rotation);
    let expected = 2.0 * estimate.translation - previous.translation;
    assert!((translation.translation - expected).length() < 1e-12);
}

/// The constant-velocity prediction repeats the last motion between aligned frames:
/// on a steady motion it starts the next frame far closer than the last estimate.
#[test]
fn constant_velocity_predicts_a_steady_motion() {
    let camera = fixture();
    let truth = truth(7);
    let mut servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let frames: Vec<_> = truth.iter().map(|p| servo.render(p).unwrap()).collect();
    // The initial pose is a guess: its correction is not a motion of the camera.
    let initial =
        truth[0] * Isometry3::from_pose_vector([0.05, -0.05, 0.02, 0.0, 0.0, 0.02]).unwrap();
    let mut tracker = Tracker::new(servo, Method::Rule2, initial)
        .unwrap()
        .with_prediction(Prediction::ConstantVelocity);
    assert_eq!(tracker.prediction(), initial, "nothing to extrapolate yet");
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

/// Recovery: an alignment that ends farther from its start than the gates allow is
/// searched again in the box around its start, and the search's outcome is kept; an
/// alignment within the gates is kept as it is; a search that diverges loses the
/// track; bad gates are typed errors.
#[test]
fn recovery_searches_again_after_a_failed_alignment() {
    let camera = fixture();
    let truth = truth(4);
    let mut servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let frames: Vec<_> = truth.iter().map(|p| servo.render(p).unwrap()).collect();
    let start = truth[0] * Isometry3::from_pose_vector([0.15, -0.1, 0.0, 0.0, 0.0, 0.02]).unwrap();
    // Gates tighter than the start's error: the converged alignment counts as a jump.
    let strict = Recovery {
        max_jump_m: 0.05,
        max_jump_deg: 20.0,
        search: PriorBox {
            translation_m: [0.5, 0.5, 0.25],
            rotation_deg: [5.0, 5.0, 5.0],
        },
    };
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let mut tracker = Tracker::new(servo, Method::Rule2, start)
        .unwrap()
        .with_recovery(Some(strict.clone()))
        .unwrap();
    let outcome = tracker.align(&frames[0]).unwrap();
    assert!(tracker.recovered() && !tracker.is_lost());
    assert!(outcome.search.is_some(), "the kept outcome is the search's");
    let (dt, dr) = outcome.world_from_camera.distance_to(&truth[0]);
    eprintln!("recovered: {dt:.4} m, {:.3}°", dr.to_degrees());
    assert!(dt < 0.01 && dr.to_degrees() < 0.3);
    // The next frame, 2 cm on: within the gates, not searched again.
    let outcome = tracker.align(&frames[1]).unwrap();
    assert!(!tracker.recovered() && outcome.search.is_none());
    assert!(outcome.world_from_camera.distance_to(&truth[1]).0 < 0.01);
    // Through `track`, each frame says whether it was searched again.
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let mut tracker = Tracker::new(servo, Method::Rule2, start)
        .unwrap()
        .with_recovery(Some(strict.clone()))
        .unwrap();
    let report = tracker
        .track(frames.iter().map(Some), 2, |_| ControlFlow::Continue(()))
        .unwrap();
    assert!(!report.lost);
    let recovered: Vec<bool> = report.frames.iter().map(|f| f.recovered).collect();
    assert_eq!(recovered, [true, false]);

    // Without recovery the same start converges as it is.
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let mut tracker = Tracker::new(servo, Method::Rule2, start).unwrap();
    let outcome = tracker.align(&frames[0]).unwrap();
    assert!(!tracker.recovered() && outcome.search.is_none());

    // A camera far above the city: the alignment and the search both diverge.
    let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
    let high = camera_looking_down(DVec3::new(-20.0, 0.5, 500.0), 0.0);
    let mut tracker = Tracker::new(servo, Method::Rule2, high)
        .unwrap()
        .with_recovery(Some(Recovery::default()))
        .unwrap();
    let outcome = tracker.align(&frames[0]).unwrap();
    assert!(tracker.recovered() && tracker.is_lost());
    assert!(matches!(
        outcome.stop,
        StopReason::Diverged(_) | StopReason::IterationBudget
    ));
    assert_eq!(tracker.estimate(), high);

    // Bad gates.
    for bad in [
        Recovery {
            max_jump_m: 0.0,
            ..Recovery::default()
        },
        Recovery {
            max_jump_deg: f64::NAN,
            ..Recovery::default()
        },
        Recovery {
            search: PriorBox {
                translation_m: [-1.0, 1.0, 1.0],
                rotation_deg: [1.0; 3],
            },
            ..Recovery::default()
        },
    ] {
        let servo = Servo::new(&city().cloud, &camera, config()).unwrap();
        assert!(matches!(
            Tracker::new(servo, Method::Rule2, truth[0])
                .unwrap()
                .with_recovery(Some(bad)),
            Err(VvsError::Config { .. })
        ));
    }
}

/// The tracker's defaults (step 1 from λ* = 7.5) follow measured pictures as closely as
/// the localiser's (from λ* = 15), in fewer iterations: a frame's start is well inside
/// λ = 7.5's basin.
#[test]
fn the_tracker_defaults_follow_as_closely_in_fewer_iterations() {
    let camera = fixture();
    let truth = truth(5);
    let pictures = measured_pictures(&camera, &truth);
    let start =
        truth[0] * Isometry3::from_pose_vector([0.03, -0.02, 0.01, 0.0, 0.0, 0.01]).unwrap();
    let track = |config: VvsConfig| {
        let servo = Servo::new(&city().cloud, &camera, config).unwrap();
        let mut tracker = Tracker::new(servo, Method::Rule2, start).unwrap();
        let report = tracker
            .track(pictures.iter().map(Some), 1, |_| ControlFlow::Continue(()))
            .unwrap();
        assert!(!report.lost);
        let worst_m = report
            .frames
            .iter()
            .map(|f| f.outcome.world_from_camera.distance_to(&truth[f.frame]).0)
            .fold(0.0, f64::max);
        let iterations: usize = report
            .frames
            .iter()
            .map(|f| f.outcome.iterations.iter().sum::<usize>())
            .sum();
        (worst_m, iterations)
    };
    let (tracker_m, tracker_iterations) = track(Tracker::default_config());
    let (localizer_m, localizer_iterations) = track(Localizer::default().config);
    eprintln!(
        "tracker: {tracker_m:.4} m, {tracker_iterations} iterations; \
         localiser: {localizer_m:.4} m, {localizer_iterations} iterations"
    );
    assert!(tracker_m < 0.01, "{tracker_m} m");
    assert!(
        tracker_m <= localizer_m + 0.002,
        "{tracker_m} against {localizer_m} m"
    );
    assert!(
        4 * tracker_iterations <= 3 * localizer_iterations,
        "{tracker_iterations} against {localizer_iterations} iterations"
    );
}
