use std::path::PathBuf;

use bench_conv::protocol::Protocol;
use bench_conv::report::{merge, read_csv, summarize, summary_markdown, write_csv};
use bench_conv::run::{Shard, load_scene, run_protocol};
use test_support::workspace_root as root;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bench-conv-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A tiny protocol (short budgets) written next to a copy of the fixture camera.
fn tiny_protocol(dir: &std::path::Path) -> PathBuf {
    std::fs::copy(
        root().join("fixtures/omni-320x240.toml"),
        dir.join("camera.toml"),
    )
    .unwrap();
    let text = r#"
name = "tiny"
camera = "camera.toml"
methods = ["povs", "rule2"]
jacobians = ["convolved", "paper"]
initial_indices = [0, 5, 63]

[scene]
kind = "city"
seed = 1
spacing_m = 0.1

[offsets]
translation_m = [0.3, 0.1, 0.1]
rotation_deg = [1.0, 1.0, 2.0]

[[desired]]
looking_down = [-20.0, 0.5, 3.0, 0.0]

[vvs]
step1_max_iterations = 2
max_iterations = 4

[[variant]]
name = "rule2/lm"
method = "rule2"
vvs = { levenberg_marquardt = 0.1 }
"#;
    let path = dir.join("tiny.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn fixture_protocols_parse_and_keep_every_pose_in_the_street() {
    for name in [
        "protocol-fig3.toml",
        "protocol-fig3-quick.toml",
        "protocol-fig3-lambda30.toml",
        "protocol-global.toml",
        "protocol-global-uniform.toml",
        "protocol-global-quick.toml",
        "protocol-global-any-heading.toml",
        "protocol-global-any-heading-quick.toml",
        "protocol-fig3-domain.toml",
        "protocol-fig3-axes.toml",
        "protocol-fig3-domain-quick.toml",
        "protocol-fig3-axes-quick.toml",
        "ablations/baseline.toml",
        "ablations/no-clutter.toml",
        "ablations/plain-facades.toml",
        "ablations/wide-field.toml",
        "ablations/wide-street.toml",
        "ablations/camera-4.5m.toml",
        "ablations/seed2.toml",
        "ablations/localizer-stall-window.toml",
    ] {
        let p = Protocol::load(&root().join("fixtures").join(name)).unwrap();
        assert!(!p.runs(true).unwrap().is_empty());
        for d in 0..p.desired.len() {
            for (i, &scale) in p
                .initial_indices()
                .into_iter()
                .flat_map(|i| p.offsets.scales.iter().map(move |s| (i, s)))
            {
                let pose = p.initial_pose(d, i, scale).unwrap();
                let t = pose.translation;
                // Inside a 7 m road of one of the two streets, at least 1 m above it.
                let across = if t.x.abs() > 6.0 { t.y } else { t.x };
                assert!(across.abs() < 3.5, "{name}: desired {d} initial {i} at {t}");
                assert!(
                    t.z >= 1.0 && t.z <= 6.5,
                    "{name}: desired {d} initial {i} at {t}"
                );
                assert!(t.x.abs() < 60.0 && t.y.abs() < 60.0);
            }
        }
    }
    // Twice the paper's translations reach the sidewalks and 0–6 m of height: parsed,
    // with the heading search on and every heading drawn.
    let wide =
        Protocol::load(&root().join("fixtures/protocol-global-any-heading-wide.toml")).unwrap();
    assert_eq!(wide.runs(false).unwrap().len(), 7 * 16);
    assert_eq!(wide.prior_box().rotation_deg[2], 180.0);
    let configs = wide.method_configs(false).unwrap();
    assert_eq!(configs[0].config.global.heading_spacing_deg, Some(15.0));
    let headings: Vec<f64> = (0..16)
        .map(|i| wide.offset(0, i, 1.0)[5].to_degrees())
        .collect();
    assert!(
        headings.iter().any(|h| *h > 90.0) && headings.iter().any(|h| *h < -90.0),
        "{headings:?}"
    );
    let twice = Protocol::load(&root().join("fixtures/protocol-global-twice.toml")).unwrap();
    assert_eq!(twice.runs(false).unwrap().len(), 7 * 8);
    assert_eq!(twice.prior_box().rotation_deg, [20.0, 20.0, 30.0]);
    let full = Protocol::load(&root().join("fixtures/protocol-fig3.toml")).unwrap();
    assert_eq!(full.desired.len(), 7);
    assert_eq!(full.initial_indices().len(), 64);
    // PoVS once, three rules × two Jacobians: 7 configurations, 448 runs each.
    assert_eq!(full.method_configs(false).unwrap().len(), 7);
    assert_eq!(full.runs(false).unwrap().len(), 7 * 448);
    // Offsets: index 0 all positive, 63 all negative, in the desired camera's frame.
    assert_eq!(full.offset(0, 0, 1.0)[0], 8.0);
    assert_eq!(full.offset(0, 63, 1.0)[2], -1.5);
    assert_eq!(full.offset(0, 63, 0.5)[2], -0.75);
    let d = full.desired_pose(0).unwrap();
    let i = full.initial_pose(0, 1, 1.0).unwrap();
    assert!(
        ((i.translation - d.translation).x + 8.0).abs() < 1e-9,
        "tX is along the street (camera X = world X)"
    );
}

#[test]
fn shards_merge_to_the_single_run() {
    let dir = temp("shards");
    let protocol = Protocol::load(&tiny_protocol(&dir)).unwrap();
    let (cloud, scene) = load_scene(&protocol).unwrap();
    let all = run_protocol(&protocol, &cloud, &scene, true, None).unwrap();
    assert_eq!(all.len(), 3 * 4); // povs, rule2 × 2 Jacobians, the variant
    let parts: Vec<_> = (0..2)
        .map(|i| {
            run_protocol(
                &protocol,
                &cloud,
                &scene,
                true,
                Some(Shard { index: i, count: 2 }),
            )
            .unwrap()
        })
        .collect();
    // A shard holds whole poses, each with every method (whatever the shard count's
    // factors).
    for (i, part) in parts.iter().enumerate() {
        let methods: std::collections::BTreeSet<&str> =
            part.iter().map(|r| r.config.as_str()).collect();
        assert_eq!(methods.len(), 4, "shard {i}: {methods:?}");
        assert_eq!(part.len() % 4, 0, "shard {i}");
    }
    // Through CSV files, as on a cluster.
    let files: Vec<PathBuf> = parts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let f = dir.join(format!("shard{i}.csv"));
            write_csv(&f, p).unwrap();
            f
        })
        .collect();
    let merged = merge(files.iter().map(|f| read_csv(f).unwrap()).collect()).unwrap();
    assert_eq!(merged.len(), all.len());
    for (a, b) in merged.iter().zip(&all) {
        // Everything but the wall time is identical.
        assert_eq!(
            (a.run_id, &a.config, a.desired, a.initial),
            (b.run_id, &b.config, b.desired, b.initial)
        );
        assert!(
            (a.final_position_error_m - b.final_position_error_m).abs()
                <= 1e-6 * b.final_position_error_m.abs().max(1e-12)
        );
        assert_eq!(
            (a.iterations_step1, a.iterations_step2, &a.stop, a.success),
            (b.iterations_step1, b.iterations_step2, &b.stop, b.success)
        );
    }
    // Overlapping shards are refused.
    assert!(merge(vec![parts[0].clone(), parts[0].clone()]).is_err());
    let md = summary_markdown("tiny", &all, 0.02, None);
    assert!(md.contains("| rule2/convolved |") && md.contains("97 %"));
    assert_eq!(summarize(&all).len(), 4);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_protocols_are_clear_errors() {
    let dir = temp("bad");
    let good = std::fs::read_to_string(tiny_protocol(&dir)).unwrap();
    for (broken, expected) in [
        (
            good.replace("methods = [\"povs\", \"rule2\"]", "methods = []"),
            "no method",
        ),
        (
            good.replace("initial_indices = [0, 5, 63]", "initial_indices = [64]"),
            "not in 0..64",
        ),
        (
            good.replace(
                "looking_down = [-20.0, 0.5, 3.0, 0.0]",
                "looking_down = [1.0]",
            ),
            "parsing protocol",
        ),
        (
            good.replace("gain_unused", "x")
                .replace("[vvs]", "[vvs]\ngian = 0.3"),
            "gian",
        ),
        (
            good.replace(
                "kind = \"city\"\nseed = 1\nspacing_m = 0.1",
                "kind = \"las\"\npath = \"missing.laz\"",
            ),
            "missing.laz",
        ),
        (
            good.replace("initial_indices = [0, 5, 63]", "initial_indices = []"),
            "initial_indices is empty",
        ),
        (
            good.replace(
                "initial_indices = [0, 5, 63]",
                "initial_indices = [0, 5, 0]",
            ),
            "lists 0 twice",
        ),
        (
            good.replace("name = \"rule2/lm\"", "name = \"povs\""),
            "named `povs`",
        ),
        (
            good.replace("name = \"rule2/lm\"", "name = \"rule2/convolved\""),
            "named `rule2/convolved`",
        ),
        (
            good.replace(
                "name = \"tiny\"",
                "name = \"tiny\"\nsuccess_threshold_m = inf",
            ),
            "finite and > 0",
        ),
        (
            good.replace(
                "name = \"tiny\"",
                "name = \"tiny\"\nsuccess_threshold_m = -1.0",
            ),
            "finite and > 0",
        ),
        (
            good.replace(
                "looking_down = [-20.0, 0.5, 3.0, 0.0]",
                "looking_down = [nan, 0.5, 3.0, 0.0]",
            ),
            "is not finite",
        ),
        (
            good.replace("rotation_deg = [1.0, 1.0, 2.0]", "rotation_deg = [1e10, 1.0, 2.0]"),
            "not an angle in [0, 180]",
        ),
        (
            good.replace("translation_m = [0.3, 0.1, 0.1]", "translation_m = [inf, 0.1, 0.1]"),
            "not a finite length",
        ),
        (
            good.replace("[vvs]\n", "[vvs]\njacobian = \"paper\"\n"),
            "sets `jacobian`",
        ),
        (
            good.replace(
                "[vvs]\n",
                "[vvs]\nglobal = { prior = { translation_m = [1.0, 1.0, 1.0], rotation_deg = [1.0, 1.0, 1.0] } }\n",
            ),
            "sets `global.prior`",
        ),
        (
            good.replace(
                "vvs = { levenberg_marquardt = 0.1 }",
                "vvs = { jacobian = \"paper\" }",
            ),
            "variant rule2/lm's [vvs] sets `jacobian`",
        ),
        (
            good.replace("max_iterations = 4", "max_iterations = 2"),
            "leaves step 2 no iteration",
        ),
    ] {
        let path = dir.join("broken.toml");
        std::fs::write(&path, &broken).unwrap();
        let result = Protocol::load(&path).and_then(|p| load_scene(&p).map(|_| ()));
        let message = format!("{:#}", result.expect_err(expected));
        assert!(
            message.contains(expected),
            "expected `{expected}` in: {message}"
        );
    }
    // A pose outside the cloud is refused before anything runs.
    let far = good.replace(
        "looking_down = [-20.0, 0.5, 3.0, 0.0]",
        "looking_down = [-500.0, 0.5, 3.0, 0.0]",
    );
    let path = dir.join("far.toml");
    std::fs::write(&path, far).unwrap();
    let protocol = Protocol::load(&path).unwrap();
    let (cloud, scene) = load_scene(&protocol).unwrap();
    let message = format!(
        "{:#}",
        run_protocol(&protocol, &cloud, &scene, false, None).unwrap_err()
    );
    assert!(message.contains("outside the cloud"), "{message}");
    assert!(message.contains("bounds_margin_m"), "{message}");
    // One rule for cameras (the optimiser's): within bounds_margin_m (5 m) of the
    // cloud's box, as a camera a few metres from an object scan is.
    let (lo, _) = cloud.bounds();
    let near = good.replace(
        "looking_down = [-20.0, 0.5, 3.0, 0.0]",
        &format!("looking_down = [{}, 0.5, 3.0, 0.0]", lo.x - 3.0),
    );
    std::fs::write(&path, near).unwrap();
    let protocol = Protocol::load(&path).unwrap();
    run_protocol(&protocol, &cloud, &scene, false, None).unwrap();
    // A shard with no run is an error, not an empty success.
    let protocol = Protocol::load(&tiny_protocol(&dir)).unwrap();
    let message = format!(
        "{:#}",
        run_protocol(
            &protocol,
            &cloud,
            &scene,
            false,
            Some(Shard { index: 5, count: 8 })
        )
        .unwrap_err()
    );
    assert!(message.contains("at most 3 shards"), "{message}");
    // More shards than poses, whichever shard is asked for (some would hold no run).
    for text in ["0/4", "1/1000000", "0/18446744073709551615"] {
        let shard = Shard::parse(text).unwrap();
        let message = format!(
            "{:#}",
            bench_conv::run::check_shard(&protocol, false, Some(shard)).unwrap_err()
        );
        assert!(message.contains("at most 3 shards"), "{text}: {message}");
    }
    bench_conv::run::check_shard(&protocol, false, Some(Shard::parse("2/3").unwrap())).unwrap();
    for bad in ["1/2/3", "a/2", "2/2", "1", "-1/2"] {
        let message = format!("{:#}", Shard::parse(bad).unwrap_err());
        assert!(message.contains("write i/n"), "{bad}: {message}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// CSV fields with commas and quotes survive a round trip; errors that are NaN,
/// infinite or negative are refused with the file, line and field; a new threshold
/// decides success anew; a results folder is marked incomplete until it is finished,
/// and a file in the way of `--out` is an error before any work.
#[test]
fn csv_thresholds_and_results_folders_are_safe() {
    use bench_conv::report::{
        INCOMPLETE_MARKER, LOCK_FILE, RunRecord, apply_threshold, begin_results, finish_results,
    };
    let dir = temp("csv");
    let record = |id: usize, error: f64| RunRecord {
        run_id: id,
        scene: "a,b \"c\".las".into(),
        desired: 0,
        offset_scale: 0.5,
        initial: id,
        config: "rule2,x".into(),
        method: vvs::Method::Rule2,
        final_position_error_m: error,
        final_rotation_error_deg: 0.1,
        iterations_step1: 3,
        iterations_step2: 4,
        stop: vvs::StopReason::Stalled,
        lambda: 1.0,
        cost: 1e-3,
        wall_time_s: 0.25,
        success: error < 0.02,
    };
    let records = vec![record(0, 0.01), record(1, 0.5)];
    let path = dir.join("runs.csv");
    write_csv(&path, &records).unwrap();
    let back = read_csv(&path).unwrap();
    assert_eq!(back.len(), 2);
    assert_eq!(back[0].scene, records[0].scene);
    assert_eq!(back[1].config, "rule2,x");
    let merged = merge(vec![back]).unwrap();
    assert_eq!(merged.len(), 2);
    for bad in [f64::NAN, f64::INFINITY, -1.0] {
        write_csv(&path, &[record(0, bad)]).unwrap();
        let message = format!("{:#}", read_csv(&path).unwrap_err());
        assert!(
            message.contains("final_position_error_m") && message.contains(":2"),
            "{bad}: {message}"
        );
    }
    let mut rethresholded = records.clone();
    apply_threshold(&mut rethresholded, 1.0).unwrap();
    assert!(rethresholded.iter().all(|r| r.success));
    // A run whose cost is not finite is never a success.
    rethresholded[0].cost = f64::NAN;
    apply_threshold(&mut rethresholded, 1.0).unwrap();
    assert!(!rethresholded[0].success && rethresholded[1].success);
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(apply_threshold(&mut rethresholded, bad).is_err());
    }
    let out = dir.join("results");
    std::fs::create_dir_all(&out).unwrap();
    // Earlier results are refused without --force, and replaced with it: the files a
    // run writes go (a stale domain.csv, the pictures/ folder), others stay.
    for name in ["summary.md", "domain.csv", "notes.txt"] {
        std::fs::write(out.join(name), "stale").unwrap();
    }
    std::fs::create_dir_all(out.join("pictures")).unwrap();
    std::fs::write(out.join("pictures/1.png"), "stale").unwrap();
    let message = format!("{:#}", begin_results(&out, false).unwrap_err());
    assert!(
        message.contains("--force") && message.contains("domain.csv, pictures, summary.md"),
        "{message}"
    );
    assert!(out.join("summary.md").exists() && !out.join(LOCK_FILE).exists());
    let lock = begin_results(&out, true).unwrap();
    assert!(out.join(INCOMPLETE_MARKER).exists() && out.join("notes.txt").exists());
    for gone in ["summary.md", "domain.csv", "pictures"] {
        assert!(!out.join(gone).exists(), "{gone}");
    }
    // A second run into the folder while the first holds it is refused, even forced.
    let message = format!("{:#}", begin_results(&out, true).unwrap_err());
    assert!(message.contains("another run"), "{message}");
    // A CSV beside the marker (an interrupted run) is refused by merge's reader.
    write_csv(&out.join("runs.csv"), &records).unwrap();
    assert!(read_csv(&out.join("runs.csv")).is_err());
    finish_results(&out).unwrap();
    drop(lock);
    assert!(!out.join(INCOMPLETE_MARKER).exists() && !out.join(LOCK_FILE).exists());
    // The lock of a process that no longer runs is taken over.
    std::fs::write(out.join(LOCK_FILE), format!("{}\n", u32::MAX)).unwrap();
    let lock = begin_results(&out, true).unwrap();
    drop(lock);
    let message = format!("{:#}", begin_results(&path, false).unwrap_err());
    assert!(message.contains("not a folder"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_papers_rates_stand_beside_its_configurations_only() {
    use bench_conv::report::paper_success_rate;
    assert_eq!(paper_success_rate("povs"), Some(0.0));
    assert_eq!(paper_success_rate("rule0/convolved"), Some(70.0));
    assert_eq!(paper_success_rate("rule1/paper"), Some(78.0));
    assert_eq!(paper_success_rate("rule2/paper-margin3"), Some(97.0));
    assert_eq!(paper_success_rate("rule2/convolved+lm"), None);
    assert_eq!(paper_success_rate("rule2/convolved+no-stall"), None);
    assert_eq!(paper_success_rate("my-method"), None);
    // A name is `method` or `method/jacobian`, spelt as the protocol writes them.
    assert_eq!(paper_success_rate("rule2"), Some(97.0));
    assert_eq!(paper_success_rate("rule2/convolved"), Some(97.0));
    assert_eq!(paper_success_rate("rule1/paper-margin2.5"), Some(78.0));
    assert_eq!(paper_success_rate("povs/convolved"), Some(0.0));
    for other in [
        "",
        "rule2/",
        "/convolved",
        "Rule2/convolved",
        " rule2",
        "rule2/ paper",
        "rule2/paper/x",
        "rule2/paper-margin",
        "rule2-lm",
        "rule2/lm",
        "global",
        "global/convolved",
    ] {
        assert_eq!(paper_success_rate(other), None, "`{other}`");
    }
    assert_eq!(
        bench_conv::report::parse_config_name("rule1/paper"),
        Some((
            vvs::Method::Rule1,
            Some(vvs::PgmJacobian::Paper { edge_margin: None })
        ))
    );
}

/// A desired pose is `looking_down = […]` or `pose = […]`, exactly one, nothing else.
#[test]
fn a_pose_is_looking_down_or_a_pose_vector() {
    use bench_conv::protocol::PoseSpec;
    #[derive(serde::Deserialize)]
    struct File {
        desired: Vec<PoseSpec>,
    }
    let parse = |text: &str| toml::from_str::<File>(text).map(|f| f.desired);
    assert_eq!(
        parse("[[desired]]\nlooking_down = [1.0, 2.0, 3.0, 90.0]\n").unwrap(),
        [PoseSpec::LookingDown([1.0, 2.0, 3.0, 90.0])]
    );
    assert_eq!(
        parse("[[desired]]\npose = [1.0, 2.0, 3.0, 0.0, 0.0, 0.5]\n").unwrap(),
        [PoseSpec::Pose([1.0, 2.0, 3.0, 0.0, 0.0, 0.5])]
    );
    for (bad, expected) in [
        (
            "[[desired]]\nlooking_down = [1.0, 2.0, 3.0, 0.0]\npose = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
            "exactly one",
        ),
        ("[[desired]]\n", "exactly one"),
        (
            "[[desired]]\nlooking_down = [1.0, 2.0, 3.0, 0.0]\nheading = 1.0\n",
            "heading",
        ),
        ("[[desired]]\npose = [1.0]\n", "invalid length"),
    ] {
        let message = parse(bad).unwrap_err().to_string();
        assert!(
            message.contains(expected),
            "expected `{expected}` in: {message}"
        );
    }
    // The command line's `--pose` and `--looking-down` follow the same rule.
    assert!(bench_conv::parse_pose(Some("1,2,3,0,0,0"), None).is_ok());
    assert!(bench_conv::parse_pose(None, Some("1,2,3,0")).is_ok());
    for (pose, looking_down) in [(None, None), (Some("1,2,3,0,0,0"), Some("1,2,3,0"))] {
        let message = format!(
            "{:#}",
            bench_conv::parse_pose(pose, looking_down).unwrap_err()
        );
        assert!(message.contains("exactly one"), "{message}");
    }
}

/// `axes` offsets move one component, `uniform` ones stay within the box and are
/// reproducible, and every initial pose runs at every scale.
#[test]
fn samplings_and_scales_draw_the_documented_offsets() {
    let dir = temp("samplings");
    let path = tiny_protocol(&dir);
    let text = std::fs::read_to_string(&path).unwrap();
    let axes_text = text.replace("initial_indices = [0, 5, 63]", "").replace(
        "rotation_deg = [1.0, 1.0, 2.0]",
        "rotation_deg = [1.0, 1.0, 2.0]\nsampling = \"axes\"\nscales = [0.5, 1.0, 2.0]",
    );
    std::fs::write(dir.join("axes.toml"), axes_text).unwrap();
    let axes = Protocol::load(&dir.join("axes.toml")).unwrap();
    assert_eq!(axes.initial_indices().len(), 12);
    // 1 desired × 3 scales × 12 initial poses × 4 configurations (PoVS, Rule2 with two
    // Jacobians, the variant).
    assert_eq!(axes.runs(true).unwrap().len(), 3 * 12 * 4);
    let mag = [
        0.3,
        0.1,
        0.1,
        1f64.to_radians(),
        1f64.to_radians(),
        2f64.to_radians(),
    ];
    for i in 0..12 {
        let o = axes.offset(0, i, 2.0);
        for k in 0..6 {
            let expected = if k == i / 2 {
                if i % 2 == 0 {
                    2.0 * mag[k]
                } else {
                    -2.0 * mag[k]
                }
            } else {
                0.0
            };
            assert!((o[k] - expected).abs() < 1e-12, "initial {i}: {o:?}");
        }
    }
    let uniform_text = text.replace(
        "rotation_deg = [1.0, 1.0, 2.0]",
        "rotation_deg = [1.0, 1.0, 2.0]\nsampling = \"uniform\"\nseed = 3",
    );
    std::fs::write(dir.join("uniform.toml"), uniform_text).unwrap();
    let uniform = Protocol::load(&dir.join("uniform.toml")).unwrap();
    let draws: Vec<[f64; 6]> = (0..64).map(|i| uniform.offset(0, i, 1.0)).collect();
    for o in &draws {
        assert!((0..6).all(|k| o[k].abs() <= mag[k]), "{o:?}");
    }
    assert_eq!(draws[5], uniform.offset(0, 5, 1.0), "reproducible");
    assert_ne!(draws[5], draws[6]);
    assert_ne!(
        draws[5],
        uniform.offset(1, 5, 1.0),
        "each desired pose draws its own"
    );
    // Not at the corners: some component well inside the box.
    assert!(draws.iter().any(|o| o[0].abs() < 0.5 * mag[0]));
    // An index beyond the sampling's count is refused.
    let bad = std::fs::read_to_string(dir.join("axes.toml"))
        .unwrap()
        .replace("methods =", "initial_indices = [12]\nmethods =");
    std::fs::write(dir.join("bad.toml"), bad).unwrap();
    let message = format!("{:#}", Protocol::load(&dir.join("bad.toml")).unwrap_err());
    assert!(message.contains("0..12"), "{message}");
    let twice = std::fs::read_to_string(dir.join("axes.toml"))
        .unwrap()
        .replace("scales = [0.5, 1.0, 2.0]", "scales = [1.0, 0.5, 1.0]");
    std::fs::write(dir.join("twice.toml"), twice).unwrap();
    let message = format!("{:#}", Protocol::load(&dir.join("twice.toml")).unwrap_err());
    assert!(message.contains("twice"), "{message}");
}

/// The domain curve and the axis basins count what the records say.
#[test]
fn domain_curve_and_axis_basins_count_the_records() {
    use bench_conv::report::{RunRecord, axis_basins, domain, domain_markdown};
    let record = |method: &str, scale: f64, initial: usize, success: bool| RunRecord {
        run_id: 0,
        scene: "s".into(),
        desired: 0,
        offset_scale: scale,
        initial,
        config: method.into(),
        method: vvs::Method::Rule2,
        final_position_error_m: if success { 0.001 } else { 3.0 },
        final_rotation_error_deg: 0.0,
        iterations_step1: 1,
        iterations_step2: 1,
        stop: vvs::StopReason::Converged,
        lambda: 1.0,
        cost: 0.0,
        wall_time_s: 0.0,
        success,
    };
    let mut records = Vec::new();
    for &scale in &[0.5, 1.0, 2.0] {
        for initial in 0..12 {
            // Method a: every axis converges up to 1, axis 0 (initials 0 and 1) to 2,
            // and axis 5's negative side fails from 0.5 already.
            let a = scale <= 1.0 || initial < 2;
            let a = a && initial != 11;
            records.push(record("a", scale, initial, a));
            records.push(record("b", scale, initial, false));
        }
    }
    let points = domain(&records);
    assert_eq!(points.len(), 6);
    let a_half = points
        .iter()
        .find(|p| p.config == "a" && p.offset_scale == 0.5)
        .unwrap();
    assert_eq!((a_half.runs, a_half.successes), (12, 11));
    let a_two = points
        .iter()
        .find(|p| p.config == "a" && p.offset_scale == 2.0)
        .unwrap();
    assert_eq!(a_two.successes, 2);
    let table = domain_markdown(&points);
    assert!(
        table.contains("s = 0.5") && table.contains("91.7 % (11/12)"),
        "{table}"
    );
    let basins = axis_basins(&records);
    assert_eq!(basins[0].0, "a");
    assert_eq!(basins[0].1, [2.0, 1.0, 1.0, 1.0, 1.0, 0.0].map(Some));
    assert_eq!(basins[1].1, [Some(0.0); 6]);
    // An axis with no run at a scale ends its basin there (no success from nothing).
    records.retain(|r| !(r.initial / 2 == 1 && r.offset_scale == 1.0));
    assert_eq!(axis_basins(&records)[0].1[1], Some(0.5));
    // An axis with no run at all has no basin to give.
    records.retain(|r| r.initial / 2 != 2);
    assert_eq!(axis_basins(&records)[0].1[2], None);
}

/// The domain curve's subset of the 64 sign combinations is balanced as its fixture
/// says: every component + as often as −, every pair of components each sign pair
/// equally often (so no component's effect is confounded with another's).
#[test]
fn the_domain_curves_subset_is_an_orthogonal_fraction() {
    let p = Protocol::load(&root().join("fixtures/protocol-fig3-domain.toml")).unwrap();
    let indices = p.initial_indices();
    assert_eq!(indices.len(), 8);
    let sign = |i: usize, k: usize| if i >> k & 1 == 1 { -1 } else { 1 };
    for k in 0..6 {
        assert_eq!(
            indices.iter().map(|&i| sign(i, k)).sum::<i32>(),
            0,
            "component {k}"
        );
        for l in k + 1..6 {
            let product: i32 = indices.iter().map(|&i| sign(i, k) * sign(i, l)).sum();
            assert_eq!(product, 0, "components {k} and {l}");
        }
    }
}

/// An adaptive axes protocol runs each (method, axis) up to its first failing scale and
/// no further, finds the basins the whole ladder finds, and refuses to be sharded; the
/// check accepts its rows and refuses rows beyond a basin.
#[test]
fn adaptive_axes_stop_beyond_each_basin() {
    use bench_conv::report::{RunRecord, axis_basins, write_csv};
    use bench_conv::run::{Shard, check_shard, run_adaptive};
    let protocol = Protocol::load(&root().join("fixtures/protocol-fig3-axes.toml")).unwrap();
    assert!(protocol.offsets.adaptive);
    let err = check_shard(&protocol, false, Some(Shard { index: 0, count: 2 })).unwrap_err();
    assert!(err.to_string().contains("cannot be sharded"), "{err}");
    let methods = protocol.method_configs(false).unwrap();
    let runs = protocol.runs(false).unwrap();
    // A made-up outcome: method m converges along axis a up to scale index m + a - 3
    // (none for small sums), except desired pose 3 on the negative side of axis 2,
    // which fails from the second scale.
    let converges = |r: &bench_conv::protocol::RunSpec| {
        let axis = Protocol::axis_of(r.initial);
        let limit = r.method as isize + axis as isize - 3;
        let exception = axis == 2 && r.initial % 2 == 1 && r.desired == 3 && r.scale >= 1;
        (r.scale as isize) <= limit && !exception
    };
    let record = |r: &bench_conv::protocol::RunSpec| {
        let success = converges(r);
        RunRecord {
            run_id: r.id,
            scene: "s".into(),
            desired: r.desired,
            offset_scale: protocol.offsets.scales[r.scale],
            initial: r.initial,
            config: methods[r.method].name.clone(),
            method: methods[r.method].method,
            final_position_error_m: if success { 0.001 } else { 3.0 },
            final_rotation_error_deg: 0.0,
            iterations_step1: 1,
            iterations_step2: 1,
            stop: vvs::StopReason::Converged,
            lambda: 1.0,
            cost: 0.0,
            wall_time_s: 0.0,
            success,
        }
    };
    let mut skipped = 0;
    let mut rounds = 0;
    let adaptive = run_adaptive(
        &runs,
        methods.len(),
        |round| {
            rounds += 1;
            // In any order (the protocol's runner groups Rule1 with Rule2).
            Ok(round.iter().rev().map(record).collect())
        },
        |n| skipped += n,
    )
    .unwrap();
    assert_eq!(rounds, protocol.offsets.scales.len());
    assert_eq!(
        adaptive.len() + skipped,
        runs.len(),
        "every run is run or skipped"
    );
    assert!(skipped > runs.len() / 4, "{skipped} runs skipped");
    let mut every: Vec<RunRecord> = runs.iter().map(record).collect();
    let mut adaptive_sorted = adaptive.clone();
    adaptive_sorted.sort_by_key(|r| r.run_id);
    assert_eq!(axis_basins(&adaptive_sorted), axis_basins(&every));
    // The basins are the made-up ones (rule0/convolved is method 1, axis 4: scale index
    // 2, 0.75; axis 2 of the last method stops at its exception).
    let basins = axis_basins(&adaptive_sorted);
    let find = |name: &str| basins.iter().find(|b| b.0 == name).unwrap().1;
    assert_eq!(find("rule0/convolved")[4], Some(0.75));
    assert_eq!(find("rule2/paper")[2], Some(0.25));
    // The check: the adaptive rows pass, the whole ladder's rows do not (runs beyond a
    // failed scale), nor rows with a run missing.
    let dir = temp("adaptive");
    let write = |rows: &[RunRecord]| {
        write_csv(&dir.join("runs.csv"), rows).unwrap();
        for name in [
            "summary.md",
            "cdf.png",
            "cdf.svg",
            "domain.csv",
            "domain.png",
            "domain.svg",
        ] {
            std::fs::write(dir.join(name), "x").unwrap();
        }
        bench_conv::check::check_protocol(
            &root().join("fixtures/protocol-fig3-axes.toml"),
            &dir,
            false,
            false,
        )
    };
    write(&adaptive_sorted).unwrap();
    let err = write(&every).unwrap_err();
    assert!(err.to_string().contains("beyond a failed scale"), "{err}");
    every = adaptive_sorted.clone();
    every.remove(3);
    assert!(write(&every).is_err());
}

/// Pixel counts (`--crop`) are non-negative integers that fit in u32, nothing else.
#[test]
fn pixel_counts_parse_strictly() {
    use bench_conv::parse_pixels;
    assert_eq!(
        parse_pixels::<4>("310, 80,1230,1000").unwrap(),
        [310, 80, 1230, 1000]
    );
    for bad in [
        "1e10,80,1230,1000",
        "-10,80,1230,1000",
        "nan,80,1230,1000",
        "2.5,80,1230,1000",
        "4294967296,0,1,1",
        "1,2,3",
    ] {
        assert!(parse_pixels::<4>(bad).is_err(), "{bad}");
    }
}

/// `merge` knows the protocol's whole set of runs from the manifests beside the CSV
/// files: all shards make a complete merge, missing ones a partial merge that says
/// which, a shard given twice or shards of different protocols are errors, and CSV
/// files without a manifest leave completeness unknown.
#[test]
fn merges_know_whether_they_are_complete() {
    use bench_conv::report::{
        Completeness, RunManifest, check_run_ids, completeness, fingerprint, read_manifest,
        write_manifest,
    };
    let shard = |i: usize, runs: usize| {
        Some(RunManifest {
            protocol: "fig3".into(),
            protocol_hash: Some(fingerprint(b"name = \"fig3\"")),
            extras: false,
            total_runs: 10,
            run_id_limit: Some(10),
            shard: Some([i, 3]),
            runs,
        })
    };
    assert_eq!(
        completeness(&[shard(0, 4), shard(1, 3), shard(2, 3)], 10).unwrap(),
        Completeness::Complete {
            protocol: "fig3".into(),
            runs: 10
        }
    );
    let partial = completeness(&[shard(2, 3), shard(0, 4)], 7).unwrap();
    assert_eq!(
        partial,
        Completeness::Partial {
            protocol: "fig3".into(),
            runs: 7,
            total_runs: 10,
            shards: 3,
            missing: vec![1]
        }
    );
    assert!(partial.markdown().contains("PARTIAL") && partial.markdown().contains("1/3"));
    let twice = format!(
        "{:#}",
        completeness(&[shard(0, 4), shard(0, 4)], 8).unwrap_err()
    );
    assert!(twice.contains("given twice"), "{twice}");
    let mut other = shard(1, 3);
    if let Some(m) = &mut other {
        m.protocol = "fig3-domain".into();
    }
    assert!(completeness(&[shard(0, 4), other], 7).is_err());
    assert_eq!(
        completeness(&[shard(0, 4), None], 7).unwrap(),
        Completeness::Unknown
    );
    // Two protocol files of one name: told apart by their fingerprint.
    let mut edited = shard(1, 3);
    if let Some(m) = &mut edited {
        m.protocol_hash = Some(fingerprint(b"name = \"fig3\"\nseed = 2"));
    }
    let two = format!("{:#}", completeness(&[shard(0, 4), edited], 7).unwrap_err());
    assert!(two.contains("two different protocol files"), "{two}");
    // A run id past the protocol's 10 runs.
    let record = |run_id: usize| sample_record(run_id, true);
    let manifests = [shard(0, 4), shard(1, 3), shard(2, 3)];
    check_run_ids(&[record(0), record(9)], &manifests).unwrap();
    let past = format!(
        "{:#}",
        check_run_ids(&[record(0), record(10)], &manifests).unwrap_err()
    );
    assert!(past.contains("run 10 is not a run"), "{past}");
    check_run_ids(&[record(10)], &[shard(0, 4), None]).unwrap();
    // An adaptive protocol ran fewer runs than its ids span: ids count, not runs.
    let adaptive = |i: usize| {
        shard(i, 3).map(|m| RunManifest {
            run_id_limit: Some(12),
            ..m
        })
    };
    check_run_ids(&[record(11)], &[adaptive(0), adaptive(1), adaptive(2)]).unwrap();
    // Through the file beside a runs.csv.
    let dir = temp("manifest");
    write_manifest(&dir, shard(2, 3).as_ref().unwrap()).unwrap();
    assert_eq!(read_manifest(&dir.join("runs.csv")).unwrap(), shard(2, 3));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Frame lists of `bench-conv fuse` and the real benchmarks: numbers and inclusive
/// ranges, stepped, in the order given, without repeats; anything else refused.
#[test]
fn frame_lists() {
    use bench_conv::parse_frames;
    assert_eq!(parse_frames("1-5").unwrap(), [1, 2, 3, 4, 5]);
    assert_eq!(parse_frames("0-30/10, 7, 10").unwrap(), [0, 10, 20, 30, 7]);
    assert_eq!(
        parse_frames("460-510/10").unwrap(),
        [460, 470, 480, 490, 500, 510]
    );
    for bad in [
        "",
        "5-1",
        "a",
        "1-",
        "-3",
        "0-9/0",
        "0-9/x",
        "1.5",
        "0-99999999999",
    ] {
        assert!(parse_frames(bad).is_err(), "{bad}");
    }
}

/// The global search with the localiser's settings (common support) from two uniform
/// starts of `protocol-global-uniform.toml` at the end of the X street: ranked by the
/// PGMs' correlation alone its screening lost both (0.9 m and 5 m away), so it keeps the
/// best by the squared difference too.
#[test]
fn global_on_the_common_support_from_uniform_starts_at_the_end_of_the_street() {
    let dir = temp("global-common");
    std::fs::copy(
        root().join("fixtures/omni-320x240.toml"),
        dir.join("camera.toml"),
    )
    .unwrap();
    let text = r#"
name = "global-common"
camera = "camera.toml"
success_threshold_m = 0.02
methods = ["global"]
jacobians = ["convolved"]
initial_indices = [1, 2]

[scene]
kind = "city"
seed = 1
spacing_m = 0.05

[offsets]
translation_m = [8.0, 2.0, 1.5]
rotation_deg = [10.0, 10.0, 15.0]
sampling = "uniform"
seed = 1

[[desired]]
looking_down = [-42.0, 0.5, 3.0, 0.0]

[vvs]
normalize = true
support = "common"
gain = 1.0
levenberg_marquardt = 0.1
lambda_schedule = [7.5, 3.0]
"#;
    let path = dir.join("global-common.toml");
    std::fs::write(&path, text).unwrap();
    let protocol = Protocol::load(&path).unwrap();
    let (cloud, scene) = load_scene(&protocol).unwrap();
    let records = run_protocol(&protocol, &cloud, &scene, false, None).unwrap();
    assert_eq!(records.len(), 2);
    for r in &records {
        assert!(
            r.success,
            "start {}: {} m, {}°",
            r.initial, r.final_position_error_m, r.final_rotation_error_deg
        );
    }
}

/// A run record of a protocol run `run_id` (the tests' and fuzzers' sample).
pub fn sample_record(run_id: usize, success: bool) -> bench_conv::report::RunRecord {
    bench_conv::report::RunRecord {
        run_id,
        scene: "city-1".into(),
        desired: 0,
        offset_scale: 1.0,
        initial: run_id,
        config: "rule2/convolved".into(),
        method: vvs::Method::Rule2,
        final_position_error_m: 0.01 * run_id as f64,
        final_rotation_error_deg: 0.1,
        iterations_step1: 10,
        iterations_step2: 20,
        stop: vvs::StopReason::Stalled,
        lambda: 1.0,
        cost: 0.5,
        wall_time_s: 1.0,
        success,
    }
}
