//! What the rendering and the picture are compared on (`vvs::Support`): a cloud that
//! lacks part of what the picture sees.

use glam::DVec3;
use splat::PointCloud;
use vvs::{Localizer, Method, Servo, Support, VvsConfig};

use crate::common::*;

/// The city without the upper floors (above 3 m) of the buildings on one side of the
/// street around the desired pose: what a scan that missed them would hold.
fn holed_city() -> PointCloud {
    let cloud = &city().cloud;
    let (positions, intensities): (Vec<DVec3>, Vec<f32>) = cloud
        .decoded()
        .map(|(p, i)| (cloud.origin() + p, i))
        .filter(|(w, _)| !(w.x > -30.0 && w.x < -10.0 && w.y > 1.0 && w.z > 3.0))
        .unzip();
    assert!(positions.len() + 100_000 < cloud.len());
    PointCloud::from_points(
        DVec3::ZERO,
        &positions,
        &intensities,
        None,
        Some(cloud.spacing_m()),
    )
    .unwrap()
}

/// The fixture camera, its picture of the whole city at the desired pose, and the city
/// with holes.
fn whole_picture_and_holed_cloud() -> (ucm::Camera, frame::Frame, PointCloud) {
    let camera = fixture();
    let desired = Servo::new(&city().cloud, &camera, VvsConfig::default())
        .unwrap()
        .render(&desired_pose())
        .unwrap();
    (camera, desired, holed_city())
}

/// A picture of the whole city, localised in a cloud that lacks part of what it sees:
/// with the paper's comparison the rendering's empty pixels (sky-grey where the picture
/// has facades) pull Rule2 a metre away; compared only where the rendering sees a
/// point, it converges.
#[test]
fn a_cloud_with_holes_is_compared_on_the_common_support() {
    let (camera, desired, holed) = whole_picture_and_holed_cloud();
    let start = offset([0.5, 0.3, 0.2, 0.03, -0.03, 0.05]);
    let error = |support| {
        let config = VvsConfig {
            support,
            ..VvsConfig::default()
        };
        let outcome = Servo::new(&holed, &camera, config)
            .unwrap()
            .run(Method::Rule2, &desired, start)
            .unwrap();
        let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose());
        eprintln!(
            "{support:?}: {:?}, {dt:.4} m, {:.3}°",
            outcome.stop,
            dr.to_degrees()
        );
        (dt, dr.to_degrees())
    };
    let (region_m, _) = error(Support::Region);
    let (common_m, common_deg) = error(Support::Common);
    assert!(
        common_m < 0.05 && common_deg < 0.5,
        "{common_m} m, {common_deg}°"
    );
    assert!(
        region_m > 0.3,
        "the paper's comparison ended {region_m} m away"
    );
}

/// The localiser's defaults compare on the common support, brightness normalised.
#[test]
fn the_localizer_compares_on_the_common_support() {
    let localizer = Localizer::default();
    assert_eq!(localizer.config.support, Support::Common);
    assert!(localizer.config.normalize);
    assert_eq!(localizer.method, Method::Rule2);
    assert_eq!(localizer.config.gain, 1.0);
    assert_eq!(localizer.config.levenberg_marquardt, Some(0.1));
    assert_eq!(localizer.config.lambda_schedule, [7.5, 3.0]);
    // The paper's settings stay the optimiser's defaults.
    assert_eq!(VvsConfig::default().support, Support::Region);
}

/// The global search with the localiser's settings (common support, its candidates
/// ranked by the correlation of the two PGMs over the compared pixels divided by the
/// fraction compared): from the corner of the paper's box, in the city with holes, it
/// finds the picture's pose.
#[test]
fn the_global_search_on_the_common_support_finds_the_pose_in_a_cloud_with_holes() {
    let (camera, desired, holed) = whole_picture_and_holed_cloud();
    let degree = std::f64::consts::PI / 180.0;
    let start = offset([8.0, 2.0, 1.5, 10.0 * degree, 10.0 * degree, 15.0 * degree]);
    let config = VvsConfig {
        keep_history: false,
        ..Localizer::default().config
    };
    let outcome = Servo::new(&holed, &camera, config)
        .unwrap()
        .localize_in_box(&desired, start, &vvs::PriorBox::default())
        .unwrap();
    let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose());
    assert!(
        dt < 0.05 && dr.to_degrees() < 0.5,
        "{dt} m, {}°",
        dr.to_degrees()
    );
}
