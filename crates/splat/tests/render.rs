//! The renderer on scenes of known geometry, determinism, and the city.

use frame::{Frame, PixelStatus};
use glam::DVec3;
use splat::{PointCloud, RenderOptions, Renderer, SplatError};
use ucm::Isometry3;
use world::city::camera_looking_down;

use crate::common::*;

/// A square of side `size` m in the horizontal plane `z`, centred on `(cx, cy)`,
/// sampled every `step` m, of one intensity.
fn square(
    cx: f64,
    cy: f64,
    z: f64,
    size: f64,
    step: f64,
    intensity: f32,
) -> (Vec<DVec3>, Vec<f32>) {
    let n = (size / step) as i64;
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..n {
            p.push(DVec3::new(
                cx - size / 2.0 + (i as f64 + 0.5) * step,
                cy - size / 2.0 + (j as f64 + 0.5) * step,
                z,
            ));
        }
    }
    let k = p.len();
    (p, vec![intensity; k])
}

fn cloud_of(parts: &[(Vec<DVec3>, Vec<f32>)], spacing: f32) -> PointCloud {
    let positions: Vec<DVec3> = parts.iter().flat_map(|p| p.0.clone()).collect();
    let intensities: Vec<f32> = parts.iter().flat_map(|p| p.1.clone()).collect();
    PointCloud::from_points(
        DVec3::new(1000.0, 2000.0, 0.0),
        &positions,
        &intensities,
        None,
        Some(spacing),
    )
    .unwrap()
}

/// A ground plane with a bright marker, seen from above: the marker lands on the pixel
/// `ucm` projects it to, with its range; the plane is everywhere below the camera.
#[test]
fn plane_and_marker_land_where_the_model_projects_them() {
    let camera = fixture("omni-320x240.toml");
    let origin = DVec3::new(1000.0, 2000.0, 0.0);
    let ground = square(origin.x, origin.y, 0.0, 30.0, 0.03, 0.2);
    let marker_at = origin + DVec3::new(2.5, 1.0, 0.15);
    let marker = square(marker_at.x, marker_at.y, marker_at.z, 0.3, 0.01, 0.9);
    let cloud = cloud_of(&[ground, marker], 0.03);
    let world_from_camera = camera_looking_down(origin + DVec3::new(0.0, 0.0, 1.6), 0.3);
    let camera_from_world = world_from_camera.inverse();
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
    let mut frame = Frame::for_camera(&camera);
    renderer
        .render(&cloud, &camera_from_world, &mut frame)
        .unwrap();

    let p = camera_from_world.transform_point(marker_at).to_array();
    let pixel = camera.project(p).expect("marker visible");
    let k = camera.pixel_index(pixel).unwrap();
    assert_eq!(frame.status[k], PixelStatus::Hit);
    assert!(
        (frame.intensity[k] - 0.9).abs() < 0.02,
        "{}",
        frame.intensity[k]
    );
    let range = DVec3::from_array(p).length() as f32;
    assert!(
        (frame.range_m[k] - range).abs() < 0.03 * range,
        "{} vs {range}",
        frame.range_m[k]
    );

    // Every valid pixel looking below the horizon sees the plane (or the marker), at the
    // range of the ray's intersection with it.
    let w = camera.width() as usize;
    let mut checked = 0;
    for (k, _) in camera
        .valid_pixels()
        .iter()
        .enumerate()
        .filter(|(_, v)| **v)
    {
        let ray = camera.unproject([(k % w) as f64, (k / w) as f64]).unwrap();
        if ray[2] < 0.35 || frame.intensity[k] > 0.5 {
            continue; // near or above the horizon, beyond the plane's edge, or the marker
        }
        assert_eq!(frame.status[k], PixelStatus::Hit, "pixel {k}");
        // The splats covering a pixel come from up to a pixel and a half around it: at
        // grazing angles the plane's range varies that much across them.
        let (i, j) = ((k % w) as f64, (k / w) as f64);
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for (di, dj) in [(-1.5, 0.0), (1.5, 0.0), (0.0, -1.5), (0.0, 1.5), (0.0, 0.0)] {
            let r = camera.unproject([i + di, j + dj]).unwrap();
            let range = 1.6 / r[2];
            lo = lo.min(range);
            hi = hi.max(range);
        }
        let got = f64::from(frame.range_m[k]);
        assert!(
            got > lo * 0.99 && got < hi * 1.01,
            "pixel {k}: {got} not in [{lo}, {hi}]"
        );
        checked += 1;
    }
    assert!(checked > 2000, "{checked}");
    // Outside the annulus: masked, never zero-filled silently.
    assert_eq!(frame.status[0], PixelStatus::Masked);
    assert!(frame.range_m[0].is_nan());
}

