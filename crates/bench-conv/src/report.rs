//! Results: the CSV of every run, its merge, the Markdown summary and the
//! cumulative-distribution plot of Fig. 3.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use vvs::{Method, StopReason};

/// One run's result (a CSV row).
#[derive(Clone, Debug, PartialEq)]
pub struct RunRecord {
    /// Global run index in the protocol.
    pub run_id: usize,
    /// Cloud name.
    pub scene: String,
    /// Desired pose index.
    pub desired: usize,
    /// Scale of the protocol's offsets for this run (1: as written).
    pub offset_scale: f64,
    /// Initial pose index (0–63, or 0–11 along the axes).
    pub initial: usize,
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// The method it ran.
    pub method: Method,
    /// Final position error, metres.
    pub final_position_error_m: f64,
    /// Final rotation error, degrees.
    pub final_rotation_error_deg: f64,
    /// Iterations of step 1.
    pub iterations_step1: usize,
    /// Iterations of step 2.
    pub iterations_step2: usize,
    /// Why the run stopped.
    pub stop: StopReason,
    /// Final λ.
    pub lambda: f32,
    /// Final cost.
    pub cost: f64,
    /// Wall time of the run's iterations, seconds: what the run takes alone (a step 1
    /// that Rule1 and Rule2 share counts in both).
    pub wall_time_s: f64,
    /// Final position error below the threshold.
    pub success: bool,
}

const HEADER: [&str; 16] = [
    "run_id",
    "scene",
    "desired",
    "offset_scale",
    "initial",
    "config",
    "method",
    "final_position_error_m",
    "final_rotation_error_deg",
    "iterations_step1",
    "iterations_step2",
    "stop",
    "lambda",
    "cost",
    "wall_time_s",
    "success",
];

/// The file beside a `runs.csv` that says which runs of which protocol it holds, so
/// that `merge` can tell a complete merge from a partial one.
pub const MANIFEST: &str = "run.toml";

/// What a results folder of `bench-conv run` holds ([`MANIFEST`]).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunManifest {
    /// The protocol's name.
    pub protocol: String,
    /// A fingerprint of the protocol file's bytes ([`fingerprint`]): two protocol
    /// files of one name are told apart.
    #[serde(default)]
    pub protocol_hash: Option<String>,
    /// Whether its extra methods ran.
    pub extras: bool,
    /// Runs of the whole protocol (every shard).
    pub total_runs: usize,
    /// Every run id of the protocol is below this (its run list's length; more than
    /// `total_runs` for an adaptive protocol, whose skipped runs leave gaps).
    #[serde(default)]
    pub run_id_limit: Option<usize>,
    /// This shard `[i, n]`, or none for the whole protocol.
    pub shard: Option<[usize; 2]>,
    /// Rows of the `runs.csv` beside it.
    pub runs: usize,
}

/// A 64-bit FNV-1a fingerprint of `bytes` without their carriage returns (a file
/// checked out with CRLF or LF line ends is one file), as 16 hexadecimal digits (to
/// tell files apart, not to resist anyone).
pub fn fingerprint(bytes: &[u8]) -> String {
    let hash = bytes
        .iter()
        .filter(|&&b| b != b'\r')
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
    format!("{hash:016x}")
}

/// Every merged run is a run of the protocol its manifests describe: a run id at or
/// past their `run_id_limit` is an error (known only when every CSV has a manifest
/// that states it).
pub fn check_run_ids(
    records: &[RunRecord],
    manifests: &[Option<RunManifest>],
) -> anyhow::Result<()> {
    let Some(Some(first)) = manifests.first() else {
        return Ok(());
    };
    let Some(limit) = first.run_id_limit else {
        return Ok(());
    };
    if manifests
        .iter()
        .any(|m| m.as_ref().is_none_or(|m| m.run_id_limit != Some(limit)))
    {
        return Ok(());
    }
    if let Some(r) = records.iter().find(|r| r.run_id >= limit) {
        bail!(
            "run {} is not a run of protocol `{}`, whose run ids go from 0 to {}",
            r.run_id,
            first.protocol,
            limit.saturating_sub(1)
        );
    }
    Ok(())
}

/// Write the manifest of the results folder `out`.
pub fn write_manifest(out: &Path, manifest: &RunManifest) -> anyhow::Result<()> {
    let text = toml::to_string(manifest).context("encoding the run manifest")?;
    write_atomically(&out.join(MANIFEST), text.as_bytes())
}

