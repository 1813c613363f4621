//! The sequence generator (trajectory, shaking, acquired images) and tracking.

use bench_conv::tracking::{
    SequenceSpec, TrackingResults, read_csv, run_sequence, summarize, write_csv, write_results,
};
use test_support::workspace_root as root;
use vvs::{Localizer, Prediction, Tracker, VvsConfig};
use world::sequence::{Acquisition, Trajectory};

/// The quick file relies on the models' defaults: they must be the full file's values.
#[test]
fn sequence_fixtures_parse_and_share_the_same_sequence() {
    let full = SequenceSpec::load(&root().join("fixtures/sequence-fig4.toml")).unwrap();
    let quick = SequenceSpec::load(&root().join("fixtures/sequence-fig4-quick.toml")).unwrap();
    assert_eq!(full.trajectory, Trajectory::default());
    assert_eq!(full.acquisition, Acquisition::default());
    assert_eq!(quick.trajectory, full.trajectory);
    assert_eq!(quick.acquisition, full.acquisition);
    assert_eq!(full.frame_steps, vec![1, 2, 5, 10, 20]);
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
    assert!(full.prediction == Prediction::Last && full.recovery.is_none());
    assert!(!full.vvs_config().unwrap().vignetting);
    // The improved tracking: the same sequences, tracked beyond the paper.
    for (improved, plain) in [
        ("sequence-fig4-improved.toml", &full),
        ("sequence-fig4-quick-improved.toml", &quick),
    ] {
        let improved = SequenceSpec::load(&root().join("fixtures").join(improved)).unwrap();
        assert_eq!(improved.trajectory, plain.trajectory);
        assert_eq!(improved.acquisition, plain.acquisition);
        assert_eq!(improved.frame_steps, plain.frame_steps);
        assert_eq!(improved.methods, plain.methods);
        assert_eq!(improved.initial_offset, plain.initial_offset);
        assert_ne!(improved.prediction, Prediction::Last);
        assert!(improved.vvs_config().unwrap().vignetting);
        let full_improved =
            SequenceSpec::load(&root().join("fixtures/sequence-fig4-improved.toml")).unwrap();
        assert_eq!(improved.prediction, full_improved.prediction);
        assert_eq!(improved.recovery, full_improved.recovery);
    }
}

/// The tracking ablations hold the localiser's and the tracker's settings as the
/// library gives them, and track the improved sequence's frames as it does.
#[test]
fn the_tracking_ablations_hold_the_presets() {
    let improved =
        SequenceSpec::load(&root().join("fixtures/sequence-fig4-improved.toml")).unwrap();
    for (name, preset) in [
        ("tracking-localizer.toml", Localizer::default().config),
        ("tracking-tracker.toml", Tracker::default_config()),
    ] {
        let spec = SequenceSpec::load(&root().join("fixtures/ablations").join(name)).unwrap();
        assert_eq!(spec.trajectory, improved.trajectory, "{name}");
        assert_eq!(spec.acquisition, improved.acquisition, "{name}");
        assert_eq!(spec.frame_steps, improved.frame_steps, "{name}");
        assert_eq!(spec.initial_offset, improved.initial_offset, "{name}");
        assert_eq!(spec.prediction, improved.prediction, "{name}");
        let config = spec.vvs_config().unwrap();
        // Threads, the per-iteration history and the global search's settings (a
        // tracker without recovery searches nothing) are the harness's.
        let expected = VvsConfig {
            parallel: config.parallel,
            keep_history: config.keep_history,
            global: config.global.clone(),
            ..preset
        };
        assert_eq!(config, expected, "{name}");
    }
}

