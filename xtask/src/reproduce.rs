//! `cargo xtask reproduce-fig3`: run the protocol with the release build of
//! `bench-conv`, then check the results for consistency.

use std::process::Command;

use anyhow::{Context, bail, ensure};
use bench_conv::protocol::Protocol;
use bench_conv::report::{read_csv, summarize};

use crate::project_root;

/// How `bench-conv` is compiled for a reproduction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Build {
    /// For the instruction set of the machine that runs it (`-C target-cpu=native`, in
    /// its own target folder `target/native`): the reproduction runs where it is built.
    /// The numbers are the same as the portable build's, bit for bit: Rust never fuses
    /// or reorders floating-point operations, so wider vector instructions compute the
    /// same IEEE operations (CI compares the two builds' quick Fig. 3).
    Native,
    /// For the baseline instruction set of the target, like any `cargo build`.
    Portable,
}

/// `cargo run --release -p bench-conv -- <args>` from the project root.
fn bench_conv(args: &[&std::ffi::OsStr], build: Build) -> anyhow::Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut command = Command::new(cargo);
    command
        .current_dir(project_root())
        .args(["run", "--release", "--quiet", "-p", "bench-conv"]);
    if build == Build::Native {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map_or_else(|| project_root().join("target"), Into::into);
        let mut flags = std::env::var("RUSTFLAGS").unwrap_or_default();
        flags.push_str(" -C target-cpu=native");
        command
            .arg("--target-dir")
            .arg(target.join("native"))
            .env("RUSTFLAGS", flags.trim_start());
    }
    let status = command
        .arg("--")
        .args(args)
        .status()
        .context("running bench-conv")?;
    ensure!(status.success(), "bench-conv failed: {status}");
    Ok(())
}

/// Run the tracking experiment of Fig. 4 (or its quick subset) and check the results.
pub fn fig4(quick: bool, build: Build) -> anyhow::Result<()> {
    let root = project_root();
    let (sequence, out) = if quick {
        (
            root.join("fixtures/sequence-fig4-quick.toml"),
            root.join("results/fig4-quick"),
        )
    } else {
        (
            root.join("fixtures/sequence-fig4.toml"),
            root.join("results/fig4"),
        )
    };
    bench_conv(
        &[
            "track".as_ref(),
            sequence.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ],
        build,
    )?;
    check_fig4(&sequence, &out)?;
    println!(
        "checked: {} is consistent with {}",
        out.display(),
        sequence.display()
    );
    Ok(())
}

/// The result files exist; every track aligned every frame of its step unless it was
/// lost, and a lost track ends on a frame beyond the threshold or diverged.
pub fn check_fig4(sequence: &std::path::Path, out: &std::path::Path) -> anyhow::Result<()> {
    use bench_conv::tracking::{SequenceSpec, display_name, read_csv};
    let spec = SequenceSpec::load(sequence)?;
    let mut files = vec![
        "frames.csv".to_string(),
        "summary.md".into(),
        "trajectories.png".into(),
        "trajectories.svg".into(),
        "errors.png".into(),
        "errors.svg".into(),
    ];
    let records = read_csv(&out.join("frames.csv"))?;
    let frames = spec.trajectory.frames;
    let largest = spec.steps.iter().copied().max().unwrap_or(1);
    for method in &spec.methods {
        for &n in &spec.steps {
            let track: Vec<_> = records
                .iter()
                .filter(|r| r.method == method.name() && r.step == n)
                .collect();
            let expected: Vec<usize> = (0..frames).step_by(n).collect();
            let got: Vec<usize> = track.iter().map(|r| r.frame).collect();
            ensure!(
                expected.starts_with(&got) && !got.is_empty(),
                "{} N = {n}: frames {got:?} are not a prefix of {expected:?}",
                method.name()
            );
            if got.len() < expected.len() {
                let last = track[track.len() - 1];
                ensure!(
                    last.position_error_m > spec.lost_threshold_m
                        || last.stop.starts_with("diverged"),
                    "{} N = {n} stops early at frame {} without being lost",
                    method.name(),
                    last.frame
                );
            }
            if n == largest {
                files.push(format!(
                    "overlay-n{n}-{}-frame{}.png",
                    display_name(method.name()),
                    got[got.len() - 1]
                ));
            }
        }
    }
    ensure_files(out, &files)
}