/// The manifest beside the CSV file `csv`, if there is one.
pub fn read_manifest(csv: &Path) -> anyhow::Result<Option<RunManifest>> {
    let path = csv.with_file_name(MANIFEST);
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text)
        .map(Some)
        .with_context(|| format!("parsing {}", path.display()))
}

/// Whether merged shards make the whole protocol.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Completeness {
    /// Every run of the protocol (`shards` shards).
    Complete {
        /// The protocol's name.
        protocol: String,
        /// Its runs.
        runs: usize,
    },
    /// Some shards are missing.
    Partial {
        /// The protocol's name.
        protocol: String,
        /// Runs merged.
        runs: usize,
        /// Runs of the whole protocol.
        total_runs: usize,
        /// Shard count, and the shards missing from the merge.
        shards: usize,
        /// Shards not merged.
        missing: Vec<usize>,
    },
    /// Some CSV files have no manifest beside them.
    Unknown,
}

impl Completeness {
    /// One Markdown line for the top of the summary.
    pub fn markdown(&self) -> String {
        match self {
            Completeness::Complete { protocol, runs } => {
                format!("Complete: all {runs} runs of protocol `{protocol}`.")
            }
            Completeness::Partial {
                protocol,
                runs,
                total_runs,
                shards,
                missing,
            } => {
                let list: Vec<String> = missing.iter().map(|i| format!("{i}/{shards}")).collect();
                format!(
                    "**PARTIAL MERGE: {runs} of the {total_runs} runs of protocol `{protocol}`; \
                     missing shards {}.** The statistics below are not the protocol's.",
                    list.join(", ")
                )
            }
            Completeness::Unknown => "Completeness unknown: some CSV files have no `run.toml` \
                 beside them (written by `bench-conv run`)."
                .into(),
        }
    }
}

/// Check merged shards against their manifests: every CSV must come from the same
/// protocol, extras and shard count; a shard given twice is an error; shards missing
/// make the merge [`Completeness::Partial`].
pub fn completeness(
    manifests: &[Option<RunManifest>],
    merged_runs: usize,
) -> anyhow::Result<Completeness> {
    let Some(all) = manifests.iter().cloned().collect::<Option<Vec<_>>>() else {
        return Ok(Completeness::Unknown);
    };
    let Some(first) = all.first() else {
        return Ok(Completeness::Unknown);
    };
    let count = first.shard.map_or(1, |[_, n]| n);
    // The manifests are files a user can edit: every count is checked before it sizes
    // anything.
    for m in &all {
        if m.runs > m.total_runs {
            bail!(
                "a manifest says its CSV holds {} runs of a {}-run protocol",
                m.runs,
                m.total_runs
            );
        }
        if let Some([i, n]) = m.shard
            && !(i < n && n <= m.total_runs.max(1))
        {
            bail!(
                "a manifest names shard {i}/{n} of a {}-run protocol: a shard i/n needs \
                 i < n <= the number of runs",
                m.total_runs
            );
        }
    }
    let mut seen = vec![false; count];
    for m in &all {
        if (&m.protocol, m.extras, m.total_runs)
            != (&first.protocol, first.extras, first.total_runs)
            || m.shard.map_or(1, |[_, n]| n) != count
        {
            bail!(
                "the CSV files come from different runs: protocol `{}` (extras {}, {} runs, {} shards) \
                 and `{}` (extras {}, {} runs, {} shards)",
                first.protocol,
                first.extras,
                first.total_runs,
                count,
                m.protocol,
                m.extras,
                m.total_runs,
                m.shard.map_or(1, |[_, n]| n)
            );
        }
        if let (Some(a), Some(b)) = (&first.protocol_hash, &m.protocol_hash)
            && a != b
        {
            bail!(
                "the CSV files come from two different protocol files, both named `{}` \
                 (fingerprints {a} and {b})",
                m.protocol
            );
        }
        let i = m.shard.map_or(0, |[i, _]| i);
        if seen[i] {
            bail!("shard {i}/{count} is given twice");
        }
        seen[i] = true;
    }
    let missing: Vec<usize> = (0..count).filter(|&i| !seen[i]).collect();
    if missing.is_empty() && merged_runs == first.total_runs {
        Ok(Completeness::Complete {
            protocol: first.protocol.clone(),
            runs: merged_runs,
        })
    } else {
        Ok(Completeness::Partial {
            protocol: first.protocol.clone(),
            runs: merged_runs,
            total_runs: first.total_runs,
            shards: count,
            missing,
        })
    }
}

