//! Running a protocol: every run in parallel over rayon, with a progress bar, results
//! in a stable order whatever the thread count.

use std::sync::Mutex;
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use splat::PointCloud;
use vvs::Servo;

use crate::protocol::{MethodConfig, Protocol, RunSpec};
use crate::report::RunRecord;

/// Load or generate the protocol's cloud.
pub fn load_scene(protocol: &Protocol) -> anyhow::Result<(PointCloud, String)> {
    protocol.scene.load(&protocol.base_dir, None)
}

/// Which runs of the protocol this process executes: all, or shard `i` of `n`
/// (run ids congruent to `i` modulo `n`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl Shard {
    /// Parse `i/n`.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let (i, n) = text.split_once('/').context("a shard is written i/n")?;
        let (index, count): (usize, usize) = (i.trim().parse()?, n.trim().parse()?);
        anyhow::ensure!(
            count > 0 && index < count,
            "shard {index}/{count}: need 0 <= i < n"
        );
        Ok(Self { index, count })
    }

    /// Whether this shard runs `id`.
    pub fn owns(&self, id: usize) -> bool {
        id % self.count == self.index
    }
}

/// Run the protocol (or a shard of it) and return one record per run, in run order.
pub fn run_protocol(
    protocol: &Protocol,
    cloud: &PointCloud,
    scene_name: &str,
    extras: bool,
    shard: Option<Shard>,
) -> anyhow::Result<Vec<RunRecord>> {
    let camera = ucm::Camera::load_toml(protocol.resolve(&protocol.camera))?;
    let methods = protocol.method_configs(extras)?;
    let runs: Vec<RunSpec> = protocol
        .runs(extras)?
        .into_iter()
        .filter(|r| shard.is_none_or(|s| s.owns(r.id)))
        .collect();
    // Bounds: every desired and initial pose must be inside the cloud's box.
    let (lo, hi) = cloud.bounds();
    for r in &runs {
        for pose in [
            protocol.desired_pose(r.desired)?,
            protocol.initial_pose(r.desired, r.initial)?,
        ] {
            let p = pose.translation;
            anyhow::ensure!(
                p.cmpge(lo).all() && p.cmple(hi).all(),
                "pose {p} of desired {} / initial {} is outside the cloud's bounds {lo} – {hi}",
                r.desired,
                r.initial
            );
        }
    }
    // Desired images, rendered once.
    let mut renderer = Servo::new(cloud, &camera, methods[0].config.clone())?;
    let desired: Vec<splat::Frame> = (0..protocol.desired.len())
        .map(|k| Ok(renderer.render(&protocol.desired_pose(k)?)?))
        .collect::<anyhow::Result<_>>()?;

    let bar = ProgressBar::new(runs.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} runs, ETA {eta} {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let successes = Mutex::new(0usize);
    let mut records: Vec<RunRecord> = runs
        .par_iter()
        .map_init(
            || None::<(usize, Servo<'_>)>,
            |servo_slot, spec| -> anyhow::Result<RunRecord> {
                let method: &MethodConfig = &methods[spec.method];
                // One optimiser per worker, rebuilt when the method's settings change.
                if servo_slot.as_ref().is_none_or(|(m, _)| *m != spec.method) {
                    *servo_slot = Some((
                        spec.method,
                        Servo::new(cloud, &camera, method.config.clone())?,
                    ));
                }
                let servo = &mut servo_slot.as_mut().expect("set above").1;
                let desired_pose = protocol.desired_pose(spec.desired)?;
                let initial = protocol.initial_pose(spec.desired, spec.initial)?;
                let started = Instant::now();
                let outcome = servo.run(method.method, &desired[spec.desired], initial)?;
                let wall_time_s = started.elapsed().as_secs_f64();
                let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose);
                let success = dt < protocol.success_threshold_m;
                if success {
                    *successes.lock().expect("not poisoned") += 1;
                }
                bar.inc(1);
                bar.set_message(format!(
                    "{} successes",
                    successes.lock().expect("not poisoned")
                ));
                Ok(RunRecord {
                    run_id: spec.id,
                    scene: scene_name.to_string(),
                    desired: spec.desired,
                    initial: spec.initial,
                    method: method.name.clone(),
                    final_position_error_m: dt,
                    final_rotation_error_deg: dr.to_degrees(),
                    iterations_step1: outcome.iterations[0],
                    iterations_step2: outcome.iterations[1],
                    stop: outcome.stop.name().to_string(),
                    lambda: outcome.lambda,
                    cost: outcome.cost,
                    wall_time_s,
                    success,
                })
            },
        )
        .collect::<anyhow::Result<_>>()?;
    bar.finish();
    records.sort_by_key(|r| r.run_id);
    Ok(records)
}
