//! Tests of the whole renderer, and the setups that the tests of its modules share.

use glam::DVec3;
use proptest::prelude::*;
use ucm::{Camera, Intrinsics, Isometry3, ValidRegion};

use frame::Frame;

use super::*;

/// A 320×240 camera without distortion, its principal point at the centre, and
/// rendering options with the given splats.
pub(super) fn test_setup(
    alpha_u: f32,
    aspect: f32,
    skew: f32,
    xi: f32,
    splat_scale: f32,
    max_radius: u32,
) -> (Camera, RenderOptions) {
    let camera = Camera::new(
        Intrinsics {
            alpha_u: f64::from(alpha_u),
            alpha_v: f64::from(alpha_u * aspect),
            u0: 159.5,
            v0: 119.5,
            xi: f64::from(xi),
            skew: f64::from(skew),
        },
        None,
        320,
        240,
        ValidRegion::Full,
    )
    .unwrap();
    let options = RenderOptions {
        splat_scale,
        max_splat_radius_px: max_radius,
        ..RenderOptions::default()
    };
    (camera, options)
}

/// 40 000 points in a 40 × 40 × 12 m box around the origin (none within 1 m of
/// it), random intensities.
fn scattered_cloud() -> PointCloud {
    let mut rng = crate::rng::SplitMix64::new(7);
    let mut positions = Vec::new();
    let mut intensities = Vec::new();
    while positions.len() < 40_000 {
        let p = DVec3::new(
            rng.unit() * 40.0 - 20.0,
            rng.unit() * 40.0 - 20.0,
            rng.unit() * 12.0 - 4.0,
        );
        if p.length() > 1.0 {
            positions.push(p);
            intensities.push(rng.unit() as f32);
        }
    }
    PointCloud::from_points(DVec3::ZERO, &positions, &intensities, None, Some(0.2)).unwrap()
}

/// A rendering that did not reach its resolve (its buffers left with stale keys
/// and sums, as a panic would leave them) is cleared by the next one, which then
/// draws a fresh renderer's frame bit for bit, on one thread and in a pool of three
/// (the other runs' buffers); and the test fails if it is not.
#[test]
fn a_rendering_left_unfinished_is_cleared_by_the_next() {
    let (camera, options) = test_setup(80.0, 1.0, 0.0, 0.9, 1.25, 8);
    let options = RenderOptions {
        parallel: false,
        ..options
    };
    let cloud = scattered_cloud();
    let pose = Isometry3::from_pose_vector([0.3, -0.2, 0.1, 0.05, -0.1, 0.2]).unwrap();
    let render = |renderer: &mut Renderer| {
        let mut frame = Frame::for_camera(&camera);
        renderer.render(&cloud, &pose, &mut frame).unwrap();
        frame
    };
    let fresh = render(&mut Renderer::new(camera.clone(), options).unwrap());
    assert!(fresh.counts().0 > 1_000);
    let poisoned = |cleared: bool| {
        let mut renderer = Renderer::new(camera.clone(), options).unwrap();
        render(&mut renderer);
        renderer.depth.fill(0);
        renderer.accum.fill([1, 1]);
        renderer.cleared = cleared;
        render(&mut renderer)
    };
    assert!(poisoned(false).bitwise_eq(&fresh));
    // The flag is what clears them: claimed clear, the stale buffers show.
    assert!(!poisoned(true).bitwise_eq(&fresh));
    // The same for the buffers of a parallel rendering's other runs.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap();
    let parallel = RenderOptions {
        parallel: true,
        ..options
    };
    let poisoned_runs = |cleared: bool| {
        pool.install(|| {
            let mut renderer = Renderer::new(camera.clone(), parallel).unwrap();
            render(&mut renderer);
            renderer.slots.poison(cleared);
            render(&mut renderer)
        })
    };
    assert!(poisoned_runs(false).bitwise_eq(&fresh));
    assert!(!poisoned_runs(true).bitwise_eq(&fresh));
}

