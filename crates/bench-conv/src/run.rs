//! Running a protocol: every run in parallel over rayon, with a progress bar, results
//! in a stable order whatever the thread count.

use std::sync::Mutex;

use anyhow::Context as _;
use rayon::prelude::*;
use splat::PointCloud;
use vvs::{Method, Servo, VvsConfig};

use crate::progress::Progress;
use crate::protocol::{MethodConfig, Protocol, RunSpec};
use crate::report::RunRecord;

/// Load or generate the protocol's cloud.
pub fn load_scene(protocol: &Protocol) -> anyhow::Result<(PointCloud, String)> {
    protocol.scene.load(&protocol.base_dir, None)
}

/// Which runs of the protocol this process executes: all, or shard `i` of `n`: every
/// method's runs from the poses `k ≡ i (mod n)`, poses numbered desired-major
/// (`k = desired × initial poses per desired + initial`). Every shard thus samples
/// every method, and a pose's methods stay together (Rule1 and Rule2 share step 1).
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
        let usage = || format!("shard `{text}`: write i/n with integers 0 <= i < n");
        let (i, n) = text.split_once('/').with_context(usage)?;
        let index: usize = i.trim().parse().with_context(usage)?;
        let count: usize = n.trim().parse().with_context(usage)?;
        anyhow::ensure!(count > 0 && index < count, usage());
        Ok(Self { index, count })
    }

    /// Whether this shard runs the pose numbered `pose`.
    pub fn owns(&self, pose: usize) -> bool {
        pose % self.count == self.index
    }
}

/// Refuse a shard that holds no run (more shards than poses), or any shard of an
/// adaptive protocol, before any work.
pub fn check_shard(protocol: &Protocol, extras: bool, shard: Option<Shard>) -> anyhow::Result<()> {
    let Some(s) = shard else { return Ok(()) };
    anyhow::ensure!(
        !protocol.offsets.adaptive,
        "an adaptive protocol ([offsets] adaptive = true) cannot be sharded: which runs it \
         needs at a scale depends on the runs at the smaller ones (run it whole)"
    );
    let methods = protocol.method_configs(extras)?.len().max(1);
    let poses = protocol.runs(extras)?.len() / methods;
    anyhow::ensure!(
        s.count <= poses,
        "shard {}/{}: the protocol has {poses} poses (desired × initial × scale), so at most \
         {poses} shards, each with a run",
        s.index,
        s.count
    );
    Ok(())
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
        .filter(|r| shard.is_none_or(|s| s.owns(r.id / methods.len())))
        .collect();
    check_shard(protocol, extras, shard)?;
    // One rule for where a camera may be, the optimiser's own: inside the cloud's
    // bounding box enlarged by `bounds_margin_m` (a street camera, or a camera a few
    // metres from an object scan).
    let (lo, hi) = cloud.bounds();
    for r in &runs {
        let margin = methods[r.method].config.bounds_margin_m;
        for (what, pose) in [
            ("desired", protocol.desired_pose(r.desired)?),
            (
                "initial",
                protocol.initial_pose(r.desired, r.initial, protocol.offsets.scales[r.scale])?,
            ),
        ] {
            let p = pose.translation;
            anyhow::ensure!(
                p.cmpge(lo - margin).all() && p.cmple(hi + margin).all(),
                "the {what} camera at {p} (desired {}, initial {}) is more than \
                 bounds_margin_m = {margin} m outside the cloud's bounds {lo} – {hi}",
                r.desired,
                r.initial
            );
        }
    }
    // Desired images, rendered once.
    let mut renderer = Servo::new(cloud, &camera, methods[0].config.clone())?;
    let desired_images: Vec<frame::Frame> = (0..protocol.desired.len())
        .map(|k| Ok(renderer.render(&protocol.desired_pose(k)?)?))
        .collect::<anyhow::Result<_>>()?;
    let context = Shared {
        protocol,
        cloud,
        camera: &camera,
        methods: &methods,
        scene_name,
        desired_images: &desired_images,
        bar: std::sync::Arc::new(Progress::new(runs.len() as u64, "runs")),
        successes: Mutex::new(0),
    };
    let mut records = if protocol.offsets.adaptive {
        run_adaptive(
            &runs,
            methods.len(),
            |round| context.run(round),
            |beyond| {
                context
                    .bar
                    .inc(beyond as u64, "(runs beyond a basin skipped)")
            },
        )?
    } else {
        context.run(&runs)?
    };
    context.bar.finish();
    records.sort_by_key(|r| r.run_id);
    Ok(records)
}

/// The runs of an adaptive axes protocol ([`crate::protocol::Offsets::adaptive`]):
/// the scales in increasing order (`runs` holds scale indices in that order), each
/// (method, axis) stopped after its first scale with a failed run. `run` runs one
/// round (one record per run, in order); `skipped` hears how many runs of `runs` each
/// round made unnecessary. Returns the records of every round.
///
/// `run` returns one record per run of its round, in any order (each is matched to its
/// run by `run_id`).
pub fn run_adaptive(
    runs: &[RunSpec],
    method_count: usize,
    mut run: impl FnMut(&[RunSpec]) -> anyhow::Result<Vec<RunRecord>>,
    mut skipped: impl FnMut(usize),
) -> anyhow::Result<Vec<RunRecord>> {
    let axis = |r: &RunSpec| Protocol::axis_of(r.initial);
    // Whether each (method, axis) is still inside its basin.
    let mut inside = vec![[true; 6]; method_count];
    let mut records = Vec::new();
    let scales = runs.iter().map(|r| r.scale + 1).max().unwrap_or(0);
    for scale in 0..scales {
        let before = inside.clone();
        let round: Vec<RunSpec> = runs
            .iter()
            .filter(|r| r.scale == scale && inside[r.method][axis(r)])
            .copied()
            .collect();
        let done = run(&round)?;
        anyhow::ensure!(done.len() == round.len(), "a round lost runs");
        for record in &done {
            let spec = round
                .iter()
                .find(|r| r.id == record.run_id)
                .context("a round returned a run it was not given")?;
            if !record.success {
                inside[spec.method][axis(spec)] = false;
            }
        }
        records.extend(done);
        // The runs beyond a basin found in this round will not be needed.
        let beyond = runs
            .iter()
            .filter(|r| r.scale > scale && before[r.method][axis(r)] && !inside[r.method][axis(r)])
            .count();
        if beyond > 0 {
            skipped(beyond);
        }
    }
    Ok(records)
}

