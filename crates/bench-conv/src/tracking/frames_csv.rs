//! The per-frame CSV of a tracking experiment (`frames.csv`): a row per aligned frame.

use std::path::Path;

use serde::{Deserialize, Serialize};
use vvs::{Method, StopReason};

use super::FrameRecord;
use crate::csv_io;

/// A row of `frames.csv`: a [`FrameRecord`] with its poses and iterations spread over
/// columns, numbers in fixed formats so that two runs compare as text.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct FrameRow {
    #[serde(
        serialize_with = "csv_io::display",
        deserialize_with = "csv_io::from_str"
    )]
    method: Method,
    frame_step: usize,
    frame: usize,
    #[serde(serialize_with = "csv_io::fixed::<6, _>")]
    time_s: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_tx: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_ty: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_tz: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_wx: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_wy: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    true_wz: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_tx: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_ty: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_tz: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_wx: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_wy: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    est_wz: f64,
    #[serde(serialize_with = "csv_io::fixed::<9, _>")]
    position_error_m: f64,
    #[serde(serialize_with = "csv_io::fixed::<6, _>")]
    rotation_error_deg: f64,
    iterations_step1: usize,
    iterations_step2: usize,
    #[serde(
        serialize_with = "csv_io::display",
        deserialize_with = "csv_io::from_str"
    )]
    stop: StopReason,
    recovered: bool,
    #[serde(serialize_with = "csv_io::fixed::<6, _>")]
    wall_time_s: f64,
}

impl From<&FrameRecord> for FrameRow {
    fn from(r: &FrameRecord) -> Self {
        let [true_tx, true_ty, true_tz, true_wx, true_wy, true_wz] = r.true_pose;
        let [est_tx, est_ty, est_tz, est_wx, est_wy, est_wz] = r.estimated_pose;
        FrameRow {
            method: r.method,
            frame_step: r.frame_step,
            frame: r.frame,
            time_s: r.time_s,
            true_tx,
            true_ty,
            true_tz,
            true_wx,
            true_wy,
            true_wz,
            est_tx,
            est_ty,
            est_tz,
            est_wx,
            est_wy,
            est_wz,
            position_error_m: r.position_error_m,
            rotation_error_deg: r.rotation_error_deg,
            iterations_step1: r.iterations[0],
            iterations_step2: r.iterations[1],
            stop: r.stop,
            recovered: r.recovered,
            wall_time_s: r.wall_time_s,
        }
    }
}

impl From<FrameRow> for FrameRecord {
    fn from(r: FrameRow) -> Self {
        FrameRecord {
            method: r.method,
            frame_step: r.frame_step,
            frame: r.frame,
            time_s: r.time_s,
            true_pose: [
                r.true_tx, r.true_ty, r.true_tz, r.true_wx, r.true_wy, r.true_wz,
            ],
            estimated_pose: [r.est_tx, r.est_ty, r.est_tz, r.est_wx, r.est_wy, r.est_wz],
            position_error_m: r.position_error_m,
            rotation_error_deg: r.rotation_error_deg,
            iterations: [r.iterations_step1, r.iterations_step2],
            stop: r.stop,
            recovered: r.recovered,
            wall_time_s: r.wall_time_s,
        }
    }
}

/// Write the per-frame CSV ([`csv_io::write_records`]), atomically.
pub fn write_csv(path: &Path, records: &[FrameRecord]) -> anyhow::Result<()> {
    let rows: Vec<FrameRow> = records.iter().map(FrameRow::from).collect();
    csv_io::write_records(path, &rows)
}

/// Read a per-frame CSV written by [`write_csv`]; errors name the file, line and field.
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<FrameRecord>> {
    let rows: Vec<FrameRow> = csv_io::read_records(path, "tracking CSV")?;
    Ok(rows.into_iter().map(FrameRecord::from).collect())
}