/// Two overlapping squares at different heights: the nearer one hides the farther one
/// whatever the order of the points, and the z-buffer keeps its range.
#[test]
fn nearer_surface_occludes_farther_one() {
    let camera = fixture("omni-320x240.toml");
    let origin = DVec3::new(1000.0, 2000.0, 0.0);
    let far = square(origin.x + 3.0, origin.y, 0.0, 2.0, 0.02, 0.1);
    let near = square(origin.x + 3.0, origin.y, 0.8, 1.0, 0.02, 0.9);
    let camera_from_world = camera_looking_down(origin + DVec3::new(0.0, 0.0, 2.0), 0.0).inverse();
    for parts in [[far.clone(), near.clone()], [near.clone(), far.clone()]] {
        let cloud = cloud_of(&parts, 0.02);
        let mut renderer = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
        let mut frame = Frame::for_camera(&camera);
        renderer
            .render(&cloud, &camera_from_world, &mut frame)
            .unwrap();
        let centre = camera_from_world
            .transform_point(origin + DVec3::new(3.0, 0.0, 0.8))
            .to_array();
        let k = camera.pixel_index(camera.project(centre).unwrap()).unwrap();
        assert!(
            (frame.intensity[k] - 0.9).abs() < 1e-3,
            "{}",
            frame.intensity[k]
        );
        let expected = DVec3::from_array(centre).length() as f32;
        // The z-buffer keeps the nearest point of the splats covering the pixel: within
        // a pixel's footprint of the exact range.
        assert!(
            (frame.range_m[k] - expected).abs() < 0.03 * expected,
            "{} vs {expected}",
            frame.range_m[k]
        );
        // Beside the near square, the far one shows.
        let beside = camera_from_world
            .transform_point(origin + DVec3::new(3.0, 0.85, 0.0))
            .to_array();
        let k = camera.pixel_index(camera.project(beside).unwrap()).unwrap();
        assert!(
            (frame.intensity[k] - 0.1).abs() < 1e-3,
            "{}",
            frame.intensity[k]
        );
    }
}

fn render_city(
    camera: &ucm::Camera,
    world_from_camera: &Isometry3,
    options: RenderOptions,
) -> Frame {
    let mut renderer = Renderer::new(camera.clone(), options).unwrap();
    let mut frame = Frame::for_camera(camera);
    renderer
        .render(
            &default_city().cloud,
            &world_from_camera.inverse(),
            &mut frame,
        )
        .unwrap();
    frame
}

