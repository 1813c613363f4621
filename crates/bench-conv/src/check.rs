//! Consistency checks of a results folder against the protocol or sequence file that
//! made it (`bench-conv check`, `bench-conv check-track`; what `cargo xtask reproduce-*`
//! runs after each experiment).

use std::path::Path;

use anyhow::{Context, bail, ensure};
use vvs::StopReason;

use crate::protocol::Protocol;
use crate::report::{read_csv, summarize};
use crate::tracking::{SequenceSpec, display_name};

/// The result files exist; every track aligned every frame of its step unless it was
/// lost, and a lost track ends on a frame beyond the threshold or diverged.
pub fn check_sequence(sequence: &Path, out: &Path) -> anyhow::Result<()> {
    let spec = SequenceSpec::load(sequence)?;
    let mut files = vec![
        "frames.csv".to_string(),
        "summary.md".into(),
        "trajectories.png".into(),
        "trajectories.svg".into(),
        "errors.png".into(),
        "errors.svg".into(),
        "rmse.png".into(),
        "rmse.svg".into(),
    ];
    let records = crate::tracking::read_csv(&out.join("frames.csv"))?;
    let frames = spec.trajectory.frames;
    let largest = spec.frame_steps.iter().copied().max().unwrap_or(1);
    for method in &spec.methods {
        for &n in &spec.frame_steps {
            let track: Vec<_> = records
                .iter()
                .filter(|r| r.method == *method && r.frame_step == n)
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
                        || matches!(last.stop, StopReason::Diverged(_)),
                    "{} N = {n} stops early at frame {} without being lost",
                    method.name(),
                    last.frame
                );
            }
            if n == largest {
                files.push(format!(
                    "overlay-n{n}-{}-frame{}.png",
                    display_name(*method),
                    got[got.len() - 1]
                ));
            }
        }
    }
    ensure_files(out, &files)
}

/// Every file of `names` exists under `out` and is not empty.
fn ensure_files<S: AsRef<Path>>(out: &Path, names: &[S]) -> anyhow::Result<()> {
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

/// The result files exist, every method has one row per (desired, scale, initial)
/// pose, and in quick mode: PoVS fails from 8 m, Rule2 succeeds at least as often as
/// Rule0.
pub fn check_protocol(
    protocol_path: &Path,
    out: &Path,
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
            .find(|s| s.config == m.name)
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
                .find(|s| s.config == name)
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
