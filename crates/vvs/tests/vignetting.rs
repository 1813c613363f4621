//! The vignetting model: its columns against finite differences, and alignment of a
//! vignetted picture.

use frame::{Frame, Image};
use pgm::{Pgm, PgmOptions};
use ucm::Isometry3;
use vvs::vignetting::RadialVignetting;
use vvs::{Method, Servo, VvsConfig};
use world::Acquisition;

use crate::common::*;
use crate::pipeline_support::compare;

/// The PGM of the corrected rendering at `c`.
fn feature(pgm: &mut Pgm, model: &RadialVignetting, frame: &Frame, c: [f64; 2]) -> Vec<f32> {
    let mut corrected = frame.clone();
    model.apply(c, frame, &mut corrected);
    pgm.transform(&corrected, 15.0).unwrap().to_vec()
}

/// Each coefficient's column (the PGM of its derivative picture, through the
/// normalisation when the brightness is normalised) equals the finite difference of the
/// feature to 1e-3, with and without normalisation (ε = 0.02: the feature is linear in
/// the picture, and the normalisation's derivative is taken exactly).
#[test]
fn columns_match_finite_differences() {
    let camera = fixture();
    let mut servo = Servo::new(&city().cloud, &camera, VvsConfig::default()).unwrap();
    let frame = servo.render(&desired_pose()).unwrap();
    let model = RadialVignetting::new(&camera);
    let c = [-0.2, 0.05];
    for normalize in [false, true] {
        let options = PgmOptions {
            normalize,
            ..PgmOptions::default()
        };
        let mut pgm = Pgm::new(&camera, options).unwrap();
        let mut plain = Pgm::new(
            &camera,
            PgmOptions {
                normalize: false,
                ..PgmOptions::default()
            },
        )
        .unwrap();
        // The picture's normalisation at c.
        let _ = feature(&mut pgm, &model, &frame, c);
        let normalized = pgm.brightness().image().to_vec();
        let scale = normalize.then(|| (pgm.brightness().normalization_scale(), &normalized[..]));
        let samples = pgm.brightness().samples().to_vec();
        let observed = pgm.brightness().observed().to_vec();
        for k in 0..2 {
            let mut derivative = Image::new(camera.width(), camera.height());
            model.derivative(k, &frame, &samples, &observed, scale, &mut derivative);
            let analytic: Vec<f64> = plain
                .transform(&derivative, 15.0)
                .unwrap()
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            let eps = 2e-2;
            let mut up = c;
            up[k] += eps;
            let mut down = c;
            down[k] -= eps;
            let plus = feature(&mut pgm, &model, &frame, up);
            let minus = feature(&mut pgm, &model, &frame, down);
            let numeric: Vec<f64> = plus
                .iter()
                .zip(&minus)
                .map(|(a, b)| (f64::from(*a) - f64::from(*b)) / (2.0 * eps))
                .collect();
            let (cosine, relative) = compare(&analytic, &numeric);
            eprintln!(
                "normalize {normalize}, c{}: cosine {cosine:.5}, relative {relative:.2e}",
                k + 1
            );
            let bound = 1e-3;
            assert!(cosine > 0.999 && relative < bound, "{cosine} {relative}");
        }
    }
}

/// A picture vignetted by 30 % at the rim (the acquisition simulator, nothing else):
/// with the model, Rule2 recovers the pose to a few millimetres from 1 m away and the
/// coefficients to a few hundredths (the truth is c = (−0.3, 0) in this basis).
#[test]
fn estimates_the_vignetting_with_the_pose() {
    let camera = fixture();
    let config = VvsConfig {
        normalize: true,
        vignetting: true,
        keep_history: false,
        ..VvsConfig::default()
    };
    let mut servo = Servo::new(&city().cloud, &camera, config).unwrap();
    let rendered = servo.render(&desired_pose()).unwrap();
    let acquisition = Acquisition {
        gain_amplitude: 0.0,
        offset_amplitude: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        ..Acquisition::default()
    };
    let picture = acquisition.acquire(&rendered, &camera, 0, 0.0).unwrap();
    let start =
        desired_pose() * Isometry3::from_pose_vector([1.0, 0.3, 0.1, 0.0, 0.0, 0.05]).unwrap();
    let outcome = servo.run(Method::Rule2, &picture, start).unwrap();
    let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose());
    let c = outcome.vignetting.unwrap();
    eprintln!(
        "{:?}: {dt:.4} m, {:.3}°, c = {c:?}",
        outcome.stop,
        dr.to_degrees()
    );
    assert!(dt < 0.01 && dr.to_degrees() < 0.1, "{dt} m");
    assert!((c[0] + 0.3).abs() < 0.05 && c[1].abs() < 0.05, "{c:?}");
    // Off, the same start ends farther (the ramp pulls the wide PGM).
    let mut plain = Servo::new(
        &city().cloud,
        &camera,
        VvsConfig {
            normalize: true,
            keep_history: false,
            ..VvsConfig::default()
        },
    )
    .unwrap();
    let off = plain.run(Method::Rule2, &picture, start).unwrap();
    let (dt_off, _) = off.world_from_camera.distance_to(&desired_pose());
    eprintln!("without the model: {:?}: {dt_off:.4} m", off.stop);
    assert!(off.vignetting.is_none());
}
