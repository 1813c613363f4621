//! The runs CSV (`runs.csv`): one row per run of a protocol, its success, and the merge
//! of the shards' files.

use std::path::Path;

use anyhow::bail;
use serde::{Deserialize, Deserializer, Serialize};
use vvs::{Method, StopReason};

use super::INCOMPLETE_MARKER;
use crate::csv_io;

/// One run's result: a row of `runs.csv`, whose columns are these fields in this order,
/// numbers in the formats below so that two runs compare as text.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Global run index in the protocol.
    pub run_id: usize,
    /// Cloud name.
    pub scene: String,
    /// Desired pose index.
    pub desired: usize,
    /// Scale of the protocol's offsets for this run (1: as written).
    #[serde(serialize_with = "csv_io::display", deserialize_with = "positive")]
    pub offset_scale: f64,
    /// Initial pose index (0–63, or 0–11 along the axes).
    pub initial: usize,
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// The method it ran.
    #[serde(
        serialize_with = "csv_io::display",
        deserialize_with = "csv_io::from_str"
    )]
    pub method: Method,
    /// Final position error, metres.
    #[serde(
        serialize_with = "csv_io::scientific::<6, _>",
        deserialize_with = "finite_non_negative"
    )]
    pub final_position_error_m: f64,
    /// Final rotation error, degrees.
    #[serde(
        serialize_with = "csv_io::scientific::<6, _>",
        deserialize_with = "finite_non_negative"
    )]
    pub final_rotation_error_deg: f64,
    /// Iterations of step 1.
    pub iterations_step1: usize,
    /// Iterations of step 2.
    pub iterations_step2: usize,
    /// Why the run stopped.
    #[serde(
        serialize_with = "csv_io::display",
        deserialize_with = "csv_io::from_str"
    )]
    pub stop: StopReason,
    /// Final λ.
    #[serde(serialize_with = "csv_io::display")]
    pub lambda: f32,
    /// Final cost.
    #[serde(serialize_with = "csv_io::scientific::<6, _>")]
    pub cost: f64,
    /// Wall time of the run's iterations, seconds: what the run takes alone (a step 1
    /// that Rule1 and Rule2 share counts in both).
    #[serde(
        serialize_with = "csv_io::fixed::<3, _>",
        deserialize_with = "finite_non_negative"
    )]
    pub wall_time_s: f64,
    /// Final position error below the threshold.
    pub success: bool,
}

/// An error or a time: finite and >= 0 (no statistic is computed from anything else).
fn finite_non_negative<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    let value = f64::deserialize(deserializer)?;
    if !(value.is_finite() && value >= 0.0) {
        return Err(serde::de::Error::custom(format_args!(
            "{value} is not a finite, non-negative number"
        )));
    }
    Ok(value)
}

/// An offset scale: finite and > 0.
fn positive<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    let value = f64::deserialize(deserializer)?;
    if !(value.is_finite() && value > 0.0) {
        return Err(serde::de::Error::custom(format_args!(
            "{value} is not a positive scale"
        )));
    }
    Ok(value)
}

/// A protocol run's success: its final position error below the threshold, and a
/// finite cost (a run whose cost is not finite never succeeds).
pub fn is_success(position_error_m: f64, cost: f64, threshold_m: f64) -> bool {
    position_error_m < threshold_m && cost.is_finite()
}

/// Write records as `runs.csv` ([`csv_io::write_records`]: RFC 4180 quoting, so that
/// names with commas or quotes survive; atomically).
pub fn write_csv(path: &Path, records: &[RunRecord]) -> anyhow::Result<()> {
    csv_io::write_records(path, records)
}

/// Read a CSV written by [`write_csv`]. Errors name the file, line and field; errors
/// that are NaN, infinite or negative, and an offset scale that is not positive, are
/// refused (no statistic is computed from them), and so is a CSV whose folder is
/// marked [`INCOMPLETE_MARKER`].
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<RunRecord>> {
    if path.with_file_name(INCOMPLETE_MARKER).exists() {
        bail!(
            "{}: its folder is marked {INCOMPLETE_MARKER} (its run was interrupted or is \
             still writing)",
            path.display()
        );
    }
    csv_io::read_records(path, "bench-conv runs CSV")
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