/// Every file of `names` exists under `out` and is not empty.
fn ensure_files<S: AsRef<std::path::Path>>(
    out: &std::path::Path,
    names: &[S],
) -> anyhow::Result<()> {
    for name in names {
        let path = out.join(name);
        ensure!(
            path.metadata().map(|m| m.len() > 0).unwrap_or(false),
            "{} is missing or empty",
            path.display()
        );
    }
    Ok(())
}

/// Run the Fig. 3 protocol (or its quick subset) and check the result files; with
/// `domain`, also the domain curve below the paper's offsets and the basin along each
/// axis (`fixtures/protocol-fig3-domain.toml`, `fixtures/protocol-fig3-axes.toml`).
pub fn fig3(quick: bool, extras: bool, domain: bool, build: Build) -> anyhow::Result<()> {
    if domain {
        let root = project_root();
        for (protocol, out) in [
            ("protocol-fig3-domain.toml", "fig3-domain"),
            ("protocol-fig3-axes.toml", "fig3-axes"),
        ] {
            let protocol_path = root.join("fixtures").join(protocol);
            let out = root.join("results").join(out);
            run_protocol(&protocol_path, &out, false, build)?;
            check(&protocol_path, &out, false, false)?;
        }
    }
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
    run_protocol(&protocol_path, &out, extras, build)?;
    check(&protocol_path, &out, quick, extras)
}

/// Run the global localisation protocols (method `global`, beyond the paper): the
/// paper's poses at the corners of the box and at half of them, and starts drawn
/// uniformly inside it (or the quick subset), and check the result files.
pub fn global(quick: bool, build: Build) -> anyhow::Result<()> {
    let root = project_root();
    let runs: &[(&str, &str)] = if quick {
        &[("protocol-global-quick.toml", "global-quick")]
    } else {
        &[
            ("protocol-global.toml", "global"),
            ("protocol-global-uniform.toml", "global-uniform"),
        ]
    };
    for (protocol, out) in runs {
        let protocol_path = root.join("fixtures").join(protocol);
        let out = root.join("results").join(out);
        run_protocol(&protocol_path, &out, false, build)?;
        check(&protocol_path, &out, false, false)?;
    }
    Ok(())
}

/// `bench-conv run PROTOCOL --out OUT [--extras]`.
fn run_protocol(
    protocol_path: &std::path::Path,
    out: &std::path::Path,
    extras: bool,
    build: Build,
) -> anyhow::Result<()> {
    let mut args = vec![
        "run".as_ref(),
        protocol_path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    if extras {
        args.push("--extras".as_ref());
    }
    bench_conv(&args, build)
}

/// The result files exist, every method has one row per (desired, scale, initial)
/// pose, and in quick mode: PoVS fails from 8 m, Rule2 succeeds at least as often as
/// Rule0.
pub fn check(
    protocol_path: &std::path::Path,
    out: &std::path::Path,
    quick: bool,
    extras: bool,
) -> anyhow::Result<()> {
    ensure_files(out, &["runs.csv", "summary.md", "cdf.png", "cdf.svg"])?;
    let protocol = Protocol::load(protocol_path)?;
    if protocol.offsets.scales.len() > 1 {
        ensure_files(out, &["domain.csv", "domain.png", "domain.svg"])?;
    }
    let records = read_csv(&out.join("runs.csv"))?;
    let methods = protocol.method_configs(extras)?;
    let per_method =
        protocol.desired.len() * protocol.offsets.scales.len() * protocol.initial_indices().len();
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
    println!(
        "checked: {} is consistent with {}",
        out.display(),
        protocol_path.display()
    );
    Ok(())
}
