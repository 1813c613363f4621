//! `cargo xtask reproduce-fig3`: run the protocol with the release build of
//! `bench-conv`, then check the results for consistency.

use std::process::Command;

use anyhow::{Context, bail, ensure};
use bench_conv::protocol::Protocol;
use bench_conv::report::{read_csv, summarize};

use crate::project_root;

/// Run the Fig. 3 protocol (or its quick subset) and check the result files.
pub fn fig3(quick: bool, extras: bool) -> anyhow::Result<()> {
    let root = project_root();
    let (protocol_path, out) = if quick {
        (
            root.join("fixtures/protocol-fig3-quick.toml"),
            root.join("results/fig3-quick"),
        )
    } else {
        (
            root.join("fixtures/protocol-fig3.toml"),
            root.join("results/fig3"),
        )
    };
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut command = Command::new(cargo);
    command
        .current_dir(&root)
        .args([
            "run",
            "--release",
            "--quiet",
            "-p",
            "bench-conv",
            "--",
            "run",
        ])
        .arg(&protocol_path)
        .arg("--out")
        .arg(&out);
    if extras {
        command.arg("--extras");
    }
    let status = command.status().context("running bench-conv")?;
    ensure!(status.success(), "bench-conv failed: {status}");
    check(&protocol_path, &out, quick, extras)?;
    println!(
        "checked: {} is consistent with {}",
        out.display(),
        protocol_path.display()
    );
    Ok(())
}

/// The result files exist, every method has one row per (desired, initial) pose, and
/// in quick mode: PoVS fails from 8 m, Rule2 succeeds at least as often as Rule0.
pub fn check(
    protocol_path: &std::path::Path,
    out: &std::path::Path,
    quick: bool,
    extras: bool,
) -> anyhow::Result<()> {
    for name in ["runs.csv", "summary.md", "cdf.png", "cdf.svg"] {
        let path = out.join(name);
        ensure!(
            path.metadata().map(|m| m.len() > 0).unwrap_or(false),
            "{} is missing or empty",
            path.display()
        );
    }
    let protocol = Protocol::load(protocol_path)?;
    let records = read_csv(&out.join("runs.csv"))?;
    let methods = protocol.method_configs(extras)?;
    let per_method = protocol.desired.len() * protocol.initial_indices().len();
    ensure!(
        records.len() == per_method * methods.len(),
        "{} rows, expected {} ({} per method)",
        records.len(),
        per_method * methods.len(),
        per_method
    );
    let summaries = summarize(&records);
    for m in &methods {
        let s = summaries
            .iter()
            .find(|s| s.method == m.name)
            .with_context(|| format!("no rows for {}", m.name))?;
        ensure!(
            s.runs == per_method,
            "{}: {} rows, expected {per_method}",
            m.name,
            s.runs
        );
    }
    for (k, r) in records.iter().enumerate() {
        ensure!(
            r.run_id == k,
            "run ids are not 0..{}: {} at row {k}",
            records.len(),
            r.run_id
        );
        ensure!(
            r.success == (r.final_position_error_m < protocol.success_threshold_m),
            "run {}: success flag inconsistent with its error",
            r.run_id
        );
    }
    if quick {
        let successes = |name: &str| {
            summaries
                .iter()
                .find(|s| s.method == name)
                .map_or(0, |s| s.successes)
        };
        if successes("povs") != 0 {
            bail!(
                "PoVS succeeded from 8 m offsets ({} runs): unexpected",
                successes("povs")
            );
        }
        ensure!(
            successes("rule2/convolved") >= successes("rule0/convolved"),
            "Rule2 succeeded less often than Rule0 on the quick subset"
        );
    }
    Ok(())
}
