//! The fusion on synthetic frames: geometry, colour, flying pixels, occlusion,
//! `min_frames`, bounded memory and bad input.

use glam::DVec3;
use rgbd::{DepthImage, FuseOptions, Fusion, RgbdError, Sensor};
use ucm::Isometry3;

use crate::scenes::{Scene, at, pinhole, texture};

const WALL: Scene = Scene {
    square_half_m: None,
};

#[test]
fn a_wall_seen_twice_becomes_points_on_the_wall_with_its_colours() {
    // Pixels 3.3 cm apart on the wall, voxels of 5 cm: each voxel gets a point of
    // each frame.
    let camera = pinhole(60.0);
    let options = FuseOptions {
        voxel_size_m: 0.05,
        min_frames: 2,
        ..FuseOptions::default()
    };
    let mut fusion = Fusion::new(Sensor::registered(camera.clone()), options).unwrap();
    for pose in [at(0.0, 0.0), at(0.05, 0.0)] {
        let stats = fusion
            .add(
                &WALL.depth(&camera, &pose),
                &WALL.color(&camera, &pose),
                &pose,
            )
            .unwrap();
        assert_eq!(stats.measured, 64 * 48);
        assert_eq!(stats.flying, 0);
        assert_eq!(stats.fused, 64 * 48);
    }
    let cloud = fusion.cloud().unwrap();
    // The wall seen twice is 2.08 × 1.57 m: about 1300 voxels.
    assert!(cloud.len() > 1000, "{} points", cloud.len());
    let colors = cloud.colors().unwrap();
    let mut worst = 0.0f64;
    for (i, (p, _)) in cloud.decoded().enumerate() {
        let p = cloud.origin() + p;
        assert!((p.z - 2.0).abs() < 1e-3, "point {p:?} off the wall");
        let expected = texture(p);
        for c in 0..3 {
            worst = worst.max((f64::from(colors[i][c]) - expected[c]).abs());
        }
    }
    // A voxel's colour is the mean of a smooth texture over its points, near the
    // texture at their mean (its curvature over 5 cm moves it by about 1 level).
    assert!(worst < 6.0, "colour off by {worst}");
}

/// A colour picture taken from elsewhere than the depth picture (a moving camera whose
/// pictures are not simultaneous): `add_at` colours the points from where the colour
/// picture was taken, `add` (the sensor's fixed transform) from the wrong place.
#[test]
fn a_colour_picture_taken_elsewhere_colours_the_points_from_its_own_pose() {
    let camera = pinhole(60.0);
    let options = FuseOptions {
        voxel_size_m: 0.05,
        min_frames: 1,
        ..FuseOptions::default()
    };
    let world_from_depth = at(0.0, 0.0);
    let world_from_color =
        at(0.12, -0.05) * Isometry3::from_pose_vector([0.0, 0.0, 0.0, 0.0, 0.03, 0.0]).unwrap();
    let depth = WALL.depth(&camera, &world_from_depth);
    let color = WALL.color(&camera, &world_from_color);
    let worst = |at_its_pose: bool| {
        let mut fusion = Fusion::new(Sensor::registered(camera.clone()), options).unwrap();
        let stats = if at_its_pose {
            fusion.add_at(&depth, &color, &world_from_depth, &world_from_color)
        } else {
            fusion.add(&depth, &color, &world_from_depth)
        }
        .unwrap();
        assert!(stats.fused > 2000, "{stats:?}");
        let cloud = fusion.cloud().unwrap();
        let colors = cloud.colors().unwrap();
        let mut worst = 0.0f64;
        for (i, (p, _)) in cloud.decoded().enumerate() {
            let expected = texture(cloud.origin() + p);
            for c in 0..3 {
                worst = worst.max((f64::from(colors[i][c]) - expected[c]).abs());
            }
        }
        worst
    };
    let (right, wrong) = (worst(true), worst(false));
    assert!(right < 6.0, "colour off by {right}");
    assert!(wrong > 4.0 * right, "{wrong} vs {right}");
}

#[test]
fn voxels_seen_by_too_few_frames_are_dropped() {
    let camera = pinhole(60.0);
    let options = |min_frames| FuseOptions {
        voxel_size_m: 0.02,
        min_frames,
        ..FuseOptions::default()
    };
    let poses = [at(0.0, 0.0), at(0.5, 0.0)];
    let fuse = |min_frames| {
        let mut fusion =
            Fusion::new(Sensor::registered(camera.clone()), options(min_frames)).unwrap();
        for pose in &poses {
            fusion
                .add(&WALL.depth(&camera, pose), &WALL.color(&camera, pose), pose)
                .unwrap();
        }
        fusion.cloud().unwrap()
    };
    let (one, two) = (fuse(1), fuse(2));
    assert!(two.len() < one.len());
    // The cameras 0.5 m apart see x in [-1.07, 1.07] and [-0.57, 1.57] on the wall:
    // twice only [-0.57, 1.07].
    let (lowest, highest) = two.bounds();
    assert!(lowest.x > -0.6 && highest.x < 1.1, "{lowest:?} {highest:?}");
    let (lowest, highest) = one.bounds();
    assert!(lowest.x < -1.0 && highest.x > 1.5, "{lowest:?} {highest:?}");
}

