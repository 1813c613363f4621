//! Projection, unprojection, validity, the pinhole special case, the fixture camera
//! and the real Mei calibration.

use crate::common::*;
use proptest::prelude::*;
use ucm::{Camera, Distortion, Intrinsics, OutOfView, ValidRegion};

proptest! {
    /// unproject ∘ project is the identity on the unit sphere, for every valid point.
    #[test]
    fn unproject_of_project_is_the_ray(
        camera in prop_oneof![camera_strategy(false), camera_strategy(true)],
        seed in point_strategy(1.0),
    ) {
        let xi = camera.intrinsics().xi;
        // Rescale the angle to the camera's domain.
        let rho = (seed[0] * seed[0] + seed[1] * seed[1] + seed[2] * seed[2]).sqrt();
        let theta = (seed[2] / rho).acos() / 1.0 * max_off_axis(xi);
        let phi = seed[1].atan2(seed[0]);
        let p = [rho * theta.sin() * phi.cos(), rho * theta.sin() * phi.sin(), rho * theta.cos()];
        // Beyond the fold of a random distortion polynomial there is no projection.
        prop_assume!(camera.project_unbounded(p).is_ok());
        let pixel = camera.project_unbounded(p).unwrap();
        let ray = camera.unproject(pixel).unwrap();
        for k in 0..3 {
            prop_assert!((ray[k] - p[k] / rho).abs() < 1e-9, "{ray:?} vs {p:?}/{rho}");
        }
    }

    /// project ∘ unproject is the identity on pixels of the image.
    #[test]
    fn project_of_unproject_is_the_pixel(
        camera in camera_strategy(false),
        u in 0.0..639.0f64,
        v in 0.0..479.0f64,
        range in 0.5..40.0f64,
    ) {
        let Ok(ray) = camera.unproject([u, v]) else {
            // Only possible beyond the ξ > 1 domain.
            prop_assert!(camera.intrinsics().xi > 1.0);
            return Ok(());
        };
        let back = camera.project([ray[0] * range, ray[1] * range, ray[2] * range]).unwrap();
        prop_assert!((back[0] - u).abs() < 1e-8 && (back[1] - v).abs() < 1e-8, "{back:?} vs {u} {v}");
    }

    /// The same with Mei's distortion (iterative undistortion), on pixels where the
    /// distortion is invertible.
    #[test]
    fn project_of_unproject_with_distortion(
        camera in camera_strategy(true),
        u in 0.0..639.0f64,
        v in 0.0..479.0f64,
    ) {
        if let Ok(ray) = camera.unproject([u, v]) {
            let back = camera.project(ray).unwrap();
            prop_assert!((back[0] - u).abs() < 1e-7 && (back[1] - v).abs() < 1e-7, "{back:?} vs {u} {v}");
        }
    }

    /// With ξ = 0 the model is the pinhole.
    #[test]
    fn xi_zero_is_the_pinhole(p in point_strategy(1.2), au in 100.0..500.0f64, av in 100.0..500.0f64) {
        let intrinsics = Intrinsics { alpha_u: au, alpha_v: av, u0: 320.0, v0: 240.0, xi: 0.0, skew: 0.0 };
        let camera = Camera::new(intrinsics, None, 640, 480, ValidRegion::Full).unwrap();
        let [u, v] = camera.project_unbounded(p).unwrap();
        prop_assert!((u - (au * p[0] / p[2] + 320.0)).abs() < 1e-9);
        prop_assert!((v - (av * p[1] / p[2] + 240.0)).abs() < 1e-9);
    }
}

