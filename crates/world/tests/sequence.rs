//! The sequence generator: trajectory, shaking, acquired images.

use frame::{Frame, Image, PixelStatus};
use test_support::workspace_root as root;
use ucm::Camera;
use world::{Acquisition, Trajectory};

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
    let a = noise_only.acquire(&flat, &camera, 0, 0.0);
    let (mean, std) = stats(&a);
    assert!(
        (mean - 0.5).abs() < 0.002 && (std - 0.03).abs() < 0.002,
        "{mean} {std}"
    );
    let again = noise_only.acquire(&flat, &camera, 0, 0.0);
    assert_eq!(a, again, "seeded noise");
    let other = noise_only.acquire(&flat, &camera, 1, 0.0);
    assert_ne!(a, other, "frames get independent noise");
    // Gain at a quarter period: 1 + amplitude; offset cos = 0.
    let gain_only = Acquisition {
        vignetting: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        ..Acquisition::default()
    };
    let g = gain_only.acquire(&flat, &camera, 0, gain_only.gain_period_s / 4.0);
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
    let v = vignette_only.acquire(&flat, &camera, 0, 0.0);
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
}