/// Same frame and statistics, bit for bit, on one thread (`parallel` off) and in pools
/// of 2, 3, 5 and 8 threads (each run on buffers of its own, merged), by a renderer
/// that drew in other pools and at other poses before (its threads' buffers kept, grown and cleared between
/// renderings), at street poses and a pose between the buildings' walls.
#[test]
fn rendering_is_deterministic_across_thread_counts() {
    let camera = fixture("omni-320x240.toml");
    let poses = [
        camera_looking_down(DVec3::new(-18.0, 1.0, 3.0), 0.2),
        camera_looking_down(DVec3::new(5.0, -1.0, 1.6), 1.0),
        camera_looking_down(DVec3::new(-31.0, 5.5, 1.2), 2.0),
    ];
    let cloud = &default_city().cloud;
    let serial = RenderOptions {
        parallel: false,
        ..RenderOptions::default()
    };
    let mut reused = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
    for pose in &poses {
        let mut expected = Frame::for_camera(&camera);
        let expected_stats = Renderer::new(camera.clone(), serial)
            .unwrap()
            .render(cloud, &pose.inverse(), &mut expected)
            .unwrap();
        assert!(expected.counts().0 > 5_000);
        for threads in [2, 3, 5, 8, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut frame = Frame::for_camera(&camera);
            let stats = pool.install(|| reused.render(cloud, &pose.inverse(), &mut frame).unwrap());
            assert!(frame.bitwise_eq(&expected), "{threads} threads, {pose:?}");
            assert_eq!(stats, expected_stats, "{threads} threads, {pose:?}");
        }
    }
}

/// A renderer that drew other poses before (its buffers cleared by each resolve, not
/// before each drawing) gives the fresh renderer's frame, bit for bit, on one thread
/// and on two.
#[test]
fn a_reused_renderer_draws_as_a_fresh_one() {
    let camera = fixture("omni-320x240.toml");
    let poses = [
        camera_looking_down(DVec3::new(-18.0, 1.0, 3.0), 0.2),
        camera_looking_down(DVec3::new(5.0, -1.0, 1.6), 1.0),
        camera_looking_down(DVec3::new(-18.0, 1.0, 3.0), 0.2),
    ];
    for parallel in [false, true] {
        let options = RenderOptions {
            parallel,
            ..RenderOptions::default()
        };
        let mut renderer = Renderer::new(camera.clone(), options).unwrap();
        let mut frame = Frame::for_camera(&camera);
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| {
                for pose in &poses {
                    let cloud = &default_city().cloud;
                    renderer.render(cloud, &pose.inverse(), &mut frame).unwrap();
                    let fresh = render_city(&camera, pose, options);
                    assert!(fresh.counts().0 > 10_000);
                    assert!(frame.bitwise_eq(&fresh), "parallel {parallel}, {pose:?}");
                }
            });
    }
}

