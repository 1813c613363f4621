//! The manifest of a results folder (`run.toml`: which runs of which protocol its
//! `runs.csv` holds) and what merged shards make of it: a complete or partial merge.

use std::path::Path;

use anyhow::{Context, bail};

use super::{RunRecord, write_atomically};

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
