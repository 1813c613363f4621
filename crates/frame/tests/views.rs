//! A picture on a support (`Restricted`), observed flags, and a picture resampled to
//! another camera at the same pose.

use frame::{AnyImage, Frame, Image, PixelStatus, Restricted, seen_through};
use proptest::prelude::*;
use ucm::{Camera, Intrinsics, ValidRegion};

fn pinhole() -> Camera {
    let intrinsics = Intrinsics {
        alpha_u: 80.0,
        alpha_v: 80.0,
        u0: 39.5,
        v0: 29.5,
        xi: 0.0,
        skew: 0.0,
    };
    Camera::new(intrinsics, None, 80, 60, ValidRegion::Full).unwrap()
}

fn catadioptric() -> Camera {
    let intrinsics = Intrinsics {
        alpha_u: 152.0,
        alpha_v: 152.0,
        u0: 39.5,
        v0: 29.5,
        xi: 0.9,
        skew: 0.0,
    };
    Camera::new(intrinsics, None, 80, 60, ValidRegion::Full).unwrap()
}

/// A smooth picture of the directions: what any central camera at the origin sees.
fn sky(direction: [f64; 3]) -> f32 {
    let n = (direction[0].powi(2) + direction[1].powi(2) + direction[2].powi(2)).sqrt();
    let [x, y, z] = direction.map(|c| c / n);
    (0.5 + 0.3 * (4.0 * x).sin() * (3.0 * y).cos() + 0.1 * z) as f32
}

fn picture_of(camera: &Camera) -> Image {
    let w = camera.width() as usize;
    let intensity = (0..camera.pixel_count())
        .map(|k| sky(camera.unproject([(k % w) as f64, (k / w) as f64]).unwrap()))
        .collect();
    Image::from_parts(
        camera.width(),
        camera.height(),
        intensity,
        camera.valid_pixels().to_vec(),
    )
    .unwrap()
}

#[test]
fn a_pinhole_picture_resampled_to_a_catadioptric_camera_is_what_that_camera_sees() {
    let (from, to) = (pinhole(), catadioptric());
    let resampled = picture_of(&from).resampled(&from, &to).unwrap();
    let truth = picture_of(&to);
    let w = to.width() as usize;
    let mut valid = 0;
    for k in 0..to.pixel_count() {
        let ray = to.unproject([(k % w) as f64, (k / w) as f64]).unwrap();
        let inside = from.project(ray).is_ok();
        if resampled.valid[k] {
            valid += 1;
            assert!(inside, "pixel {k} valid outside the pinhole's field");
            let error = (resampled.intensity[k] - truth.intensity[k]).abs();
            assert!(error < 0.01, "pixel {k}: {error}");
        } else {
            assert_eq!(resampled.intensity[k], 0.0);
        }
    }
    // The pinhole's field covers the middle of the catadioptric picture.
    assert!(valid > to.pixel_count() / 4, "{valid} valid pixels");
    // The camera seen through the pinhole is valid where the picture may be.
    let seen = seen_through(&to, &from).unwrap();
    for k in 0..to.pixel_count() {
        if resampled.valid[k] {
            assert!(seen.valid_pixels()[k]);
        }
    }
    let border = seen.valid_pixel_count() - valid;
    assert!(
        border < 2 * (80 + 60),
        "{border} pixels of the seen region left invalid"
    );
    // The wrong size is an error.
    assert!(picture_of(&to).resampled(&from, &to).is_ok());
    let small = Image::new(10, 10);
    assert!(small.resampled(&from, &to).is_err());
}

#[test]
fn invalid_pixels_of_the_source_stay_invalid() {
    let (from, to) = (pinhole(), catadioptric());
    let mut picture = picture_of(&from);
    // A hole in the middle of the pinhole picture.
    for y in 25..35 {
        for x in 35..45 {
            picture.valid[y * 80 + x] = false;
        }
    }
    let resampled = picture.resampled(&from, &to).unwrap();
    assert!(!resampled.valid[30 * 80 + 40]);
    assert!(resampled.valid[30 * 80 + 20]);
}

proptest! {
    /// A restricted view observes exactly the picture's observed pixels on the
    /// support, reads 0 elsewhere and keeps the frame's inverse ranges there.
    #[test]
    fn restricted_views_observe_the_support(seed in 0u64..1000) {
        let (w, h) = (13u32, 7u32);
        let n = (w * h) as usize;
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut next = || { state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); state >> 33 };
        let mut frame = Frame::new(w, h);
        for k in 0..n {
            frame.status[k] = match next() % 3 { 0 => PixelStatus::Hit, 1 => PixelStatus::Sky, _ => PixelStatus::Masked };
            frame.intensity[k] = (next() % 100) as f32 / 100.0;
            frame.range_m[k] = 1.0 + (next() % 10) as f32;
        }
        let support: Vec<bool> = (0..n).map(|_| next() % 2 == 0).collect();
        let view = Restricted::new(&frame, &support).unwrap();
        let mut observed = vec![false; n];
        view.observed(0..n, &mut observed);
        let mut intensity = vec![0.0; n];
        view.observed_intensity(0..n, &mut intensity);
        let mut inverse = vec![0.0; n];
        view.inverse_range(&mut inverse).unwrap();
        let mut plain = vec![0.0; n];
        frame.inverse_range(&mut plain).unwrap();
        for k in 0..n {
            let expected = support[k] && frame.status[k] != PixelStatus::Masked;
            prop_assert_eq!(observed[k], expected);
            prop_assert_eq!(view.is_observed(k), expected);
            prop_assert_eq!(intensity[k], if expected { frame.intensity[k] } else { 0.0 });
            prop_assert_eq!(inverse[k], if support[k] { plain[k] } else { 0.0 });
        }
        // A support of another size is refused.
        prop_assert!(Restricted::new(&frame, &support[1..]).is_err());
    }
}