#[test]
fn out_of_view_reasons() {
    let para = Camera::new(
        Intrinsics {
            alpha_u: 100.0,
            alpha_v: 100.0,
            u0: 320.0,
            v0: 240.0,
            xi: 0.9,
            skew: 0.0,
        },
        None,
        640,
        480,
        ValidRegion::Annulus(ucm::Annulus {
            center_px: [320.0, 240.0],
            inner_radius_px: 10.0,
            outer_radius_px: 200.0,
        }),
    )
    .unwrap();
    // ξ = 0.9 sees down to Z/ρ > −0.9: straight behind is not seen.
    assert_eq!(
        para.project([0.0, 0.0, -1.0]),
        Err(OutOfView::BehindViewpoint)
    );
    assert_eq!(
        para.project([0.0, 0.0, 0.0]),
        Err(OutOfView::BehindViewpoint)
    );
    assert_eq!(
        para.project([f64::NAN, 0.0, 1.0]),
        Err(OutOfView::BehindViewpoint)
    );
    // On the axis: the centre of the annulus, masked (the robot).
    assert_eq!(para.project([0.0, 0.0, 2.0]), Err(OutOfView::OutsideRegion));
    // Far off the axis: out of the image.
    assert_eq!(para.project([0.0, 1.0, -0.7]), Err(OutOfView::OutsideImage));
    assert!(para.project([1.0, 0.0, 0.2]).is_ok());

    // ξ = 1.5: the projection is one-to-one only where ξ Z/ρ > −1.
    let wide = Camera::new(
        Intrinsics {
            alpha_u: 100.0,
            alpha_v: 100.0,
            u0: 320.0,
            v0: 240.0,
            xi: 1.5,
            skew: 0.0,
        },
        None,
        640,
        480,
        ValidRegion::Full,
    )
    .unwrap();
    assert_eq!(
        wide.project_unbounded([0.0, 1.0, -1.0]),
        Err(OutOfView::OutsideXiDomain)
    );
    assert!(wide.project_unbounded([0.0, 1.0, -0.6]).is_ok());
    // And a pixel beyond the fold has no lifting.
    assert_eq!(
        wide.unproject([320.0 + 100.0 * 1.0, 240.0]),
        Err(OutOfView::OutsideXiDomain)
    );
}

#[test]
fn fixture_camera_geometry() {
    let camera = fixture_320();
    let xi = camera.intrinsics().xi;
    assert!((0.8..=1.0).contains(&xi));
    let off_nadir = |theta_deg: f64| {
        let t = theta_deg.to_radians();
        camera.project([t.sin(), 0.0, t.cos()]).map(|_| ())
    };
    // The nadir is masked (the robot), the ground from ~50° off the nadir is seen, the
    // horizon is seen, up to ~120° (30° above the horizon), not beyond.
    assert_eq!(off_nadir(0.0), Err(OutOfView::OutsideRegion));
    assert_eq!(off_nadir(48.0), Err(OutOfView::OutsideRegion));
    assert!(off_nadir(52.0).is_ok());
    assert!(off_nadir(90.0).is_ok());
    assert!(off_nadir(118.0).is_ok());
    assert!(off_nadir(122.0).is_err());
    // Every azimuth of the annulus fits in the image.
    for k in 0..360 {
        let a = f64::from(k).to_radians();
        let t = 119.0f64.to_radians();
        assert!(
            camera
                .project([t.sin() * a.cos(), t.sin() * a.sin(), t.cos()])
                .is_ok(),
            "azimuth {k}"
        );
    }
    // The 640×480 benchmark camera is the same camera.
    let large = Camera::load_toml(root().join("fixtures/omni-640x480.toml")).unwrap();
    assert_eq!(large, camera.rescaled(2).unwrap());
    let p = [1.0f64, 2.0, 0.3];
    let a = camera.project(p).unwrap();
    let b = large.project(p).unwrap();
    assert!(((a[0] + 0.5) * 2.0 - 0.5 - b[0]).abs() < 1e-9);
}

