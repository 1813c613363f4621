//! `L_G` (both forms) and `L_I` against the finite difference of the whole pipeline:
//! render the city at a pose, move the camera by exp(±ε v) along each axis, render,
//! transform, compare `(F(r⁺) − F(r⁻))/2ε` with `L v` over all samples.

use brightness::Brightness;
use pgm::{Pgm, PgmJacobian, PgmOptions};

use crate::pipeline_support::*;

const AXES: [&str; 6] = ["tx", "ty", "tz", "wx", "wy", "wz"];

fn unit(axis: usize) -> [f64; 6] {
    let mut v = [0.0; 6];
    v[axis] = 1.0;
    v
}

/// Steps of the finite differences: 2 cm, 0.4°. Smaller steps are dominated by the
/// discreteness of the rendering.
fn eps(axis: usize) -> f64 {
    if axis < 3 { 0.02 } else { 0.4f64.to_radians() }
}

fn lg_cosines(jacobian: PgmJacobian, lambda: f32) -> Vec<(f64, f64)> {
    let camera = crate::common::fixture();
    let pose = street_pose();
    let mut pgm = Pgm::new(&camera, PgmOptions::default()).unwrap();
    pgm.compute(&render(&camera, &pose), lambda, jacobian)
        .unwrap();
    let rows = pgm.interaction().to_vec();
    let weights = pgm.weights().to_vec();
    (0..6)
        .map(|axis| {
            let numeric = pipeline_difference(&camera, &pose, unit(axis), eps(axis), |frame| {
                pgm.transform(frame, lambda).unwrap().to_vec()
            });
            let keep: Vec<usize> = (0..rows.len()).filter(|&s| weights[s] > 0.0).collect();
            let analytic: Vec<f64> = keep.iter().map(|&s| f64::from(rows[s][axis])).collect();
            let numeric: Vec<f64> = keep.iter().map(|&s| numeric[s]).collect();
            compare(&analytic, &numeric)
        })
        .collect()
}

#[test]
fn convolved_lg_matches_the_pipeline() {
    let result = lg_cosines(PgmJacobian::Convolved, 15.0);
    for (axis, (cos, rel)) in result.iter().enumerate() {
        eprintln!(
            "Convolved λ=15 {}: cosine {cos:.3}, relative error {rel:.3}",
            AXES[axis]
        );
    }
    for (axis, (cos, _)) in result.iter().enumerate() {
        assert!(*cos > 0.85, "{}: cosine {cos}", AXES[axis]);
    }
}

#[test]
fn paper_lg_is_wrong_near_the_mask_edge() {
    let plain = lg_cosines(PgmJacobian::Paper { edge_margin: None }, 15.0);
    let margin = lg_cosines(
        PgmJacobian::Paper {
            edge_margin: Some(3.0),
        },
        15.0,
    );
    for axis in 0..6 {
        eprintln!(
            "Paper λ=15 {}: cosine {:.3} (all samples), {:.3} (beyond 3λ of the edge)",
            AXES[axis], plain[axis].0, margin[axis].0
        );
    }
    let mean = |v: &[(f64, f64)]| v.iter().map(|c| c.0).sum::<f64>() / 6.0;
    assert!(
        mean(&margin) > mean(&plain) + 0.1,
        "{} vs {}",
        mean(&margin),
        mean(&plain)
    );
    let convolved = lg_cosines(PgmJacobian::Convolved, 15.0);
    assert!(
        mean(&convolved) > mean(&plain) + 0.2,
        "{} vs {}",
        mean(&convolved),
        mean(&plain)
    );
}