/// Masked pixels change nothing elsewhere: with square holes punched into the valid
/// region (away from its rims, so that the field of view and the pixel box stay the
/// same), every pixel that stays valid is drawn bit for bit as without the holes
/// (hole filling off: its rule differs at the edge of the valid region), on one thread and on two, by a renderer that drew another pose
/// before (the renderer holds masked pixels at the nearest range, so that they hide
/// every cell, and its resolve restores them: a mistake there would leak into valid
/// pixels), and every pixel of a hole is masked.
#[test]
fn masked_pixels_change_nothing_elsewhere() {
    let camera = fixture("omni-320x240.toml");
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let valid = camera.valid_pixels();
    let inside = |u: usize, v: usize, r: usize| {
        u >= r
            && v >= r
            && u + r < w
            && v + r < h
            && (v - r..=v + r).all(|y| (u - r..=u + r).all(|x| valid[y * w + x]))
    };
    // 9 × 9 holes on a 31-pixel grid, wherever one fits with a margin of 4 valid pixels.
    let mut holed = valid.to_vec();
    let mut holes = 0;
    for v in (15..h).step_by(31) {
        for u in (15..w).step_by(31) {
            if inside(u, v, 8) {
                holes += 1;
                for y in v - 4..=v + 4 {
                    holed[y * w + u - 4..=y * w + u + 4].fill(false);
                }
            }
        }
    }
    assert!(holes >= 20, "{holes} holes");
    let holed_camera = ucm::Camera::new(
        *camera.intrinsics(),
        camera.distortion().copied(),
        w as u32,
        h as u32,
        ucm::ValidRegion::Mask(ucm::Mask::new(w as u32, h as u32, holed.clone()).unwrap()),
    )
    .unwrap();
    let pose = camera_looking_down(DVec3::new(-18.0, 1.0, 3.0), 0.2);
    for parallel in [false, true] {
        // Without hole filling, whose rule at the valid region's edge differs.
        let options = RenderOptions {
            parallel,
            fill_holes: false,
            ..RenderOptions::default()
        };
        let (whole, with_holes) = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| {
                // The holed camera's renderer draws another pose first: its
                // buffers are then the ones the resolve left.
                let mut renderer = Renderer::new(holed_camera.clone(), options).unwrap();
                let mut frame = Frame::for_camera(&holed_camera);
                let cloud = &default_city().cloud;
                for p in [camera_looking_down(DVec3::new(5.0, -1.0, 1.6), 1.0), pose] {
                    renderer.render(cloud, &p.inverse(), &mut frame).unwrap();
                }
                (render_city(&camera, &pose, options), frame)
            });
        let mut compared = 0;
        for v in 0..h {
            for u in 0..w {
                let k = v * w + u;
                if !holed[k] {
                    assert_eq!(with_holes.status[k], PixelStatus::Masked);
                    continue;
                }
                compared += 1;
                assert_eq!(whole.status[k], with_holes.status[k], "pixel ({u}, {v})");
                assert_eq!(
                    whole.intensity[k].to_bits(),
                    with_holes.intensity[k].to_bits(),
                    "pixel ({u}, {v})"
                );
                assert_eq!(
                    whole.range_m[k].to_bits(),
                    with_holes.range_m[k].to_bits(),
                    "pixel ({u}, {v})"
                );
            }
        }
        assert!(compared > 30_000, "{compared} pixels compared");
    }
}

/// From street level, no pixel looking below the horizon is a hole, at 640×480, with and
/// without level of detail.
#[test]
fn city_has_no_holes_below_the_horizon() {
    let camera = fixture("omni-640x480.toml");
    let w = camera.width() as usize;
    for (x, y, z, heading) in [
        (-20.0, 0.5, 3.0, 0.0),
        (15.0, -1.5, 1.6, 0.4),
        (0.5, 30.0, 2.2, 1.6),
    ] {
        let pose = camera_looking_down(DVec3::new(x, y, z), heading);
        for lod in [RenderOptions::default().lod_spacing_px, Some(0.5), None] {
            let frame = render_city(
                &camera,
                &pose,
                RenderOptions {
                    lod_spacing_px: lod,
                    ..RenderOptions::default()
                },
            );
            let mut holes = 0;
            let mut below = 0;
            for (k, _) in camera
                .valid_pixels()
                .iter()
                .enumerate()
                .filter(|(_, v)| **v)
            {
                let ray = camera.unproject([(k % w) as f64, (k / w) as f64]).unwrap();
                // Camera Z is down: below the horizon means a positive Z (with margin).
                if ray[2] > 0.1 {
                    below += 1;
                    if frame.status[k] != PixelStatus::Hit {
                        holes += 1;
                    }
                }
            }
            assert!(below > 20_000, "{below}");
            assert_eq!(
                holes, 0,
                "pose ({x}, {y}, {z}), lod {lod:?}: {holes} holes of {below}"
            );
        }
    }
}