/// Downsampling inverts rescaling, maps pixel centres to block centres and keeps a
/// masked pixel only where its whole block is valid.
#[test]
fn downsampled_camera_is_the_same_camera_at_lower_resolution() {
    let camera = fixture_320();
    let large = camera.rescaled(2).unwrap();
    let back = large.downsampled(2).unwrap();
    assert_eq!((back.width(), back.height()), (320, 240));
    let (a, b) = (camera.intrinsics(), back.intrinsics());
    for (x, y) in [
        (a.alpha_u, b.alpha_u),
        (a.u0, b.u0),
        (a.v0, b.v0),
        (a.xi, b.xi),
    ] {
        assert!((x - y).abs() < 1e-9, "{x} vs {y}");
    }
    let coarse = camera.downsampled(4).unwrap();
    assert_eq!((coarse.width(), coarse.height()), (80, 60));
    let p = [1.0f64, -2.0, 0.4];
    let fine = camera.project(p).unwrap();
    let small = coarse.project(p).unwrap();
    for i in 0..2 {
        assert!(((fine[i] + 0.5) / 4.0 - 0.5 - small[i]).abs() < 1e-9);
    }
    // An explicit mask: one invalid pixel invalidates its block only.
    let mut flags = vec![true; 320 * 240];
    flags[5 * 320 + 7] = false;
    let masked = camera
        .with_region(ValidRegion::Mask(ucm::Mask::new(320, 240, flags).unwrap()))
        .unwrap();
    let half = masked.downsampled(2).unwrap();
    assert_eq!(half.valid_pixel_count(), 160 * 120 - 1);
    assert!(!half.valid_pixels()[2 * 160 + 3]);
    assert!(matches!(
        camera.downsampled(0),
        Err(ucm::UcmError::EmptyImage { .. })
    ));
    assert!(camera.downsampled(400).is_err());
    // Sizes beyond MAX_PIXELS, or that overflow, are errors before any allocation.
    assert!(matches!(
        camera.rescaled(1 << 20),
        Err(ucm::UcmError::TooManyPixels { .. })
    ));
    assert!(matches!(
        camera.rescaled(30),
        Err(ucm::UcmError::TooManyPixels { .. })
    ));
    assert!(matches!(
        Camera::new(
            *camera.intrinsics(),
            None,
            100_000,
            100_000,
            ValidRegion::Full
        ),
        Err(ucm::UcmError::TooManyPixels { .. })
    ));
}

/// The real Mei calibration: ξ ≈ 1.52, distortion and skew.
#[test]
fn mei_calibration_loads_and_projects_inside_its_crop() {
    let Some(data) = data_dir() else { return };
    let path = data.join("catadioptric/omniunwarp-mei.yaml");
    let camera = Camera::load_mei_yaml(&path, 1230, 1000, ValidRegion::Full).unwrap();
    let i = camera.intrinsics();
    assert!((i.xi - 1.518_101_310_566_618_8).abs() < 1e-12);
    assert!(
        (i.alpha_u - 471.350290197278).abs() < 1e-9 && (i.skew - 0.9326437725584913).abs() < 1e-12
    );
    let d = camera.distortion().unwrap();
    assert!((d.k2 - 0.671_518_551_772_977_5).abs() < 1e-12);

    // The mirror images directions up to ~120° off the optical axis (a disc of radius
    // ≈ 475 px in the picture); every one of them lands inside the 1230×1000 crop, and
    // round-trips through the iterative undistortion.
    let mut max_radius: f64 = 0.0;
    for k in 0..=120 {
        for a in 0..72 {
            let t = f64::from(k).to_radians();
            let az = f64::from(a * 5).to_radians();
            let p = [t.sin() * az.cos(), t.sin() * az.sin(), t.cos()];
            let pixel = camera
                .project(p)
                .unwrap_or_else(|e| panic!("{k}° az {a}: {e:?}"));
            max_radius = max_radius.max((pixel[0] - i.u0).hypot(pixel[1] - i.v0));
            let ray = camera
                .unproject(pixel)
                .unwrap_or_else(|e| panic!("{pixel:?}: {e:?}"));
            assert!((ray[0] - p[0]).abs() + (ray[1] - p[1]).abs() + (ray[2] - p[2]).abs() < 1e-8);
        }
    }
    assert!(
        (440.0..520.0).contains(&max_radius),
        "rim radius {max_radius}"
    );
    // Beyond the mirror's rim, the ξ > 1 domain extends to acos(−1/ξ) ≈ 131.2°, where the
    // distortion polynomial is extrapolated and the projection leaves the crop.
    let t = 131.0f64.to_radians();
    assert_eq!(
        camera.project([0.0, -t.sin(), t.cos()]),
        Err(OutOfView::OutsideImage)
    );
    assert_eq!(
        camera.project([0.0, 0.0, -1.0]),
        Err(OutOfView::OutsideXiDomain)
    );
}

