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

/// The rows of an adaptive axes protocol: per method and axis, the scales run are the
/// first ones of the protocol, each with every run along the axis, every scale but the
/// last run has no failure, and the last one has a failure unless it is the largest.
fn check_adaptive(
    protocol: &Protocol,
    records: &[crate::report::RunRecord],
    methods: &[crate::protocol::MethodConfig],
    extras: bool,
) -> anyhow::Result<()> {
    let all = protocol.runs(extras)?;
    ensure!(
        records.windows(2).all(|w| w[0].run_id < w[1].run_id),
        "run ids are not increasing"
    );
    for r in records {
        let spec = all
            .get(r.run_id)
            .with_context(|| format!("run id {} is not a run of the protocol", r.run_id))?;
        ensure!(
            methods[spec.method].name == r.config
                && (spec.desired, spec.initial) == (r.desired, r.initial)
                && protocol.offsets.scales[spec.scale] == r.offset_scale,
            "run {}: its row does not match the protocol's run of that id",
            r.run_id
        );
        ensure!(
            r.success == (r.final_position_error_m < protocol.success_threshold_m),
            "run {}: success flag inconsistent with its error",
            r.run_id
        );
    }
    for m in methods {
        for axis in 0..6 {
            let per_scale = protocol.desired.len()
                * protocol
                    .initial_indices()
                    .iter()
                    .filter(|&&i| Protocol::axis_of(i) == axis)
                    .count();
            let mut open = true;
            for &scale in &protocol.offsets.scales {
                let runs: Vec<_> = records
                    .iter()
                    .filter(|r| {
                        r.config == m.name
                            && Protocol::axis_of(r.initial) == axis
                            && r.offset_scale == scale
                    })
                    .collect();
                if !open {
                    ensure!(
                        runs.is_empty(),
                        "{} axis {axis}: runs at scale {scale}, beyond a failed scale",
                        m.name
                    );
                    continue;
                }
                ensure!(
                    runs.len() == per_scale,
                    "{} axis {axis} scale {scale}: {} runs, expected {per_scale}",
                    m.name,
                    runs.len()
                );
                open = runs.iter().all(|r| r.success);
            }
        }
    }
    Ok(())
}

/// The result files exist, every method has one row per (desired, scale, initial)
/// pose (for an adaptive protocol, the runs its basins needed), and in quick mode: PoVS fails from 8 m, Rule2 succeeds at least as often as
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
    if protocol.offsets.adaptive {
        return check_adaptive(&protocol, &records, &methods, extras);
    }
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