#[test]
fn renderer_rejects_bad_input() {
    let camera = fixture("omni-320x240.toml");
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
    let cloud = cloud_of(&[square(0.0, 0.0, 0.0, 1.0, 0.1, 0.5)], 0.1);
    let mut wrong = Frame::new(10, 10);
    assert!(matches!(
        renderer.render(&cloud, &Isometry3::IDENTITY, &mut wrong),
        Err(SplatError::FrameSize { .. })
    ));
    // A frame whose public buffers were resized: refused, and the renderer is left as
    // it was (it then draws a fresh renderer's frame).
    let pose = Isometry3::from_pose_vector([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]).unwrap();
    let mut short = Frame::for_camera(&camera);
    short.status.pop();
    assert!(matches!(
        renderer.render(&cloud, &pose, &mut short),
        Err(SplatError::FrameBuffer { what: "status", .. })
    ));
    let mut frame = Frame::for_camera(&camera);
    renderer.render(&cloud, &pose, &mut frame).unwrap();
    let mut fresh = Frame::for_camera(&camera);
    Renderer::new(camera.clone(), RenderOptions::default())
        .unwrap()
        .render(&cloud, &pose, &mut fresh)
        .unwrap();
    assert!(frame.bitwise_eq(&fresh));
    let nan = Isometry3 {
        translation: DVec3::new(f64::NAN, 0.0, 0.0),
        ..Isometry3::IDENTITY
    };
    assert!(matches!(
        renderer.render(&cloud, &nan, &mut frame),
        Err(SplatError::NonFinitePose)
    ));
    assert!(
        Renderer::new(
            camera,
            RenderOptions {
                depth_band: -1.0,
                ..RenderOptions::default()
            }
        )
        .is_err()
    );
    // A camera wider than a splat's 16-bit column can address.
    let wide = ucm::Camera::new(
        ucm::Intrinsics {
            alpha_u: 100.0,
            alpha_v: 100.0,
            u0: 20_000.0,
            v0: 2.0,
            xi: 0.9,
            skew: 0.0,
        },
        None,
        40_000,
        4,
        ucm::ValidRegion::Full,
    )
    .unwrap();
    assert!(matches!(
        Renderer::new(wide, RenderOptions::default()),
        Err(SplatError::RegionTooLarge {
            columns: 40_000,
            rows: 4,
            max: 16_384
        })
    ));
    // Empty and non-finite clouds cannot be built.
    assert!(matches!(
        PointCloud::from_points(DVec3::ZERO, &[], &[], None, None),
        Err(SplatError::EmptyCloud)
    ));
    let nan_point = [DVec3::new(0.0, f64::NAN, 0.0)];
    assert!(matches!(
        PointCloud::from_points(DVec3::ZERO, &nan_point, &[0.5], None, None),
        Err(SplatError::NonFinitePoint { index: 0, .. })
    ));
    assert!(matches!(
        PointCloud::from_points(DVec3::ZERO, &[DVec3::ZERO], &[0.5, 0.5], None, None),
        Err(SplatError::AttributeLength { .. })
    ));
}

/// A frame downsampled by 2 averages the hits of each block, and follows the coarse
/// camera's mask.
#[test]
fn downsampled_frame_averages_blocks() {
    let camera = fixture("omni-320x240.toml");
    let coarse = camera.downsampled(2).unwrap();
    let city = default_city();
    let pose = camera_looking_down(DVec3::new(-20.0, 0.5, 3.0), 0.0);
    let mut frame = Frame::for_camera(&camera);
    Renderer::new(camera.clone(), RenderOptions::default())
        .unwrap()
        .render(&city.cloud, &pose.inverse(), &mut frame)
        .unwrap();
    let small = frame.downsampled(2, &coarse).unwrap();
    assert_eq!((small.width(), small.height()), (160, 120));
    let mut checked = 0;
    for y in 0..120usize {
        for x in 0..160usize {
            let i = y * 160 + x;
            let block = [
                2 * y * 320 + 2 * x,
                2 * y * 320 + 2 * x + 1,
                (2 * y + 1) * 320 + 2 * x,
                (2 * y + 1) * 320 + 2 * x + 1,
            ];
            if !coarse.valid_pixels()[i] {
                assert_eq!(small.status[i], PixelStatus::Masked);
                continue;
            }
            if block.iter().all(|&j| frame.status[j] == PixelStatus::Hit) {
                let mean = block.iter().map(|&j| frame.intensity[j]).sum::<f32>() / 4.0;
                assert_eq!(small.status[i], PixelStatus::Hit);
                assert!((small.intensity[i] - mean).abs() < 1e-6);
                checked += 1;
            }
        }
    }
    assert!(checked > 5000, "{checked} full blocks");
    // The wrong coarse camera is an error.
    assert!(matches!(
        frame.downsampled(4, &coarse),
        Err(frame::FrameError::Size { .. })
    ));
}

