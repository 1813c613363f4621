//! The tracking runs: every (method, frame step) track of a sequence, frame after frame,
//! and the record of each aligned frame.

use std::ops::ControlFlow;
use std::time::Instant;

use anyhow::Context;
use frame::Image;
use rayon::prelude::*;
use splat::PointCloud;
use ucm::{Camera, Isometry3};
use vvs::{Method, Servo, StopReason, Tracker, VvsConfig};

use super::{SequenceSpec, acquire, display_name};
use crate::progress::Progress;

/// One tracked frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRecord {
    /// The method.
    pub method: Method,
    /// Frame step N (the track uses 1 frame in N).
    pub frame_step: usize,
    /// Index of the frame in the sequence.
    pub frame: usize,
    /// Time of the frame, seconds.
    pub time_s: f64,
    /// True `world_from_camera`, `(t, θw)`.
    pub true_pose: [f64; 6],
    /// Estimated `world_from_camera`, `(t, θw)`.
    pub estimated_pose: [f64; 6],
    /// Position error, metres.
    pub position_error_m: f64,
    /// Rotation error, degrees.
    pub rotation_error_deg: f64,
    /// Iterations of step 1 and step 2.
    pub iterations: [usize; 2],
    /// Why the optimisation stopped.
    pub stop: StopReason,
    /// Whether the first alignment failed and the frame was searched again
    /// ([`vvs::Recovery`]).
    pub recovered: bool,
    /// Wall time of the frame's alignment, seconds.
    pub wall_time_s: f64,
}

/// Track one method with one frame step ([`vvs::Tracker`]): returns the records of the
/// frames aligned (the last one is where the track was lost, if it was) and whether it
/// was lost (diverged, or farther than `lost_threshold_m` from the truth). `on_frame`
/// is called after each aligned frame (progress).
pub fn track(
    servo: Servo<'_>,
    method: Method,
    frame_step: usize,
    spec: &SequenceSpec,
    truth: &[Isometry3],
    acquired: &[Option<Image>],
    on_frame: impl Fn(),
) -> anyhow::Result<(Vec<FrameRecord>, bool)> {
    let initial = truth[0] * Isometry3::from_pose_vector(spec.initial_offset)?;
    let mut tracker = Tracker::new(servo, method, initial)?
        .with_prediction(spec.prediction)
        .with_recovery(spec.recovery.clone())?;
    let mut records = Vec::new();
    let report = tracker.track(acquired.iter().map(Option::as_ref), frame_step, |tracked| {
        let k = tracked.frame;
        let estimate = tracked.outcome.world_from_camera;
        let (dt, dr) = estimate.distance_to(&truth[k]);
        records.push(FrameRecord {
            method,
            frame_step,
            frame: k,
            time_s: spec.trajectory.time_s(k),
            true_pose: truth[k].to_pose_vector(),
            estimated_pose: estimate.to_pose_vector(),
            position_error_m: dt,
            rotation_error_deg: dr.to_degrees(),
            iterations: tracked.outcome.iterations,
            stop: tracked.outcome.stop,
            recovered: tracked.recovered,
            wall_time_s: tracked.wall_time_s,
        });
        on_frame();
        if dt > spec.lost_threshold_m {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })?;
    Ok((records, report.lost))
}

/// Everything a tracking experiment produced.
#[derive(Debug)]
pub struct TrackingResults {
    /// Every aligned frame, by method then step then frame.
    pub records: Vec<FrameRecord>,
    /// Whether each (method, frame step) track was lost.
    pub lost: Vec<(Method, usize, bool)>,
    /// The ground truth of every frame.
    pub truth: Vec<Isometry3>,
    /// Wall time of the whole experiment, seconds.
    pub wall_time_s: f64,
}

impl TrackingResults {
    /// The records of one track (method, frame step N), in frame order.
    pub fn track(
        &self,
        method: Method,
        frame_step: usize,
    ) -> impl DoubleEndedIterator<Item = &FrameRecord> {
        self.records
            .iter()
            .filter(move |r| r.method == method && r.frame_step == frame_step)
    }
}

/// Run every (method, step) track of the sequence, in parallel over rayon (each track
/// is sequential; results do not depend on the thread count), with a progress bar.
pub fn run_sequence(
    spec: &SequenceSpec,
    camera: &Camera,
    cloud: &PointCloud,
    acquired_cloud: Option<&PointCloud>,
) -> anyhow::Result<(TrackingResults, Vec<Option<Image>>)> {
    let started = Instant::now();
    let truth = spec.trajectory.poses();
    let mut needed = vec![false; truth.len()];
    for &n in &spec.frame_steps {
        for k in (0..truth.len()).step_by(n) {
            needed[k] = true;
        }
    }
    let acquired = acquire(
        acquired_cloud.unwrap_or(cloud),
        camera,
        &truth,
        &spec.trajectory,
        &spec.acquisition,
        &needed,
    )?;
    let config = spec.vvs_config()?;
    let jobs: Vec<(Method, usize)> = spec
        .methods
        .iter()
        .flat_map(|&m| spec.frame_steps.iter().map(move |&n| (m, n)))
        .collect();
    let total_frames: u64 = jobs
        .iter()
        .map(|&(_, n)| truth.len().div_ceil(n) as u64)
        .sum();
    let bar = Progress::new(total_frames, "frames");
    // Tracks in parallel, each image on one thread (unless there are fewer tracks than
    // threads).
    let config = VvsConfig {
        parallel: jobs.len() < rayon::current_num_threads(),
        ..config
    };
    let outputs: Vec<anyhow::Result<(Vec<FrameRecord>, bool)>> = jobs
        .par_iter()
        .map(|&(method, n)| {
            let servo = Servo::new(cloud, camera, config.clone())?;
            let label = format!("{} N={n}", display_name(method));
            let (records, lost) = track(servo, method, n, spec, &truth, &acquired, || {
                bar.inc(1, &label)
            })?;
            // A lost track skips its remaining frames.
            let remaining = truth.len().div_ceil(n).saturating_sub(records.len());
            bar.inc(remaining as u64, "");
            Ok((records, lost))
        })
        .collect();
    bar.finish();
    let mut records = Vec::new();
    let mut lost = Vec::new();
    for (&(method, n), output) in jobs.iter().zip(outputs) {
        let (r, l) = output.with_context(|| format!("tracking {} with N = {n}", method.name()))?;
        records.extend(r);
        lost.push((method, n, l));
    }
    Ok((
        TrackingResults {
            records,
            lost,
            truth,
            wall_time_s: started.elapsed().as_secs_f64(),
        },
        acquired,
    ))
}