#[test]
fn brightness_li_matches_the_pipeline() {
    let camera = crate::common::fixture();
    let pose = street_pose();
    let mut feature = Brightness::new(&camera);
    feature.compute(&render(&camera, &pose)).unwrap();
    let rows = feature.interaction().to_vec();
    let mut cosines = Vec::new();
    for axis in 0..6 {
        let numeric = pipeline_difference(&camera, &pose, unit(axis), eps(axis), |frame| {
            feature.compute(frame).unwrap();
            feature.values().to_vec()
        });
        let analytic: Vec<f64> = rows.iter().map(|r| f64::from(r[axis])).collect();
        let (cos, rel) = compare(&analytic, &numeric);
        eprintln!(
            "L_I {}: cosine {cos:.3}, relative error {rel:.3}",
            AXES[axis]
        );
        cosines.push(cos);
    }
    for (axis, cos) in cosines.iter().enumerate() {
        assert!(*cos > 0.3, "{}: cosine {cos}", AXES[axis]);
    }
}

/// Compared with a picture on their common support (`Support::Common`: the rendering's
/// hits), the difference of the two `G` changes as the camera moves both inside the
/// support and where its edge sweeps across the picture: `Pgm::compute_against`'s
/// `L_G` is the derivative of that difference, and the rows of the rendering alone
/// (its gradient inside the support, blind to the edge) are not.
#[test]
fn convolved_lg_against_a_picture_on_the_common_support_matches_the_pipeline() {
    use brightness::Against;
    use frame::{Image, PixelStatus, Restricted};
    let camera = crate::common::fixture();
    let pose = street_pose();
    // The picture: the street from 30 cm and 2° away.
    let picture = Image::from_frame(&render(
        &camera,
        &(pose * ucm::Isometry3::from_pose_vector([0.3, -0.2, 0.1, 0.0, 0.0, 0.035]).unwrap()),
    ));
    let observed = picture.valid.clone();
    let hits = |frame: &frame::Frame| -> Vec<bool> {
        frame
            .status
            .iter()
            .zip(&observed)
            .map(|(&s, &o)| o && s == PixelStatus::Hit)
            .collect()
    };
    let lambda = 15.0;
    let options = PgmOptions::default();
    let base = render(&camera, &pose);
    let support = hits(&base);
    assert!(
        support.iter().zip(&observed).any(|(&s, &o)| o && !s),
        "the street view has sky"
    );
    let mut pgm = Pgm::new(&camera, options).unwrap();
    let against = Against {
        intensity: &picture.intensity,
        observed: &observed,
    };
    let view = Restricted::new(&base, &support).unwrap();
    pgm.compute_against(&view, against, lambda, PgmJacobian::Convolved)
        .unwrap();
    let rows = pgm.interaction().to_vec();
    pgm.compute(&view, lambda, PgmJacobian::Convolved).unwrap();
    let blind = pgm.interaction().to_vec();
    let mut desired = Pgm::new(&camera, options).unwrap();
    let (mut with_edge, mut without) = (0.0, 0.0);
    for axis in 0..6 {
        let numeric = pipeline_difference(&camera, &pose, unit(axis), eps(axis), |frame| {
            let support = hits(frame);
            let g = pgm
                .transform(&Restricted::new(frame, &support).unwrap(), lambda)
                .unwrap()
                .to_vec();
            let g_star = desired
                .transform(&Restricted::new(&picture, &support).unwrap(), lambda)
                .unwrap();
            g.iter().zip(g_star).map(|(a, b)| a - b).collect()
        });
        let column =
            |rows: &[[f32; 6]]| -> Vec<f64> { rows.iter().map(|r| f64::from(r[axis])).collect() };
        let (cos, rel) = compare(&column(&rows), &numeric);
        let (cos_blind, _) = compare(&column(&blind), &numeric);
        eprintln!(
            "Convolved against the picture, λ=15 {}: cosine {cos:.3} (rendering alone {cos_blind:.3}), relative error {rel:.3}",
            AXES[axis]
        );
        assert!(cos > 0.85, "{}: cosine {cos}", AXES[axis]);
        with_edge += cos;
        without += cos_blind;
    }
    assert!(with_edge > without + 0.1, "{with_edge} vs {without}");
}
