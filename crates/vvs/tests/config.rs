use vvs::{PgmJacobian, Robust, VvsConfig, VvsError};

#[test]
fn config_round_trips_through_toml_and_rejects_bad_values() {
    let config = VvsConfig {
        jacobian: PgmJacobian::Paper {
            edge_margin: Some(3.0),
        },
        robust: Some(Robust::Tukey { c: 4.685 }),
        levenberg_marquardt: Some(0.01),
        extrapolate_steps: Some(4.0),
        pyramid_levels: 3,
        coarse_min_lambda_px: Some(1.5),
        lambda_schedule: vec![7.5, 3.0],
        stall_window: 0,
        converged_px: Some(0.05),
        pgm_recursive_from_lambda: f32::INFINITY,
        ..VvsConfig::default()
    };
    let text = config.to_toml_string().unwrap();
    assert_eq!(VvsConfig::from_toml_str(&text).unwrap(), config);
    // Missing fields take the paper's defaults.
    let partial = VvsConfig::from_toml_str("gain = 0.3\n").unwrap();
    assert_eq!(partial.gain, 0.3);
    assert_eq!(partial.max_iterations, 250);
    assert_eq!(partial.pgm_recursive_from_lambda, 3.0);
    let exact = VvsConfig::from_toml_str("pgm_recursive_from_lambda = inf\n").unwrap();
    assert_eq!(exact.pgm_recursive_from_lambda, f32::INFINITY);
    for (text, field) in [
        ("gain = 2.0", "gain"),
        ("lambda_star_step1 = 100.0", "lambda_star_step1"),
        ("step1_max_iterations = 300", "step1_max_iterations"),
        ("pgm_stride = 0", "pgm_stride"),
        ("pgm_stride = 4294967295", "pgm_stride"),
        ("step1_max_iterations = 250", "step1_max_iterations"),
        (
            "max_iterations = 1000000000000\nstep1_max_iterations = 1000000000000\nstall_window = 0",
            "max_iterations",
        ),
        (
            "pgm_recursive_from_lambda = 0.0",
            "pgm_recursive_from_lambda",
        ),
        (
            "pgm_recursive_from_lambda = nan",
            "pgm_recursive_from_lambda",
        ),
        (
            "pgm_interaction_row_step_lambdas = -0.1",
            "pgm_interaction_row_step_lambdas",
        ),
        (
            "pgm_interaction_row_step_lambdas = inf",
            "pgm_interaction_row_step_lambdas",
        ),
        ("extrapolate_steps = 0.5", "extrapolate_steps"),
        ("extrapolate_steps = nan", "extrapolate_steps"),
        ("extrapolate_steps = inf", "extrapolate_steps"),
        ("pyramid_levels = 0", "pyramid_levels"),
        ("pyramid_levels = 6", "pyramid_levels"),
        (
            "lambda_star_step1 = 1.5\npyramid_levels = 3",
            "pyramid_levels",
        ),
        ("lambda_schedule = [7.5, 0.1]", "lambda_schedule"),
        ("coarse_min_lambda_px = 0.1", "coarse_min_lambda_px"),
        ("coarse_min_lambda_px = nan", "coarse_min_lambda_px"),
        ("stall_relative_decrease = 1.5", "stall_relative_decrease"),
        ("converged_px = 0.0", "converged_px"),
        ("converged_px = -1.0", "converged_px"),
        ("converged_px = inf", "converged_px"),
        ("converged_px = nan", "converged_px"),
        ("rerender_px = 0.0", "rerender_px"),
        ("rerender_px = -2.0", "rerender_px"),
        ("rerender_px = nan", "rerender_px"),
        (
            "step1_max_iterations = 2\nlambda_schedule = [7.5, 3.0]",
            "step1_max_iterations",
        ),
        // A search keeps lists of these many candidates: bounded, not only non-zero.
        ("[global]\nrefined = 1000000000000000", "global.refined"),
        (
            "[global]\nscreened = 9223372036854775807",
            "global.screened",
        ),
        ("[global]\npruned_to = 1000001", "global.pruned_to"),
        ("[global]\nscreened = 0", "global.screened"),
        (
            "[global]\ndescent_iterations = 100001",
            "global.descent_iterations",
        ),
    ] {
        match VvsConfig::from_toml_str(text) {
            Err(VvsError::Config { name, .. }) => assert_eq!(name, field),
            other => panic!("{text}: {other:?}"),
        }
    }
    // Coarse to fine places λ*₁ where it stays in range: no pyramid stage at 0.375 px.
    VvsConfig::from_toml_str(
        "lambda_star_step1 = 1.5\npyramid_levels = 3\ncoarse_min_lambda_px = 1.0",
    )
    .unwrap();
    assert!(matches!(
        VvsConfig::from_toml_str("gian = 0.2"),
        Err(VvsError::ConfigFile(_))
    ));
}

/// Overrides replace the fields they name, merge tables key by key, keep everything
/// else (an absent level of detail included), and are validated.
#[test]
fn overrides_layer_settings() {
    let base = VvsConfig {
        gain: 0.3,
        lod_spacing_px: None,
        global: vvs::GlobalConfig {
            screened: 7,
            ..vvs::GlobalConfig::default()
        },
        ..VvsConfig::default()
    };
    let overrides: toml::Table = toml::from_str(
        "max_iterations = 300\njacobian = \"paper-margin3\"\n[global]\nrefined = 2\n",
    )
    .unwrap();
    let merged = base.with_overrides(&overrides).unwrap();
    assert_eq!(
        merged,
        VvsConfig {
            max_iterations: 300,
            jacobian: PgmJacobian::Paper {
                edge_margin: Some(3.0)
            },
            global: vvs::GlobalConfig {
                refined: 2,
                ..base.global.clone()
            },
            ..base.clone()
        }
    );
    assert_eq!(base.with_overrides(&toml::Table::new()).unwrap(), base);
    for bad in ["gian = 0.2", "gain = -1.0", "jacobian = \"sobel\""] {
        let table: toml::Table = toml::from_str(bad).unwrap();
        assert!(base.with_overrides(&table).is_err(), "{bad}");
    }
}