/// A protocol run's success: its final position error below the threshold, and a
/// finite cost (a run whose cost is not finite never succeeds).
pub fn is_success(position_error_m: f64, cost: f64, threshold_m: f64) -> bool {
    position_error_m < threshold_m && cost.is_finite()
}

/// The file that marks a results folder whose writing has not finished.
pub const INCOMPLETE_MARKER: &str = "INCOMPLETE";

/// The lock file of a results folder being written ([`begin_results`]).
pub const LOCK_FILE: &str = ".lock";

/// What a results folder may hold from an earlier run of any command: cleared by
/// [`begin_results`] with `force`. Files named `acquired-n*-frame*.png` (tracking's
/// last acquired frames) and the folder `pictures/` (the real benchmark's) go too.
pub const RESULT_FILES: &[&str] = &[
    "summary.md",
    "runs.csv",
    MANIFEST,
    "domain.csv",
    "domain.md",
    "domain.png",
    "domain.svg",
    "cdf.png",
    "cdf.svg",
    "frames.csv",
    "rmse.png",
    "rmse.svg",
    "errors.png",
    "errors.svg",
    "tracking.csv",
    "tracking.png",
    "tracking.svg",
    "poses.csv",
    INCOMPLETE_MARKER,
];

/// A results folder held by one run: its [`LOCK_FILE`] names the process, and goes
/// when this is dropped (at the end of the run, or when it fails).
#[derive(Debug)]
#[must_use = "the folder is unlocked when this is dropped"]
pub struct ResultsLock {
    path: PathBuf,
}

impl Drop for ResultsLock {
    fn drop(&mut self) {
        // Nothing to do if it is already gone.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether the process that wrote the lock file `path` still runs (on Linux, from
/// `/proc`; elsewhere a lock is taken as held).
fn lock_is_held(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return true;
    };
    match text.trim().parse::<u32>() {
        Ok(pid) if Path::new("/proc/self").exists() => {
            pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists()
        }
        Ok(_) => true,
        // Unreadable: written by something else, or half-written; held.
        Err(_) => true,
    }
}

/// Prepare the results folder `out` before any work, so that a bad `--out` fails at
/// once, two runs never write one folder, earlier results are never replaced without
/// being asked, and an interrupted run never leaves a folder that looks complete:
///
/// - the folder is created (an existing file there is an error);
/// - a folder another running process writes (its [`LOCK_FILE`]) is refused; a lock
///   left by a process that no longer runs is taken over;
/// - a folder holding results of an earlier run ([`RESULT_FILES`]) is refused unless
///   `force`, which removes them (other files are left alone);
/// - [`INCOMPLETE_MARKER`] is written until [`finish_results`].
pub fn begin_results(out: &Path, force: bool) -> anyhow::Result<ResultsLock> {
    if out.exists() && !out.is_dir() {
        bail!("{} exists and is not a folder", out.display());
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let lock_path = out.join(LOCK_FILE);
    let lock = loop {
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&lock_path)
        {
            Ok(mut file) => {
                use std::io::Write;
                let lock = ResultsLock {
                    path: lock_path.clone(),
                };
                writeln!(file, "{}", std::process::id())
                    .with_context(|| format!("writing {}", lock_path.display()))?;
                break lock;
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                if lock_is_held(&lock_path) {
                    bail!(
                        "another run is writing its results to {} (its lock file {}; remove it \
                         if no such run is going on)",
                        out.display(),
                        lock_path.display()
                    );
                }
                std::fs::remove_file(&lock_path)
                    .with_context(|| format!("removing the stale {}", lock_path.display()))?;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("creating {}", lock_path.display()));
            }
        }
    };
    let mut earlier: Vec<PathBuf> = Vec::new();
    for entry in std::fs::read_dir(out).with_context(|| format!("reading {}", out.display()))? {
        let entry = entry.with_context(|| format!("reading {}", out.display()))?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let ours = RESULT_FILES.contains(&name.as_ref())
            || name == "pictures"
            || (name.starts_with("acquired-n") && name.ends_with(".png"));
        if ours {
            earlier.push(entry.path());
        }
    }
    earlier.sort();
    if !earlier.is_empty() {
        if !force {
            let names: Vec<String> = earlier
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            bail!(
                "{} holds the results of an earlier run ({}): give --force to replace them, \
                 or another --out",
                out.display(),
                names.join(", ")
            );
        }
        for path in &earlier {
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(path)
            } else {
                std::fs::remove_file(path)
            };
            removed.with_context(|| format!("removing the earlier {}", path.display()))?;
        }
    }
    write_atomically(
        &out.join(INCOMPLETE_MARKER),
        b"These results are being written, or their writing was interrupted: do not use them.\n",
    )?;
    Ok(lock)
}