/// The frame drawn into the box of the valid pixels equals, bit for bit, the one
/// drawn into the whole image (what the box leaves out lands on masked pixels), on
/// one thread and on several, with and without occlusion culling.
#[test]
fn the_valid_pixels_box_draws_the_frame_of_the_whole_image() {
    let camera = Camera::new(
        Intrinsics {
            alpha_u: 60.0,
            alpha_v: 60.0,
            u0: 159.5,
            v0: 119.5,
            xi: 0.9,
            skew: 0.0,
        },
        None,
        320,
        240,
        ValidRegion::Annulus(ucm::Annulus {
            center_px: [159.5, 119.5],
            inner_radius_px: 25.0,
            outer_radius_px: 100.0,
        }),
    )
    .unwrap();
    let region = Region::of(&camera);
    assert!(region.len() < 320 * 200, "{region:?}");
    // Points all around the camera, many hidden behind others, some seen only
    // outside the annulus.
    let cloud = scattered_cloud();
    let pose = Isometry3::from_pose_vector([0.3, -0.2, 0.1, 0.05, -0.1, 0.2]).unwrap();
    let whole = Region {
        u0: 0,
        v0: 0,
        width: 320,
        height: 240,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    for (parallel, occlusion_culling) in [(false, true), (true, true), (false, false)] {
        let options = RenderOptions {
            parallel,
            occlusion_culling,
            ..RenderOptions::default()
        };
        let [(full, full_hit), (cropped, hit)] = [whole, region].map(|r| {
            let mut renderer = Renderer::with_region(camera.clone(), options, r).unwrap();
            let mut frame = Frame::for_camera(&camera);
            let stats = pool.install(|| renderer.render(&cloud, &pose, &mut frame).unwrap());
            (frame, stats.pixels_hit)
        });
        assert!(hit > 5_000, "{hit} pixels hit");
        assert_eq!(hit, full_hit);
        assert_eq!(cropped.status, full.status);
        let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&cropped.intensity), bits(&full.intensity));
        assert_eq!(bits(&cropped.range_m), bits(&full.range_m));
    }
}

/// Regions of the 320×240 test image: the whole image or a box inside it.
pub(super) fn regions() -> impl Strategy<Value = Region> {
    (0usize..60, 0usize..40, 0usize..60, 0usize..40).prop_map(|(u0, v0, du, dv)| Region {
        u0,
        v0,
        width: 320 - u0 - du,
        height: 240 - v0 - dv,
    })
}

proptest! {
    /// The angles off the axis that culling uses are those of a scan of every valid
    /// pixel, bit for bit, for random intrinsics (the principal point anywhere, mirrors
    /// with ξ up to 2, whose fold some pixels pass), whole images and annuli.
    #[test]
    fn theta_range_is_the_scan_of_every_pixel(
        alpha_u in 20.0f64..400.0,
        aspect in 0.8f64..1.25,
        skew in -3.0f64..3.0,
        xi in 0.0f64..2.0,
        u0 in -20.0f64..60.0,
        v0 in -20.0f64..50.0,
        annulus in prop::option::of((0.0f64..10.0, 12.0f64..40.0)),
    ) {
        let region = match annulus {
            None => ValidRegion::Full,
            Some((inner, outer)) => ValidRegion::Annulus(ucm::Annulus {
                center_px: [u0, v0],
                inner_radius_px: inner,
                outer_radius_px: outer,
            }),
        };
        let Ok(camera) = Camera::new(
            Intrinsics { alpha_u, alpha_v: alpha_u * aspect, u0, v0, xi, skew },
            None,
            48,
            36,
            region,
        ) else {
            return Ok(());
        };
        let w = camera.width() as usize;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (k, _) in camera.valid_pixels().iter().enumerate().filter(|(_, v)| **v) {
            if let Ok(ray) = camera.unproject([(k % w) as f64, (k / w) as f64]) {
                let t = ray[2].clamp(-1.0, 1.0).acos();
                lo = lo.min(t);
                hi = hi.max(t);
            }
        }
        let (got_lo, got_hi) = theta_range(&camera);
        prop_assert_eq!(got_lo.to_bits(), lo.to_bits());
        prop_assert_eq!(got_hi.to_bits(), hi.to_bits());
    }
}
