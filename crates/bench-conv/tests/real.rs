//! The real-data benchmark: its method names, and its pose check and local maps on the
//! house pictures of the shared data (`PGM_DATA_DIR`): each of pictures 3 to 5 left
//! out of a cloud of the other two, at 320×240.

use bench_conv::real::{RealSpec, run_benchmark};
use test_support::{data_dir, workspace_root};

#[test]
fn the_pose_check_and_local_maps_run_on_the_house() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("bench-conv-real-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let dataset = workspace_root().join("fixtures/real/house.toml");
    let path = dir.join("bench.toml");
    std::fs::write(
        &path,
        format!(
            "name = \"house-test\"\ndataset = {dataset:?}\ndownsample = 2\nmethods = [\"povs\"]\n\
             [fuse]\nvoxel_size_m = 0.02\nmin_frames = 1\n\
             [split]\nkind = \"leave_one_out\"\nframes = \"3-5\"\n\
             [starts]\noffsets = [[0.05, 3.0]]\nseed = 1\n\
             [pose_check]\nframes = 2\n\
             [local_map]\nframes = 1\nmethods = [\"povs\", \"rule2/convolved\"]\n"
        ),
    )
    .unwrap();
    let spec = RealSpec::load(&path).unwrap();
    let (_, results) = run_benchmark(spec, &data.join("rgbd/house")).unwrap();

    // Each query against each of its two frames alone and both together.
    assert_eq!(results.poses.len(), 3 * 3);
    for q in [3, 4, 5] {
        let rows: Vec<_> = results.poses.iter().filter(|r| r.query == q).collect();
        assert_eq!(rows.iter().map(|r| r.frames).collect::<Vec<_>>(), [1, 1, 2]);
        for r in &rows {
            assert!(r.failure.is_empty(), "{r:?}");
            assert!(r.correction_m.unwrap() < 0.3, "{r:?}");
            assert!(
                r.rms_after_mm.unwrap() <= r.rms_before_mm.unwrap() + 1e-9,
                "{r:?}"
            );
        }
    }
    // Picture 4 fits its neighbour 5 by depth to about a centimetre (rgbd's test).
    let four_five = results
        .poses
        .iter()
        .find(|r| r.query == 4 && r.against == "frame 5")
        .unwrap();
    assert!(four_five.correction_m.unwrap() < 0.03, "{four_five:?}");

    // The local runs: both methods in a one-frame cloud, from the one start, named as
    // such, measured against the truth but not against the whole cloud's optimum.
    let local: Vec<_> = results
        .runs
        .iter()
        .filter(|r| r.method.ends_with("@local1"))
        .collect();
    assert_eq!(local.len(), 3 * 2);
    for method in ["povs@local1", "rule2/convolved@local1"] {
        assert_eq!(local.iter().filter(|r| r.method == method).count(), 3);
    }
    for r in &local {
        assert!(r.error_m.is_finite() && r.to_reference_m.is_none(), "{r:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The benchmark's method names round-trip; `localizer` and `tracker` take the library's
/// settings as they are, a rule the localiser's with its Jacobian and comparison; each
/// on one thread.
#[test]
fn bench_methods_parse_and_take_their_settings() {
    use bench_conv::real::{BenchMethod, Preset};
    use vvs::{Localizer, Method, Support, Tracker, VvsConfig};
    for name in [
        "localizer",
        "tracker",
        "povs",
        "rule2/convolved",
        "rule0/paper",
        "rule1/convolved+region",
        "povs+region",
    ] {
        assert_eq!(BenchMethod::parse(name).unwrap().name(), name);
    }
    let one_thread = |config: VvsConfig| VvsConfig {
        parallel: false,
        ..config
    };
    let tracker = BenchMethod::parse("tracker").unwrap();
    assert_eq!(tracker.preset, Some(Preset::Tracker));
    assert_eq!(tracker.method, Method::Rule2);
    assert_eq!(tracker.config(), one_thread(Tracker::default_config()));
    assert_eq!(
        BenchMethod::parse("localizer").unwrap().config(),
        one_thread(Localizer::default().config)
    );
    let rule = BenchMethod::parse("rule1/paper+region").unwrap();
    assert_eq!(
        (rule.method, rule.support),
        (Method::Rule1, Support::Region)
    );
    assert_eq!(
        rule.config(),
        one_thread(VvsConfig {
            jacobian: rule.jacobian,
            support: Support::Region,
            ..Localizer::default().config
        })
    );
    assert_ne!(rule.jacobian, Localizer::default().config.jacobian);
    assert!(BenchMethod::parse("global").is_err());
}