/// Mark the results folder `out` complete (every file written).
pub fn finish_results(out: &Path) -> anyhow::Result<()> {
    let marker = out.join(INCOMPLETE_MARKER);
    std::fs::remove_file(&marker).with_context(|| format!("removing {}", marker.display()))
}

/// Write `bytes` to `path` through a temporary file in the same folder and a rename,
/// so that `path` is never left half-written.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
}

/// Write records as CSV (RFC 4180 quoting through the `csv` crate, so that names with
/// commas or quotes survive; numbers in the formats below, so that two runs compare
/// as text), atomically.
pub fn write_csv(path: &Path, records: &[RunRecord]) -> anyhow::Result<()> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer.write_record(HEADER)?;
    for r in records {
        writer.write_record([
            r.run_id.to_string(),
            r.scene.clone(),
            r.desired.to_string(),
            r.offset_scale.to_string(),
            r.initial.to_string(),
            r.config.clone(),
            r.method.to_string(),
            format!("{:.6e}", r.final_position_error_m),
            format!("{:.6e}", r.final_rotation_error_deg),
            r.iterations_step1.to_string(),
            r.iterations_step2.to_string(),
            r.stop.to_string(),
            r.lambda.to_string(),
            format!("{:.6e}", r.cost),
            format!("{:.3}", r.wall_time_s),
            r.success.to_string(),
        ])?;
    }
    let bytes = writer.into_inner().context("encoding the runs CSV")?;
    write_atomically(path, &bytes)
}

/// The rows of a CSV file whose header is exactly `header`, each with its line number
/// in the file (as the `csv` crate counts them: quoted line breaks and blank lines
/// included) and exactly `header.len()` fields; `what` names the kind of file in
/// errors.
pub(crate) fn csv_rows(
    path: &Path,
    header: &[&str],
    what: &str,
) -> anyhow::Result<Vec<(u64, csv::StringRecord)>> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_path(path)
        .with_context(|| format!("reading {}", path.display()))?;
    let found = reader
        .headers()
        .with_context(|| format!("reading {}", path.display()))?
        .clone();
    if found.iter().ne(header.iter().copied()) {
        bail!("{}: not a {what} (unexpected header)", path.display());
    }
    let mut rows = Vec::new();
    for row in reader.records() {
        let row = row.with_context(|| format!("reading {}", path.display()))?;
        let line = row.position().map_or(0, |p| p.line());
        if row.len() != header.len() {
            bail!(
                "{}:{line}: {} fields, expected {}",
                path.display(),
                row.len(),
                header.len()
            );
        }
        rows.push((line, row));
    }
    Ok(rows)
}

/// Read a CSV written by [`write_csv`]. Errors name the file, line and field; errors
/// that are NaN, infinite or negative, and an offset scale that is not positive, are
/// refused (no statistic is computed from them).
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<RunRecord>> {
    if path.with_file_name(INCOMPLETE_MARKER).exists() {
        bail!(
            "{}: its folder is marked {INCOMPLETE_MARKER} (its run was interrupted or is \
             still writing)",
            path.display()
        );
    }
    let mut records = Vec::new();
    for (line, f) in csv_rows(path, &HEADER, "bench-conv runs CSV")? {
        let field = |i: usize| &f[i];
        let ctx = |i: usize| format!("{}:{line}: field {}", path.display(), HEADER[i]);
        macro_rules! parse {
            ($i:expr) => {
                field($i)
                    .parse()
                    .with_context(|| format!("{}: `{}`", ctx($i), field($i)))?
            };
        }
        let record = RunRecord {
            run_id: parse!(0),
            scene: field(1).to_string(),
            desired: parse!(2),
            offset_scale: parse!(3),
            initial: parse!(4),
            config: field(5).to_string(),
            method: parse!(6),
            final_position_error_m: parse!(7),
            final_rotation_error_deg: parse!(8),
            iterations_step1: parse!(9),
            iterations_step2: parse!(10),
            stop: parse!(11),
            lambda: parse!(12),
            cost: parse!(13),
            wall_time_s: parse!(14),
            success: parse!(15),
        };
        for (i, value) in [
            (7, record.final_position_error_m),
            (8, record.final_rotation_error_deg),
            (14, record.wall_time_s),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                bail!("{}: {value} is not a finite, non-negative number", ctx(i));
            }
        }
        if !(record.offset_scale.is_finite() && record.offset_scale > 0.0) {
            bail!(
                "{}: {} is not a positive scale",
                ctx(3),
                record.offset_scale
            );
        }
        records.push(record);
    }
    Ok(records)
}