mod occlusion {
    use proptest::prelude::*;
    use ucm::{Camera, Intrinsics, ValidRegion};

    use super::*;

    /// A camera with random intrinsics (skew, unequal focal lengths, ξ on both sides
    /// of 1), the whole image valid.
    fn camera(alpha_u: f64, aspect: f64, skew: f64, xi: f64, shift: f64) -> Camera {
        Camera::new(
            Intrinsics {
                alpha_u,
                alpha_v: alpha_u * aspect,
                u0: 159.5 + shift,
                v0: 119.5 - shift,
                xi,
                skew,
            },
            None,
            320,
            240,
            ValidRegion::Full,
        )
        .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Occlusion culling skips only what cannot change the image: the frame is the
        /// same, bit for bit, with and without it, for random street poses (tilted,
        /// at any height) and random intrinsics.
        #[test]
        fn culling_changes_nothing_in_the_image(
            along in -55.0f64..55.0,
            across in -3.0f64..3.0,
            height in 0.8f64..8.0,
            heading in 0.0f64..std::f64::consts::TAU,
            tilt in prop::array::uniform3(-0.4f64..0.4),
            y_street in any::<bool>(),
            alpha_u in 30.0f64..90.0,
            aspect in 0.9f64..1.1,
            skew in -2.0f64..2.0,
            xi in 0.3f64..1.4,
            shift in -10.0f64..10.0,
        ) {
            let camera = camera(alpha_u, aspect, skew, xi, shift);
            let position = if y_street {
                DVec3::new(across, along, height)
            } else {
                DVec3::new(along, across, height)
            };
            let tilt = Isometry3::from_pose_vector([0.0, 0.0, 0.0, tilt[0], tilt[1], tilt[2]])
                .unwrap();
            let pose = camera_looking_down(position, heading) * tilt;
            let options = RenderOptions { parallel: false, ..RenderOptions::default() };
            let culled = render_city(&camera, &pose, options);
            let all = render_city(
                &camera,
                &pose,
                RenderOptions { occlusion_culling: false, ..options },
            );
            prop_assert!(culled.bitwise_eq(&all));
        }
    }

    /// In a street, most cells in the field of view are hidden by the facades, and the
    /// statistics say so.
    #[test]
    fn culling_skips_hidden_cells_in_a_street() {
        let camera = fixture("omni-320x240.toml");
        let pose = camera_looking_down(DVec3::new(-28.0, 2.5, 4.5), 0.0).inverse();
        let mut frame = Frame::for_camera(&camera);
        let mut stats = Vec::new();
        for occlusion_culling in [false, true] {
            let options = RenderOptions {
                occlusion_culling,
                ..RenderOptions::default()
            };
            let mut renderer = Renderer::new(camera.clone(), options).unwrap();
            stats.push(
                renderer
                    .render(&default_city().cloud, &pose, &mut frame)
                    .unwrap(),
            );
        }
        assert_eq!(stats[0].cells_occluded, 0);
        assert_eq!(
            stats[0].cells_drawn,
            stats[1].cells_drawn + stats[1].cells_occluded
        );
        assert!(
            stats[1].cells_occluded * 3 > stats[0].cells_drawn,
            "{stats:?}"
        );
        assert!(stats[1].points_drawn < stats[0].points_drawn);
        assert_eq!(stats[0].pixels_hit, stats[1].pixels_hit);
    }
}