/// A distortion whose radial polynomial bends strongly before its fold (k2 > 0, k3 < 0):
/// full Newton steps from the distorted point cycle between two radii there (the lift
/// failed with `DistortionFold`); steps that lower the residual reach the point. Every
/// direction projected on the optical axis's side of the fold lifts back.
#[test]
fn pixels_where_the_distortion_bends_lift_back() {
    let camera = Camera::new(
        Intrinsics {
            alpha_u: 100.0,
            alpha_v: 100.0,
            u0: 250.0,
            v0: 180.0,
            xi: 0.835_824_859_284_494_9,
            skew: 0.0,
        },
        Some(Distortion {
            k1: -0.021_923_383_860_871_472,
            k2: 0.044_202_131_262_805_484,
            p1: 0.0,
            p2: 0.001_141_598_747_060_272_1,
            k3: -0.004_192_270_484_036_987,
        }),
        640,
        480,
        ValidRegion::Full,
    )
    .unwrap();
    let mut lifted = 0;
    for k in 0..=130 {
        for a in 0..36 {
            let (t, az) = (f64::from(k).to_radians(), f64::from(a * 10).to_radians());
            let p = [t.sin() * az.cos(), t.sin() * az.sin(), t.cos()];
            let Ok(pixel) = camera.project_unbounded(p) else {
                continue;
            };
            let ray = camera
                .unproject(pixel)
                .unwrap_or_else(|e| panic!("{k}° az {}: {pixel:?}: {e:?}", a * 10));
            let err = (ray[0] - p[0]).abs() + (ray[1] - p[1]).abs() + (ray[2] - p[2]).abs();
            assert!(err < 1e-8, "{k}° az {}: {err:e}", a * 10);
            lifted += 1;
        }
    }
    // Up to about 112° off the axis (the point of the failure) at least.
    assert!(lifted >= 36 * 112, "{lifted} directions");
}

#[test]
fn batch_projection_matches_single() {
    let camera = fixture_320();
    let points: Vec<[f32; 3]> = (0..1000)
        .map(|k| {
            let a = k as f32 * 0.37;
            let t = 0.3 + (k % 20) as f32 * 0.1;
            [
                t.sin() * a.cos() * 5.0,
                t.sin() * a.sin() * 5.0,
                t.cos() * 5.0,
            ]
        })
        .collect();
    let mut out = vec![Err(OutOfView::OutsideImage); points.len()];
    camera.project_batch(&points, &mut out).unwrap();
    for (p, o) in points.iter().zip(&out) {
        assert_eq!(*o, camera.project(*p));
    }
    assert!(out.iter().any(|o| o.is_ok()) && out.iter().any(|o| o.is_err()));
    let mut short = vec![Err(OutOfView::OutsideImage); 3];
    assert!(camera.project_batch(&points, &mut short).is_err());
}