#[test]
fn flying_pixels_on_a_depth_step_are_dropped() {
    let camera = pinhole(60.0);
    // Left half 1 m away, right half 2 m: the two columns on the step mix both.
    let depth: Vec<f32> = (0..64 * 48)
        .map(|k| if k % 64 < 32 { 1.0 } else { 2.0 })
        .collect();
    let depth = DepthImage::from_metres(64, 48, depth).unwrap();
    let color = WALL.color(&camera, &at(0.0, 0.0));
    let run = |jump| {
        let options = FuseOptions {
            min_frames: 1,
            flying_pixel_jump: jump,
            ..FuseOptions::default()
        };
        let mut fusion = Fusion::new(Sensor::registered(camera.clone()), options).unwrap();
        fusion.add(&depth, &color, &Isometry3::IDENTITY).unwrap()
    };
    assert_eq!(run(Some(0.03)).flying, 2 * 48);
    assert_eq!(run(None).flying, 0);
}

#[test]
fn an_unregistered_colour_camera_colours_points_where_it_sees_them() {
    // The colour camera 4 cm to the right of the depth camera, with another focal.
    let depth_camera = pinhole(60.0);
    let color_camera = pinhole(50.0);
    let color_from_depth = Isometry3::from_translation(DVec3::new(-0.04, 0.0, 0.0));
    let sensor = Sensor {
        depth_camera: depth_camera.clone(),
        color_camera: color_camera.clone(),
        color_from_depth,
    };
    let world_from_depth = at(0.0, 0.0);
    let world_from_color = sensor.world_from_color(&world_from_depth);
    assert!((world_from_color.translation.x - 0.04).abs() < 1e-12);
    let options = FuseOptions {
        voxel_size_m: 0.01,
        min_frames: 1,
        ..FuseOptions::default()
    };
    let colour_error = |sensor: Sensor| {
        let mut fusion = Fusion::new(sensor, options).unwrap();
        fusion
            .add(
                &WALL.depth(&depth_camera, &world_from_depth),
                &WALL.color(&color_camera, &world_from_color),
                &world_from_depth,
            )
            .unwrap();
        let cloud = fusion.cloud().unwrap();
        let colors = cloud.colors().unwrap();
        let mut sum = 0.0;
        for (i, (p, _)) in cloud.decoded().enumerate() {
            let expected = texture(cloud.origin() + p);
            sum += (0..3)
                .map(|c| (f64::from(colors[i][c]) - expected[c]).abs())
                .sum::<f64>();
        }
        sum / (3 * cloud.len()) as f64
    };
    let right = colour_error(sensor.clone());
    // The same pictures taken as registered: every colour comes from the wrong place.
    let wrong = colour_error(Sensor {
        color_from_depth: Isometry3::IDENTITY,
        ..sensor
    });
    assert!(right < 4.0, "mean colour error {right}");
    assert!(
        wrong > 4.0 * right,
        "registered: {wrong}, unregistered: {right}"
    );
}

#[test]
fn points_hidden_from_the_colour_camera_take_no_colour() {
    // A black square 1 m away in front of the wall; the colour camera 10 cm to the
    // side sees behind it a part of the wall the depth camera does not, and does not
    // see a part the depth camera does.
    let scene = Scene {
        square_half_m: Some(0.2),
    };
    let camera = pinhole(60.0);
    let sensor = Sensor {
        depth_camera: camera.clone(),
        color_camera: camera.clone(),
        color_from_depth: Isometry3::from_translation(DVec3::new(-0.1, 0.0, 0.0)),
    };
    let world_from_depth = at(0.0, 0.0);
    let world_from_color = sensor.world_from_color(&world_from_depth);
    let options = FuseOptions {
        voxel_size_m: 0.01,
        min_frames: 1,
        flying_pixel_jump: None,
        ..FuseOptions::default()
    };
    let mut fusion = Fusion::new(sensor, options).unwrap();
    let stats = fusion
        .add(
            &scene.depth(&camera, &world_from_depth),
            &scene.color(&camera, &world_from_color),
            &world_from_depth,
        )
        .unwrap();
    assert!(stats.occluded > 20, "{stats:?}");
    let cloud = fusion.cloud().unwrap();
    let colors = cloud.colors().unwrap();
    // No wall point took the square's black (the texture never is below 28 in all
    // three channels).
    for (i, (p, _)) in cloud.decoded().enumerate() {
        let p = cloud.origin() + p;
        if p.z > 1.5 {
            assert!(
                colors[i].iter().any(|&c| c >= 28),
                "wall point {p:?} coloured {:?}",
                colors[i]
            );
        }
    }
    // Without the test, some would have.
    let options = FuseOptions {
        occlusion_tolerance: f32::MAX,
        ..options
    };
    let mut fusion = Fusion::new(fusion.sensor().clone(), options).unwrap();
    fusion
        .add(
            &scene.depth(&camera, &world_from_depth),
            &scene.color(&camera, &world_from_color),
            &world_from_depth,
        )
        .unwrap();
    let cloud = fusion.cloud().unwrap();
    let colors = cloud.colors().unwrap();
    let blackened = cloud
        .decoded()
        .enumerate()
        .filter(|(i, (p, _))| (cloud.origin() + *p).z > 1.5 && colors[*i].iter().all(|&c| c < 28))
        .count();
    assert!(
        blackened > 10,
        "{blackened} wall points blackened without the test"
    );
}

