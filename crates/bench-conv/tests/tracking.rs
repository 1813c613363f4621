//! The sequence generator (trajectory, shaking, acquired images) and tracking.

use bench_conv::sequence::{Acquisition, Trajectory};
use bench_conv::tracking::{
    SequenceSpec, TrackingResults, read_csv, run_sequence, summarize, write_csv, write_results,
};
use frame::{Frame, PixelStatus};
use test_support::workspace_root as root;
use ucm::Camera;

fn camera() -> Camera {
    Camera::load_toml(root().join("fixtures/omni-320x240.toml")).unwrap()
}

/// The quick file relies on the models' defaults: they must be the full file's values.
#[test]
fn sequence_fixtures_parse_and_share_the_same_sequence() {
    let full = SequenceSpec::load(&root().join("fixtures/sequence-fig4.toml")).unwrap();
    let quick = SequenceSpec::load(&root().join("fixtures/sequence-fig4-quick.toml")).unwrap();
    assert_eq!(full.trajectory, Trajectory::default());
    assert_eq!(full.acquisition, Acquisition::default());
    assert_eq!(quick.trajectory, full.trajectory);
    assert_eq!(quick.acquisition, full.acquisition);
    assert_eq!(full.steps, vec![1, 2, 5, 10, 20]);
    // The vignetting ablation differs from the full sequence in its vignetting alone.
    let ablation =
        SequenceSpec::load(&root().join("fixtures/sequence-fig4-no-vignetting.toml")).unwrap();
    assert_eq!(ablation.trajectory, full.trajectory);
    assert_eq!(
        ablation.acquisition,
        Acquisition {
            vignetting: 0.0,
            ..full.acquisition.clone()
        }
    );
    assert!(full.vvs_config().unwrap().normalize);
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
    let stats = |f: &Frame| {
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
    let mut a = flat.clone();
    noise_only.degrade(&mut a, &camera, 0, 0.0);
    let (mean, std) = stats(&a);
    assert!(
        (mean - 0.5).abs() < 0.002 && (std - 0.03).abs() < 0.002,
        "{mean} {std}"
    );
    let mut again = flat.clone();
    noise_only.degrade(&mut again, &camera, 0, 0.0);
    assert!(a.bitwise_eq(&again), "seeded noise");
    let mut other = flat.clone();
    noise_only.degrade(&mut other, &camera, 1, 0.0);
    assert!(!a.bitwise_eq(&other), "frames get independent noise");
    // Gain at a quarter period: 1 + amplitude; offset cos = 0.
    let gain_only = Acquisition {
        vignetting: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        ..Acquisition::default()
    };
    let mut g = flat.clone();
    gain_only.degrade(&mut g, &camera, 0, gain_only.gain_period_s / 4.0);
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
    let mut v = flat.clone();
    vignette_only.degrade(&mut v, &camera, 0, 0.0);
    let (inner, outer) = valid.iter().fold((0.0f32, 1.0f32), |(hi, lo), &i| {
        (hi.max(v.intensity[i]), lo.min(v.intensity[i]))
    });
    assert!(
        inner > 0.48 && (outer - 0.5 * 0.7).abs() < 0.01,
        "{inner} {outer}"
    );
    // Masked pixels are untouched.
    assert!(
        (0..v.intensity.len())
            .filter(|&i| !camera.valid_pixels()[i])
            .all(|i| v.intensity[i] == flat.intensity[i])
    );
}

/// A short, mildly shaken sequence through the city: PGMoT tracks every frame to
/// centimetres, the results are written, read back, and summarised.
#[test]
fn pgm_tracking_follows_a_short_sequence() {
    let dir = std::env::temp_dir().join(format!("bench-conv-tracking-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(
        root().join("fixtures/omni-320x240.toml"),
        dir.join("camera.toml"),
    )
    .unwrap();
    let text = r#"
name = "short"
camera = "camera.toml"
methods = ["rule2"]
steps = [3]
initial_offset = [0.03, 0.0, 0.0, 0.0, 0.0, 0.01]

[scene]
kind = "city"
seed = 1
spacing_m = 0.05

[trajectory]
frames = 7
start = [-20.0, -1.0, 0.0]
heading_deg = 90.0
length_m = 0.2
camera_height_m = 1.5
[trajectory.shake]
kerb_at_m = 100.0

[acquisition]
noise_sigma = 0.01

[vvs]
step1_max_iterations = 40
max_iterations = 80
"#;
    let path = dir.join("short.toml");
    std::fs::write(&path, text).unwrap();
    let spec = SequenceSpec::load(&path).unwrap();
    let camera = spec.load_camera().unwrap();
    let (cloud, acquired_cloud) = spec.load_clouds().unwrap();
    assert!(acquired_cloud.is_some(), "the city is resampled");
    let (results, acquired): (TrackingResults, _) =
        run_sequence(&spec, &camera, &cloud, acquired_cloud.as_ref()).unwrap();
    let frames: Vec<usize> = results.records.iter().map(|r| r.frame).collect();
    assert_eq!(frames, vec![0, 3, 6]);
    for r in &results.records {
        eprintln!(
            "frame {}: {:.4} m, {:.3}°, {:?}, {}",
            r.frame, r.position_error_m, r.rotation_error_deg, r.iterations, r.stop
        );
        assert!(
            r.position_error_m < 0.03,
            "frame {}: {} m",
            r.frame,
            r.position_error_m
        );
    }
    let summary = summarize(&results);
    assert_eq!(summary.len(), 1);
    assert_eq!(summary[0].lost_at, None);
    assert_eq!(summary[0].frames, 3);
    let out = dir.join("out");
    write_results(&spec, &camera, &cloud, &results, &acquired, &out).unwrap();
    let back = read_csv(&out.join("frames.csv")).unwrap();
    assert_eq!(back.len(), results.records.len());
    for (a, b) in back.iter().zip(&results.records) {
        assert_eq!(
            (&a.method, a.step, a.frame, a.iterations, &a.stop),
            (&b.method, b.step, b.frame, b.iterations, &b.stop)
        );
        assert!((a.position_error_m - b.position_error_m).abs() < 1e-8);
        for k in 0..6 {
            assert!((a.estimated_pose[k] - b.estimated_pose[k]).abs() < 1e-8);
        }
    }
    for name in [
        "summary.md",
        "trajectories.png",
        "errors.svg",
        "overlay-n3-PGMoT-frame6.png",
    ] {
        assert!(out.join(name).metadata().unwrap().len() > 0, "{name}");
    }
    write_csv(&dir.join("copy.csv"), &results.records).unwrap();
    std::fs::write(dir.join("bad.csv"), "not,a,tracking,csv\n").unwrap();
    assert!(read_csv(&dir.join("bad.csv")).is_err());
    // Bad files are clear errors.
    std::fs::write(
        dir.join("bad.toml"),
        text.replace("steps = [3]", "steps = [0]"),
    )
    .unwrap();
    let err = SequenceSpec::load(&dir.join("bad.toml")).unwrap_err();
    assert!(format!("{err:#}").contains("steps"), "{err:#}");
    std::fs::remove_dir_all(&dir).ok();
}