/// Decide every record's success anew from its final position error and
/// `threshold_m` (finite, > 0), as `merge --threshold-m` does.
pub fn apply_threshold(records: &mut [RunRecord], threshold_m: f64) -> anyhow::Result<()> {
    if !(threshold_m > 0.0 && threshold_m.is_finite()) {
        bail!("the success threshold must be finite and > 0, got {threshold_m}");
    }
    for r in records {
        r.success = is_success(r.final_position_error_m, r.cost, threshold_m);
    }
    Ok(())
}

/// Merge shards: concatenate, sort by run id, refuse duplicates.
pub fn merge(parts: Vec<Vec<RunRecord>>) -> anyhow::Result<Vec<RunRecord>> {
    let mut all: Vec<RunRecord> = parts.into_iter().flatten().collect();
    all.sort_by_key(|r| r.run_id);
    if let Some(w) = all.windows(2).find(|w| w[0].run_id == w[1].run_id) {
        bail!("run {} appears twice: overlapping shards", w[0].run_id);
    }
    Ok(all)
}

/// The paper's success rate (§3.2) of one of its configurations, by method name
/// (`povs`, `rule0/convolved`, `rule2/paper`, …); `None` for the variants beyond it.
pub fn paper_success_rate(method: &str) -> Option<f64> {
    // Only the paper's configurations ("povs", "rule2/convolved", "rule1/paper", …),
    // not the variants beyond it ("rule2/convolved+lm").
    if let Some((_, jacobian)) = method.split_once('/') {
        let known = ["convolved", "paper"].contains(&jacobian)
            || jacobian
                .strip_prefix("paper-margin")
                .is_some_and(|m| m.parse::<f32>().is_ok());
        if !known {
            return None;
        }
    }
    match method.split('/').next()? {
        "rule2" => Some(97.0),
        "rule1" => Some(78.0),
        "rule0" => Some(70.0),
        "povs" => Some(0.0),
        _ => None,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Per-method statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSummary {
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// Runs.
    pub runs: usize,
    /// Successful runs.
    pub successes: usize,
    /// Median final position error, metres.
    pub median_position_error_m: f64,
    /// Median final rotation error, degrees.
    pub median_rotation_error_deg: f64,
    /// Median total iterations.
    pub median_iterations: f64,
    /// Median wall time per run, seconds.
    pub median_wall_time_s: f64,
    /// Total wall time of the method's runs, seconds.
    pub total_wall_time_s: f64,
}

/// Statistics of every method, by method name (a stable order whatever the shard).
pub fn summarize(records: &[RunRecord]) -> Vec<MethodSummary> {
    let mut groups: BTreeMap<&str, Vec<&RunRecord>> = BTreeMap::new();
    for r in records {
        groups.entry(&r.config).or_default().push(r);
    }
    groups
        .into_iter()
        .map(|(m, g)| MethodSummary {
            config: m.to_string(),
            runs: g.len(),
            successes: g.iter().filter(|r| r.success).count(),
            median_position_error_m: median(g.iter().map(|r| r.final_position_error_m).collect()),
            median_rotation_error_deg: median(
                g.iter().map(|r| r.final_rotation_error_deg).collect(),
            ),
            median_iterations: median(
                g.iter()
                    .map(|r| (r.iterations_step1 + r.iterations_step2) as f64)
                    .collect(),
            ),
            median_wall_time_s: median(g.iter().map(|r| r.wall_time_s).collect()),
            total_wall_time_s: g.iter().map(|r| r.wall_time_s).sum(),
        })
        .collect()
}

/// The Markdown summary table, with the paper's figures beside ours.
pub fn summary_markdown(
    title: &str,
    records: &[RunRecord],
    threshold_m: f64,
    wall_time_s: Option<f64>,
) -> String {
    let mut s = format!("# {title}\n\n");
    let _ = writeln!(
        s,
        "Success: final position error < {:.0} cm. {} runs.{}\n",
        threshold_m * 100.0,
        records.len(),
        wall_time_s.map_or(String::new(), |t| format!(
            " Wall time {:.1} min.",
            t / 60.0
        ))
    );
    s.push_str("| method | runs | success | paper | median position error | median rotation error | median iterations | median time per run |\n");
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for m in summarize(records) {
        let paper =
            paper_success_rate(&m.config).map_or("—".to_string(), |p| format!("{p:.0} %"));
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} % ({}) | {} | {:.4} m | {:.3}° | {:.0} | {:.1} s |",
            m.config,
            m.runs,
            100.0 * m.successes as f64 / m.runs.max(1) as f64,
            m.successes,
            paper,
            m.median_position_error_m,
            m.median_rotation_error_deg,
            m.median_iterations,
            m.median_wall_time_s
        );
    }
    s.push_str("\nThe paper's rates (§3.2) are for its own scans of four streets and its own camera; see the project's notes for why ours differ.\n");
    s
}