#[test]
fn the_voxel_limit_is_an_error_not_an_allocation() {
    let camera = pinhole(60.0);
    let options = FuseOptions {
        voxel_size_m: 0.001,
        max_voxels: 100,
        ..FuseOptions::default()
    };
    let mut fusion = Fusion::new(Sensor::registered(camera.clone()), options).unwrap();
    let pose = at(0.0, 0.0);
    let error = fusion
        .add(
            &WALL.depth(&camera, &pose),
            &WALL.color(&camera, &pose),
            &pose,
        )
        .unwrap_err();
    assert!(
        matches!(error, RgbdError::TooManyVoxels { limit: 100 }),
        "{error}"
    );
    assert!(fusion.voxel_count() <= 100);
}

#[test]
fn bad_frames_and_settings_are_typed_errors() {
    let camera = pinhole(60.0);
    let pose = at(0.0, 0.0);
    let mut fusion =
        Fusion::new(Sensor::registered(camera.clone()), FuseOptions::default()).unwrap();
    let depth = WALL.depth(&camera, &pose);
    let color = WALL.color(&camera, &pose);
    let small = DepthImage::from_metres(2, 2, vec![1.0; 4]).unwrap();
    assert!(matches!(
        fusion.add(&small, &color, &pose),
        Err(RgbdError::Size { .. })
    ));
    let nan = Isometry3::from_translation(DVec3::new(f64::NAN, 0.0, 0.0));
    assert!(matches!(
        fusion.add(&depth, &color, &nan),
        Err(RgbdError::Parameter { .. })
    ));
    let far = Isometry3::from_translation(DVec3::new(1e300, 0.0, 0.0));
    assert!(fusion.add(&depth, &color, &far).is_err());
    assert!(matches!(
        DepthImage::from_metres(3, 3, vec![1.0; 8]),
        Err(RgbdError::Length { .. })
    ));
    // Buffers a caller shortened (public fields): typed errors, not panics.
    let mut short_depth = depth.clone();
    short_depth.depth_m.truncate(7);
    assert!(matches!(
        fusion.add(&short_depth, &color, &pose),
        Err(RgbdError::Length {
            what: "depth_m",
            got: 7,
            ..
        })
    ));
    let mut short_color = color.clone();
    short_color.rgb.truncate(7);
    assert!(matches!(
        fusion.add(&depth, &short_color, &pose),
        Err(RgbdError::Length {
            what: "rgb",
            got: 7,
            ..
        })
    ));
    // Sampling an empty or shortened colour picture finds no colour (it indexed out of
    // bounds).
    assert_eq!(short_color.bilinear(1.0, 1.0), None);
    let empty = rgbd::ColorImage::from_rgb(0, 0, Vec::new()).unwrap();
    assert_eq!(empty.bilinear(0.0, 0.0), None);
    assert!(color.bilinear(1.0, 1.0).is_some());
    // Nothing fused: no cloud.
    assert!(matches!(fusion.cloud(), Err(RgbdError::Empty { .. })));
    for options in [
        FuseOptions {
            voxel_size_m: 0.0,
            ..FuseOptions::default()
        },
        FuseOptions {
            voxel_size_m: f64::NAN,
            ..FuseOptions::default()
        },
        FuseOptions {
            min_frames: 0,
            ..FuseOptions::default()
        },
        FuseOptions {
            depth_range_m: [2.0, 1.0],
            ..FuseOptions::default()
        },
        FuseOptions {
            flying_pixel_jump: Some(-1.0),
            ..FuseOptions::default()
        },
    ] {
        assert!(
            Fusion::new(Sensor::registered(camera.clone()), options).is_err(),
            "{options:?}"
        );
    }
    // Depths that are not depths are no measurement.
    let odd = DepthImage::from_metres(2, 1, vec![f32::NAN, -1.0]).unwrap();
    assert_eq!(odd.measured_count(), 0);
}