/// The plumb-bob calibration of TUM RGB-D's "freiburg1" Kinect (k3 = 1.16, large at the
/// corners where k1 r² + k2 r⁴ + k3 r⁶ nearly cancel): every pixel of its 640×480
/// picture is lifted and projected back to itself; without k3 the corners fold.
#[test]
fn a_third_radial_coefficient_lifts_and_projects_every_pixel() {
    let intrinsics = Intrinsics {
        alpha_u: 517.3,
        alpha_v: 516.5,
        u0: 318.6,
        v0: 255.3,
        xi: 0.0,
        skew: 0.0,
    };
    let distortion = Distortion {
        k1: 0.2624,
        k2: -0.9531,
        p1: -0.0054,
        p2: 0.0026,
        k3: 1.1633,
    };
    let camera = Camera::new(intrinsics, Some(distortion), 640, 480, ValidRegion::Full).unwrap();
    let without_k3 = Camera::new(
        intrinsics,
        Some(Distortion {
            k3: 0.0,
            ..distortion
        }),
        640,
        480,
        ValidRegion::Full,
    )
    .unwrap();
    for v in (0..480).step_by(7) {
        for u in (0..640).step_by(7) {
            let pixel = [f64::from(u), f64::from(v)];
            let ray = camera
                .unproject(pixel)
                .unwrap_or_else(|e| panic!("{pixel:?}: {e:?}"));
            let back = camera.project(ray).unwrap();
            assert!(
                (back[0] - pixel[0]).abs() < 1e-6 && (back[1] - pixel[1]).abs() < 1e-6,
                "{pixel:?} -> {back:?}"
            );
        }
    }
    // Without k3 the corners' rays lie beyond the fold of k1 and k2 alone, and a pixel
    // halfway to the corner moves by more than half a pixel.
    let corner = camera.unproject([0.0, 0.0]).unwrap();
    assert_eq!(without_k3.project(corner), Err(OutOfView::DistortionFold));
    let halfway = camera.unproject([160.0, 128.0]).unwrap();
    let moved: [f64; 2] = without_k3.project(halfway).unwrap();
    assert!(
        (moved[0] - 160.0).hypot(moved[1] - 128.0) > 0.5,
        "{moved:?}"
    );
}

proptest! {
    /// The batch projection of transformed points gives `project_unbounded`'s bits, NaN
    /// where it has none: points anywhere (behind the camera, at its centre, NaN), with
    /// and without lens distortion, ξ on both sides of 1, a block's tail.
    #[test]
    fn the_batch_projection_is_project_unbounded_bit_for_bit(
        camera in prop_oneof![camera_strategy(false), camera_strategy(true)],
        points in prop::collection::vec(prop::array::uniform3(-20.0..20.0f32), 0..150),
        specials in prop::collection::vec(0usize..150, 0..4),
        rotation in prop::array::uniform3(-3.0..3.0f32),
        translation in prop::array::uniform3(-2.0..2.0f32),
    ) {
        let mut points = points;
        for (k, &at) in specials.iter().enumerate() {
            if let Some(p) = points.get_mut(at) {
                *p = [[f32::NAN, 0.0, 1.0], [0.0; 3], [0.0, 0.0, -1.0], [f32::INFINITY, 0.0, 1.0]][k];
            }
        }
        let rotation = glam::Mat3::from_quat(glam::Quat::from_scaled_axis(glam::Vec3::from_array(rotation)));
        let translation = glam::Vec3::from_array(translation);
        // The transform, and the identity (so that the special points reach the camera
        // as they are: at its centre, behind it), with pixels to spare.
        for (rotation, translation) in [(rotation, translation), (glam::Mat3::IDENTITY, glam::Vec3::ZERO)] {
            let mut pixels = vec![[7.0f32; 2]; points.len() + 3];
            camera.project_transformed_unbounded(&rotation, translation, &points, &mut pixels);
            for (p, pixel) in points.iter().zip(&pixels) {
                let q = rotation * glam::Vec3::from_array(*p) + translation;
                match camera.project_unbounded(q.to_array()) {
                    Ok(expected) => prop_assert_eq!(
                        pixel.map(f32::to_bits), expected.map(f32::to_bits), "{:?}", p
                    ),
                    Err(_) => prop_assert!(pixel[0].is_nan() && pixel[1].is_nan(), "{:?}: {:?}", p, pixel),
                }
            }
            // Only as many pixels as points are written; fewer pixels, fewer points.
            prop_assert!(pixels[points.len()..].iter().all(|&p| p == [7.0; 2]));
            let mut fewer = vec![[7.0f32; 2]; points.len() / 2];
            camera.project_transformed_unbounded(&rotation, translation, &points, &mut fewer);
            prop_assert!(fewer.iter().zip(&pixels).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)));
        }
    }
}
