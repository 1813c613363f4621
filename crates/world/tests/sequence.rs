//! The sequence generator: trajectory, shaking, acquired images.

use frame::{Frame, FrameError, Image, PixelStatus};
use test_support::workspace_root as root;
use ucm::Camera;
use world::{Acquisition, Shake, Trajectory, Turn, WorldError};

fn camera() -> Camera {
    Camera::load_toml(root().join("fixtures/omni-320x240.toml")).unwrap()
}

#[test]
fn trajectory_has_the_papers_length_the_kerb_and_the_shaking() {
    let t = Trajectory::default();
    let poses = t.poses();
    assert_eq!(poses.len(), 210);
    assert_eq!(poses, t.poses(), "deterministic");
    let (first, last) = (poses[0].translation, poses[209].translation);
    let travelled = ((last.x - first.x).powi(2) + (last.y - first.y).powi(2)).sqrt();
    assert!((travelled - 4.35).abs() < 0.12, "{travelled} m");
    // Walking speed: about 0.6 m/s.
    let speed = travelled / t.time_s(209);
    assert!((0.5..0.8).contains(&speed), "{speed} m/s");
    // The kerb: the camera ends about 12 cm lower (bumps aside).
    let drop = first.z - last.z;
    assert!((drop - 0.12).abs() < 0.05, "drop {drop} m");
    // Roll and pitch shake by degrees around the camera looking down.
    let tilts: Vec<f64> = poses
        .iter()
        .map(|p| {
            p.rotation_matrix()
                .col(2)
                .angle_between(glam::DVec3::NEG_Z)
                .to_degrees()
        })
        .collect();
    let max_tilt = tilts.iter().copied().fold(0.0, f64::max);
    assert!(max_tilt > 2.0 && max_tilt < 15.0, "max tilt {max_tilt}°");
    // Consecutive frames move by a few centimetres and a degree or so.
    for w in poses.windows(2) {
        let (dt, dr) = w[0].distance_to(&w[1]);
        assert!(
            dt < 0.1 && dr.to_degrees() < 5.0,
            "{dt} m, {}°",
            dr.to_degrees()
        );
    }
    for bad in [
        Trajectory {
            fps: 0.0,
            ..Trajectory::default()
        },
        Trajectory {
            frames: 100_000_000_000,
            ..Trajectory::default()
        },
        Trajectory {
            length_m: 1e12,
            ..Trajectory::default()
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}

/// A path with turns: straight where it should be, on its arcs at their radius, of
/// the length asked for, its heading continuous, and the camera's X axis along it;
/// turns that overlap, leave the path or are not finite are refused.
#[test]
fn turns_take_the_path_round_corners() {
    use std::f64::consts::FRAC_PI_2;
    let straight = Trajectory::default();
    // Without turns the centreline is the straight line of the heading.
    for d in [0.0, 1.0, 4.35] {
        let (p, h) = straight.centerline(d);
        let expected = glam::DVec3::from(straight.start) + glam::DVec3::new(0.0, d, 0.0);
        assert!((p - expected).length() < 1e-12 && (h - FRAC_PI_2).abs() < 1e-15);
    }
    // East 10 m, a left quarter turn of radius 3 m, north 10 m; then a right one.
    let turn = Turn {
        at_m: 10.0,
        angle_deg: 90.0,
        radius_m: 3.0,
    };
    let arc = turn.arc_length_m();
    assert!((arc - 3.0 * FRAC_PI_2).abs() < 1e-12);
    let t = Trajectory {
        frames: 600,
        start: [-10.0, -3.0, 0.0],
        heading_deg: 0.0,
        length_m: 20.0 + arc + 5.0 + arc,
        shake: Shake {
            kerb_at_m: None,
            ..Shake::default()
        },
        turns: vec![
            turn,
            Turn {
                at_m: 20.0 + arc,
                angle_deg: -90.0,
                radius_m: 3.0,
            },
        ],
        ..Trajectory::default()
    };
    t.validate().unwrap();
    let (p, h) = t.centerline(10.0);
    assert!((p - glam::DVec3::new(0.0, -3.0, 0.0)).length() < 1e-12 && h.abs() < 1e-15);
    // Half-way round the arc: 45°, on the circle about (0, 0).
    let (p, h) = t.centerline(10.0 + arc / 2.0);
    assert!((p.truncate().length() - 3.0).abs() < 1e-12, "{p}");
    assert!((h - FRAC_PI_2 / 2.0).abs() < 1e-12);
    let (p, h) = t.centerline(10.0 + arc);
    assert!(
        (p - glam::DVec3::new(3.0, 0.0, 0.0)).length() < 1e-12 && (h - FRAC_PI_2).abs() < 1e-12
    );
    let (p, _) = t.centerline(20.0 + arc);
    assert!(
        (p - glam::DVec3::new(3.0, 10.0, 0.0)).length() < 1e-12,
        "{p}"
    );
    let (p, h) = t.centerline(t.length_m);
    // Round the second corner (centre (6, 10)) to (6, 13), then 5 m east.
    assert!(
        (p - glam::DVec3::new(11.0, 13.0, 0.0)).length() < 1e-9,
        "{p}"
    );
    assert!(h.abs() < 1e-12, "heading back to east: {h}");
    // The length along the centreline is the path's, and the heading is continuous.
    let n = 20_000;
    let mut length = 0.0;
    for k in 0..n {
        let (a, ha) = t.centerline(t.length_m * k as f64 / n as f64);
        let (b, hb) = t.centerline(t.length_m * (k + 1) as f64 / n as f64);
        length += (b - a).length();
        assert!((hb - ha).abs() < 1e-3);
    }
    assert!((length - t.length_m).abs() < 1e-6, "{length}");
    // The camera's X axis follows the heading (shaking aside: a few degrees).
    let poses = t.poses();
    let mid_second_leg = poses[poses.len() * 2 / 3];
    let x_axis = mid_second_leg.rotation_matrix().col(0);
    assert!(
        x_axis.angle_between(glam::DVec3::Y) < 10f64.to_radians(),
        "{x_axis}"
    );
    for bad in [
        vec![Turn {
            radius_m: 0.0,
            ..turn
        }],
        vec![Turn {
            at_m: f64::NAN,
            ..turn
        }],
        vec![Turn {
            at_m: 100.0,
            ..turn
        }],
        vec![turn, Turn { at_m: 11.0, ..turn }],
        vec![Turn {
            angle_deg: 720.0,
            ..turn
        }],
    ] {
        let bad = Trajectory {
            turns: bad,
            ..t.clone()
        };
        assert!(bad.validate().is_err(), "{:?}", bad.turns);
    }
}

#[test]
fn acquisition_degrades_like_a_camera() {
    let camera = camera();
    let mut flat = Frame::for_camera(&camera);
    for i in 0..flat.intensity.len() {
        if camera.valid_pixels()[i] {
            flat.status[i] = PixelStatus::Hit;
            flat.intensity[i] = 0.5;
            flat.range_m[i] = 5.0;
        } else {
            flat.status[i] = PixelStatus::Masked;
        }
    }
    let valid: Vec<usize> = (0..flat.intensity.len())
        .filter(|&i| camera.valid_pixels()[i])
        .collect();
    let stats = |f: &Image| {
        let n = valid.len() as f64;
        let mean = valid
            .iter()
            .map(|&i| f64::from(f.intensity[i]))
            .sum::<f64>()
            / n;
        let var = valid
            .iter()
            .map(|&i| (f64::from(f.intensity[i]) - mean).powi(2))
            .sum::<f64>()
            / n;
        (mean, var.sqrt())
    };
    // Noise alone: the measured standard deviation is the configured one.
    let noise_only = Acquisition {
        vignetting: 0.0,
        gain_amplitude: 0.0,
        offset_amplitude: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.03,
        ..Acquisition::default()
    };
    let a = noise_only.acquire(&flat, &camera, 0, 0.0).unwrap();
    let (mean, std) = stats(&a);
    assert!(
        (mean - 0.5).abs() < 0.002 && (std - 0.03).abs() < 0.002,
        "{mean} {std}"
    );
    let again = noise_only.acquire(&flat, &camera, 0, 0.0).unwrap();
    assert_eq!(a, again, "seeded noise");
    let other = noise_only.acquire(&flat, &camera, 1, 0.0).unwrap();
    assert_ne!(a, other, "frames get independent noise");
    // Gain at a quarter period: 1 + amplitude; offset cos = 0.
    let gain_only = Acquisition {
        vignetting: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        ..Acquisition::default()
    };
    let g = gain_only
        .acquire(&flat, &camera, 0, gain_only.gain_period_s / 4.0)
        .unwrap();
    let (mean, _) = stats(&g);
    assert!(
        (mean - 0.5 * (1.0 + gain_only.gain_amplitude)).abs() < 1e-4,
        "{mean}"
    );
    // Vignetting darkens the rim more than the inner edge; blur keeps a flat image flat.
    let vignette_only = Acquisition {
        gain_amplitude: 0.0,
        offset_amplitude: 0.0,
        noise_sigma: 0.0,
        ..Acquisition::default()
    };
    let v = vignette_only.acquire(&flat, &camera, 0, 0.0).unwrap();
    let (inner, outer) = valid.iter().fold((0.0f32, 1.0f32), |(hi, lo), &i| {
        (hi.max(v.intensity[i]), lo.min(v.intensity[i]))
    });
    assert!(
        inner > 0.48 && (outer - 0.5 * 0.7).abs() < 0.01,
        "{inner} {outer}"
    );
    // Pixels outside the camera's region are not measured.
    assert!(
        (0..v.intensity.len())
            .filter(|&i| !camera.valid_pixels()[i])
            .all(|i| !v.valid[i] && v.intensity[i] == 0.0)
    );
    assert_eq!(v.valid_count(), valid.len());
    // A rendering of another size, a shortened buffer, settings `validate` refuses (a
    // blur of 1e12 pixels would allocate terabytes) and a time that is not finite are
    // errors, not panics.
    let small = Frame::new(4, 4);
    assert!(matches!(
        Acquisition::default().acquire(&small, &camera, 0, 0.0),
        Err(WorldError::Picture(FrameError::Size { .. }))
    ));
    let mut shortened = flat.clone();
    shortened.intensity.truncate(10);
    assert!(matches!(
        Acquisition::default().acquire(&shortened, &camera, 0, 0.0),
        Err(WorldError::Picture(FrameError::Length {
            what: "intensity",
            got: 10,
            ..
        }))
    ));
    let wide_blur = Acquisition {
        blur_sigma_px: 1e12,
        ..Acquisition::default()
    };
    assert!(matches!(
        wide_blur.acquire(&flat, &camera, 0, 0.0),
        Err(WorldError::Sequence(_))
    ));
    assert!(matches!(
        Acquisition::default().acquire(&flat, &camera, 0, f64::NAN),
        Err(WorldError::Sequence(_))
    ));
}