/// The long sequence and its quick subset: the improved tracking of the same
/// acquisition and shaking (no kerb), a path that turns from the X street into the Y
/// street and stays near the road's centre line, clear of the cars parked along the
/// kerbs (|across| < 0.7 m; their inner sides lie 1.35 m or more from it), from one
/// street's end to the other's,
/// at the frame density of the paper's sequence.
#[test]
fn the_long_sequence_runs_through_two_streets_on_the_road() {
    let improved =
        SequenceSpec::load(&root().join("fixtures/sequence-fig4-improved.toml")).unwrap();
    for (name, steps) in [
        ("sequence-long.toml", vec![10, 20]),
        ("sequence-long-quick.toml", vec![20]),
    ] {
        let long = SequenceSpec::load(&root().join("fixtures").join(name)).unwrap();
        assert_eq!(long.frame_steps, steps);
        assert_eq!(long.acquisition, improved.acquisition);
        assert_eq!(long.methods, improved.methods);
        assert_eq!(long.prediction, improved.prediction);
        assert_eq!(long.recovery, improved.recovery);
        assert!(long.vvs_config().unwrap().vignetting);
        let t = &long.trajectory;
        assert!(
            t.shake.kerb_drop_m == 0.0 && t.shake.kerb_pitch_deg == 0.0,
            "no kerb"
        );
        assert_eq!(t.turns.len(), 1);
        let spacing = t.length_m / (t.frames - 1) as f64;
        let paper = improved.trajectory.length_m / (improved.trajectory.frames - 1) as f64;
        assert!(
            (spacing / paper - 1.0).abs() < 0.01,
            "{spacing} m per frame"
        );
        let poses = t.poses();
        for p in &poses {
            let q = p.translation;
            let across = if q.y.abs() < 3.5 && q.x < 0.0 {
                q.y
            } else {
                q.x
            };
            assert!(across.abs() < 3.5, "{name}: off the road at {q}");
        }
        let (first, last) = (poses[0].translation, poses[poses.len() - 1].translation);
        assert!(first.x < -5.0 && first.y.abs() < 2.0, "{first}");
        assert!(last.y > 5.0 && last.x.abs() < 2.0, "{last}");
        if name == "sequence-long.toml" {
            assert!(t.length_m > 109.0 && first.x < -54.0 && last.y > 54.0);
        }
    }
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
frame_steps = [3]
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
            (
                &a.method,
                a.frame_step,
                a.frame,
                a.iterations,
                &a.stop,
                a.recovered
            ),
            (
                &b.method,
                b.frame_step,
                b.frame,
                b.iterations,
                &b.stop,
                b.recovered
            )
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
        text.replace("frame_steps = [3]", "frame_steps = [0]"),
    )
    .unwrap();
    let err = SequenceSpec::load(&dir.join("bad.toml")).unwrap_err();
    assert!(format!("{err:#}").contains("steps"), "{err:#}");
    for (broken, says) in [
        (
            text.replace("frame_steps = [3]", "frame_steps = [7]"),
            "N must be below the frame count",
        ),
        (
            text.replace("frame_steps = [3]", "frame_steps = [3, 3]"),
            "lists 3 twice",
        ),
        (
            text.replace("frames = 7", "frames = 7\nfps = 1e300"),
            "fps must be in",
        ),
    ] {
        std::fs::write(dir.join("bad.toml"), broken).unwrap();
        let err = SequenceSpec::load(&dir.join("bad.toml")).unwrap_err();
        assert!(format!("{err:#}").contains(says), "{says}: {err:#}");
    }
    // The prediction and the recovery parse, strictly.
    let with = |extra: &str| {
        let text = text.replace(
            "initial_offset = [0.03, 0.0, 0.0, 0.0, 0.0, 0.01]",
            &format!("initial_offset = [0.03, 0.0, 0.0, 0.0, 0.0, 0.01]\n{extra}"),
        );
        std::fs::write(dir.join("more.toml"), text).unwrap();
        SequenceSpec::load(&dir.join("more.toml"))
    };
    let spec = with("prediction = \"constant_translation\"").unwrap();
    assert_eq!(spec.prediction, Prediction::ConstantTranslation);
    assert!(spec.recovery.is_none());
    let spec = with("[recovery]\nmax_jump_m = 0.2\n").unwrap();
    let recovery = spec.recovery.unwrap();
    assert_eq!(recovery.max_jump_m, 0.2);
    assert_eq!(recovery.search, vvs::Recovery::default().search);
    for (bad, says) in [
        ("prediction = \"sideways\"", "sideways"),
        ("[recovery]\nmax_jump = 0.2\n", "max_jump"),
        ("[recovery]\nmax_jump_deg = -1.0\n", "max_jump_deg"),
    ] {
        let err = with(bad).unwrap_err();
        assert!(format!("{err:#}").contains(says), "{bad}: {err:#}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The real benchmark's tracking settings: every benchmark file parses (7-Scenes tracks with
/// both predictions), and bad frame steps or predictions are refused.
#[test]
fn real_benchmark_tracking_settings_are_checked() {
    let real = root().join("fixtures/real");
    let kitchen = bench_conv::real::RealSpec::load(&real.join("bench-redkitchen.toml")).unwrap();
    let tracking = kitchen.tracking.clone().unwrap();
    assert_eq!(
        tracking.predictions,
        [Prediction::Last, Prediction::ConstantVelocity]
    );
    let house = bench_conv::real::RealSpec::load(&real.join("bench-house.toml")).unwrap();
    assert!(house.tracking.is_none());
    // Every benchmark file parses (7-Scenes, TUM RGB-D, the house).
    let mut benches = 0;
    for entry in std::fs::read_dir(&real).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with("bench-") && name.ends_with(".toml") {
            bench_conv::real::RealSpec::load(&path).unwrap_or_else(|e| panic!("{name}: {e:#}"));
            benches += 1;
        }
    }
    assert!(benches >= 5, "{benches}");
    let dir = std::env::temp_dir().join(format!("bench-conv-real-spec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(real.join("redkitchen.toml"), dir.join("redkitchen.toml")).unwrap();
    let text = std::fs::read_to_string(real.join("bench-redkitchen.toml")).unwrap();
    for (from, to, says) in [
        (
            "frame_steps = [1, 2, 5, 10]",
            "frame_steps = [1, 2, 2]",
            "twice",
        ),
        (
            "frame_steps = [1, 2, 5, 10]",
            "frame_steps = [1, 100]",
            "1 frame in 100 of 100 frames",
        ),
        (
            "predictions = [\"last\", \"constant_velocity\"]",
            "predictions = []",
            "each prediction once",
        ),
        (
            "predictions = [\"last\", \"constant_velocity\"]",
            "predictions = [\"last\", \"last\"]",
            "each prediction once",
        ),
        (
            "predictions = [\"last\", \"constant_velocity\"]",
            "predictions = [\"sideways\"]",
            "sideways",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let path = dir.join("bench.toml");
        std::fs::write(&path, text.replace(from, to)).unwrap();
        let err = bench_conv::real::RealSpec::load(&path).unwrap_err();
        assert!(format!("{err:#}").contains(says), "{to}: {err:#}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