/// Plot the cumulative distribution of the final position errors per method (log
/// error axis, threshold marked), as PNG and SVG.
pub fn plot_cdf(
    records: &[RunRecord],
    threshold_m: f64,
    png: &Path,
    svg: &Path,
) -> anyhow::Result<()> {
    let summaries = summarize(records);
    let series: Vec<(String, Vec<f64>)> = summaries
        .iter()
        .map(|m| {
            let errors: Vec<f64> = records
                .iter()
                .filter(|r| r.config == m.config)
                .map(|r| r.final_position_error_m)
                .collect();
            // One decimal, so that 3 and 5 successes of 448 (0.7 and 1.1 %) read apart.
            let label = format!(
                "{} ({:.1} %, {}/{})",
                m.config,
                100.0 * m.successes as f64 / errors.len().max(1) as f64,
                m.successes,
                errors.len()
            );
            (label, errors)
        })
        .collect();
    plot_error_cdf(
        "Cumulative distribution of final position errors",
        [1e-4, 100.0],
        &series,
        threshold_m,
        png,
        svg,
    )
}

/// The cumulative distribution of each series' errors (label, final position errors
/// in metres, clamped to `range_m`), on a log scale, with a line at `threshold_m`;
/// written as PNG and SVG.
pub(crate) fn plot_error_cdf(
    title: &str,
    range_m: [f64; 2],
    series: &[(String, Vec<f64>)],
    threshold_m: f64,
    png: &Path,
    svg: &Path,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        title: &str,
        [lo, hi]: [f64; 2],
        series: &[(String, Vec<f64>)],
        threshold_m: f64,
    ) -> anyhow::Result<()> {
        root.fill(&WHITE).map_err(crate::plot::error)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d((lo..hi).log_scale(), 0.0f64..100.0)
            .map_err(crate::plot::error)?;
        chart
            .configure_mesh()
            .x_desc("final position error (m)")
            .y_desc("runs (%)")
            .draw()
            .map_err(crate::plot::error)?;
        crate::plot::line(
            &mut chart,
            vec![(threshold_m, 0.0), (threshold_m, 100.0)],
            format!("{:.0} cm threshold", threshold_m * 100.0),
            BLACK.stroke_width(1),
        )?;
        for (i, (label, errors)) in series.iter().enumerate() {
            let mut errors: Vec<f64> = errors.iter().map(|e| e.clamp(lo, hi)).collect();
            errors.sort_by(f64::total_cmp);
            let n = errors.len() as f64;
            let mut points = vec![(lo, 0.0)];
            for (k, e) in errors.iter().enumerate() {
                points.push((*e, 100.0 * k as f64 / n));
                points.push((*e, 100.0 * (k + 1) as f64 / n));
            }
            points.push((hi, 100.0));
            let color = Palette99::pick(i).to_rgba();
            crate::plot::line(&mut chart, points, label.clone(), color.stroke_width(2))?;
        }
        crate::plot::finish(&mut chart, &root)
    }
    let range = [range_m[0], range_m[1]];
    draw(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        title,
        range,
        series,
        threshold_m,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw(
        SVGBackend::new(svg, (900, 600)).into_drawing_area(),
        title,
        range,
        series,
        threshold_m,
    )
    .with_context(|| format!("plotting {}", svg.display()))
}

/// The success of one method at one offset scale: a point of the domain curve.
#[derive(Clone, Debug, PartialEq)]
pub struct DomainPoint {
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// Scale of the protocol's offsets.
    pub offset_scale: f64,
    /// Runs at this scale.
    pub runs: usize,
    /// Successful runs.
    pub successes: usize,
}