/// What every run of a protocol shares.
struct Shared<'a> {
    protocol: &'a Protocol,
    cloud: &'a PointCloud,
    camera: &'a ucm::Camera,
    methods: &'a [MethodConfig],
    scene_name: &'a str,
    desired_images: &'a [frame::Frame],
    bar: std::sync::Arc<Progress>,
    successes: Mutex<usize>,
}

impl Shared<'_> {
    /// Run `runs` in parallel; one record per run (Rule1 and Rule2 of a pose next to
    /// each other).
    fn run(&self, runs: &[RunSpec]) -> anyhow::Result<Vec<RunRecord>> {
        let Self {
            protocol,
            cloud,
            camera,
            methods,
            scene_name,
            desired_images,
            ..
        } = *self;
        // Jobs: the runs of one pose, one per method, except that Rule1 and Rule2 with the
        // same settings form one job, which runs their common step 1 once.
        let shares_step1 = |m: usize| matches!(methods[m].method, Method::Rule1 | Method::Rule2);
        let mut jobs: Vec<Vec<RunSpec>> = Vec::new();
        for r in runs {
            let partner = jobs.iter_mut().rev().take(methods.len()).find(|job| {
                let first = job[0];
                (first.desired, first.scale, first.initial) == (r.desired, r.scale, r.initial)
                    && shares_step1(first.method)
                    && shares_step1(r.method)
                    && methods[first.method].config == methods[r.method].config
            });
            match partner {
                Some(job) => job.push(*r),
                None => jobs.push(vec![*r]),
            }
        }
        // Runs in parallel, each image on one thread (unless there is a single job).
        let parallel_images = jobs.len() < rayon::current_num_threads();

        let records: Vec<Vec<RunRecord>> = jobs
            .par_iter()
            .map_init(
                Vec::<(usize, Servo<'_>)>::new,
                |servos, job| -> anyhow::Result<Vec<RunRecord>> {
                    let first = &methods[job[0].method];
                    // One optimiser per worker and setting, built once (a run starts
                    // afresh from its initial pose whatever the optimiser ran before).
                    let slot = match servos
                        .iter()
                        .position(|(m, _)| methods[*m].config == first.config)
                    {
                        Some(slot) => slot,
                        None => {
                            let config = VvsConfig {
                                parallel: parallel_images,
                                ..first.config.clone()
                            };
                            let servo = Servo::new(cloud, camera, config)?;
                            servos.push((job[0].method, servo));
                            servos.len() - 1
                        }
                    };
                    let servo = &mut servos[slot].1;
                    let (desired, initial) = (job[0].desired, job[0].initial);
                    let offset_scale = protocol.offsets.scales[job[0].scale];
                    let desired_pose = protocol.desired_pose(desired)?;
                    let initial_pose = protocol.initial_pose(desired, initial, offset_scale)?;
                    let job_methods: Vec<Method> =
                        job.iter().map(|r| methods[r.method].method).collect();
                    let desired_image = &desired_images[desired];
                    let outcomes = if job_methods == [Method::Global] {
                        // The protocol's box; a search can take seconds: its phases
                        // beside the bar.
                        vec![servo.localize_in_box_with_progress(
                            desired_image,
                            initial_pose,
                            &protocol.prior_box(),
                            &mut |p| {
                                self.bar.note(&format!(
                                    "global search: {} {}/{}",
                                    p.phase.name(),
                                    p.done,
                                    p.total
                                ))
                            },
                        )?]
                    } else {
                        servo.run_methods(&job_methods, desired_image, initial_pose)?
                    };
                    let mut records = Vec::with_capacity(job.len());
                    for (spec, outcome) in job.iter().zip(outcomes) {
                        let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose);
                        let success = crate::report::is_success(
                            dt,
                            outcome.cost,
                            protocol.success_threshold_m,
                        );
                        records.push(RunRecord {
                            run_id: spec.id,
                            scene: scene_name.to_string(),
                            desired,
                            offset_scale,
                            initial,
                            config: methods[spec.method].name.clone(),
                            method: methods[spec.method].method,
                            final_position_error_m: dt,
                            final_rotation_error_deg: dr.to_degrees(),
                            iterations_step1: outcome.iterations[0],
                            iterations_step2: outcome.iterations[1],
                            stop: outcome.stop,
                            lambda: outcome.lambda,
                            cost: outcome.cost,
                            wall_time_s: outcome.time_s,
                            success,
                        });
                    }
                    let mut successes = self.successes.lock().expect("not poisoned");
                    *successes += records.iter().filter(|r| r.success).count();
                    self.bar
                        .inc(job.len() as u64, &format!("{successes} successes"));
                    Ok(records)
                },
            )
            .collect::<anyhow::Result<_>>()?;
        Ok(records.into_iter().flatten().collect())
    }
}