impl DomainPoint {
    /// Success rate, percent.
    pub fn rate(&self) -> f64 {
        100.0 * self.successes as f64 / self.runs.max(1) as f64
    }
}

/// The domain curve: success by method and offset scale (methods by name, scales
/// increasing).
pub fn domain(records: &[RunRecord]) -> Vec<DomainPoint> {
    let mut groups: BTreeMap<(&str, u64), (f64, usize, usize)> = BTreeMap::new();
    for r in records {
        // Scales are positive, so their bits order as the values.
        let entry = groups
            .entry((&r.config, r.offset_scale.to_bits()))
            .or_insert((r.offset_scale, 0, 0));
        entry.1 += 1;
        entry.2 += usize::from(r.success);
    }
    groups
        .into_iter()
        .map(
            |((method, _), (offset_scale, runs, successes))| DomainPoint {
                config: method.to_string(),
                offset_scale,
                runs,
                successes,
            },
        )
        .collect()
}

fn scales_of(points: &[DomainPoint]) -> Vec<f64> {
    let mut scales: Vec<f64> = points.iter().map(|p| p.offset_scale).collect();
    scales.sort_by(f64::total_cmp);
    scales.dedup();
    scales
}

/// The domain curve as a Markdown table: a row per method, a column per scale.
pub fn domain_markdown(points: &[DomainPoint]) -> String {
    let scales = scales_of(points);
    let mut s = String::from("| method |");
    for scale in &scales {
        let _ = write!(s, " s = {scale} |");
    }
    s.push_str("\n|---|");
    s.push_str(&"---:|".repeat(scales.len()));
    s.push('\n');
    let mut methods: Vec<&str> = points.iter().map(|p| p.config.as_str()).collect();
    methods.dedup();
    for method in methods {
        let _ = write!(s, "| {method} |");
        for scale in &scales {
            match points
                .iter()
                .find(|p| p.config == method && p.offset_scale == *scale)
            {
                Some(p) => {
                    let _ = write!(s, " {:.1} % ({}/{}) |", p.rate(), p.successes, p.runs);
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s
}

/// Write the domain curve as CSV (`config,offset_scale,runs,successes,success_percent`).
pub fn write_domain_csv(path: &Path, points: &[DomainPoint]) -> anyhow::Result<()> {
    let mut text = String::from("config,offset_scale,runs,successes,success_percent\n");
    for p in points {
        let _ = writeln!(
            text,
            "{},{},{},{},{:.2}",
            p.config,
            p.offset_scale,
            p.runs,
            p.successes,
            p.rate()
        );
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// Plot the domain curve (success against offset scale, a line per method) as PNG and
/// SVG.
pub fn plot_domain(points: &[DomainPoint], png: &Path, svg: &Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    draw_domain(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        points,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw_domain(SVGBackend::new(svg, (900, 600)).into_drawing_area(), points)
        .with_context(|| format!("plotting {}", svg.display()))?;
    Ok(())
}

fn draw_domain<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    points: &[DomainPoint],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let largest = scales_of(points).last().copied().unwrap_or(1.0);
    root.fill(&WHITE).map_err(crate::plot::error)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Convergence domain: success against the scale of the offsets",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0f64..largest * 1.05, 0.0f64..105.0)
        .map_err(crate::plot::error)?;
    chart
        .configure_mesh()
        .x_desc("offset scale s (1: the protocol's offsets)")
        .y_desc("runs converged (%)")
        .draw()
        .map_err(crate::plot::error)?;
    let mut methods: Vec<&str> = points.iter().map(|p| p.config.as_str()).collect();
    methods.dedup();
    for (i, method) in methods.into_iter().enumerate() {
        let line: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.config == method)
            .map(|p| (p.offset_scale, p.rate()))
            .collect();
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, color.filled())),
            )
            .map_err(crate::plot::error)?;
        crate::plot::line(&mut chart, line, method, color.stroke_width(2))?;
    }
    crate::plot::finish(&mut chart, &root)
}

/// The convergence domain from finished runs, into `out` (created): the curve of every
/// method over the runs of `curve` (each element the rows of one results folder;
/// `domain.csv`, `domain.png`, `domain.svg`) and, from an axes protocol and its rows,
/// the basin along each axis; both as Markdown in `domain.md`, which is returned.
/// `force`: as [`begin_results`]'s.
pub fn write_domain(
    out: &Path,
    curve: &[Vec<RunRecord>],
    axes: Option<&(crate::protocol::Protocol, Vec<RunRecord>)>,
    force: bool,
) -> anyhow::Result<String> {
    let records: Vec<RunRecord> = curve.iter().flatten().cloned().collect();
    ensure!(!records.is_empty(), "the results folders hold no run");
    let points = domain(&records);
    let _lock = begin_results(out, force)?;
    let mut text = String::from(
        "# The convergence domain\n\nSuccess (final position error below the protocol's \
         threshold) against the scale s of every offset of the protocol (s = 1: the \
         paper's offsets); the runs behind each cell are given beside its rate.\n\n",
    );
    text.push_str(&domain_markdown(&points));
    write_domain_csv(&out.join("domain.csv"), &points)?;
    plot_domain(&points, &out.join("domain.png"), &out.join("domain.svg"))?;
    if let Some((protocol, rows)) = axes {
        ensure!(
            protocol.offsets.sampling == crate::protocol::Sampling::Axes,
            "the axes protocol `{}` does not sample along the axes (sampling = \"axes\")",
            protocol.name
        );
        let (t, r) = (
            protocol.offsets.translation_m,
            protocol.offsets.rotation_deg,
        );
        let _ = write!(
            text,
            "\n## The basin along each axis alone\n\nProtocol `{}`: one offset at a time, \
             both signs, every desired pose, at scales {:?} of the magnitudes below; the \
             largest offset from which every run along the axis converged, at that and \
             every smaller scale ({} runs{}).\n\n",
            protocol.name,
            protocol.offsets.scales,
            rows.len(),
            if protocol.offsets.adaptive {
                "; adaptive: a method stops along an axis after its first failing scale"
            } else {
                ""
            }
        );
        let top = protocol.offsets.scales.iter().copied().fold(0.0, f64::max);
        text.push_str(&axis_basins_markdown(
            &axis_basins(rows),
            [t[0], t[1], t[2], r[0], r[1], r[2]],
            top,
        ));
    }
    write_atomically(&out.join("domain.md"), text.as_bytes())?;
    finish_results(out)?;
    Ok(text)
}

/// The basin along each axis (protocols with `sampling = "axes"`): per method and
/// axis, the largest scale `s` such that every run along that axis (both signs, every
/// desired pose) converged at `s` and at every smaller scale run (a scale with no run
/// along the axis ends the basin); 0 if none, `None` for an axis with no run at all.
pub fn axis_basins(records: &[RunRecord]) -> Vec<(String, [Option<f64>; 6])> {
    let mut methods: Vec<&str> = records.iter().map(|r| r.config.as_str()).collect();
    methods.sort_unstable();
    methods.dedup();
    let mut scales: Vec<f64> = records.iter().map(|r| r.offset_scale).collect();
    scales.sort_by(f64::total_cmp);
    scales.dedup();
    let along = |r: &RunRecord, method: &str, axis: usize| {
        r.config == method && crate::protocol::Protocol::axis_of(r.initial) == axis
    };
    methods
        .into_iter()
        .map(|method| {
            let basin = std::array::from_fn(|axis| {
                if !records.iter().any(|r| along(r, method, axis)) {
                    return None;
                }
                let mut largest = 0.0;
                for &scale in &scales {
                    let mut runs = records
                        .iter()
                        .filter(|r| along(r, method, axis) && r.offset_scale == scale);
                    let mut any = false;
                    let all = runs.all(|r| {
                        any = true;
                        r.success
                    });
                    if !(any && all) {
                        break;
                    }
                    largest = scale;
                }
                Some(largest)
            });
            (method.to_string(), basin)
        })
        .collect()
}

/// [`axis_basins`] as a Markdown table in metres and degrees (`magnitudes`: the
/// protocol's offsets at scale 1, `tX, tY, tZ` in metres then `θwX, θwY, θwZ` in
/// degrees). A basin that reaches `top_scale`, the largest scale of the protocol, is
/// written `≥` it (the ladder found no end); an axis with no run `—`.
pub fn axis_basins_markdown(
    basins: &[(String, [Option<f64>; 6])],
    magnitudes: [f64; 6],
    top_scale: f64,
) -> String {
    let mut s = String::from(
        "| method | tX (m) | tY (m) | tZ (m) | θwX (°) | θwY (°) | θwZ (°) |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for (method, basin) in basins {
        let _ = write!(s, "| {method} |");
        for k in 0..6 {
            match basin[k] {
                Some(scale) => {
                    let at_least = if scale >= top_scale { "≥ " } else { "" };
                    let _ = write!(s, " {at_least}{:.2} |", scale * magnitudes[k]);
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s
}
