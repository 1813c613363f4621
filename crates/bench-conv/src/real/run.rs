//! Preparing a benchmark (clouds, queries, pictures) and running it: every
//! localisation in parallel over rayon, each on one thread, the results in a stable
//! order whatever the thread count.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, ensure};
use frame::Image;
use rayon::prelude::*;
use serde::Serialize;
use splat::PointCloud;
use ucm::{Camera, Isometry3};
use vvs::{Method, Outcome, Servo, StopReason, Tracker, VvsConfig};

use super::spec::{BenchMethod, RealSpec, Split};
use crate::progress::Progress;

/// Why a frame is a query.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum QueryKind {
    /// Left out of its cloud, which holds every other frame.
    LeftOut,
    /// Between map frames.
    Near,
    /// Inside the block held out of the map.
    Block,
}

impl QueryKind {
    /// Its name in tables.
    pub fn name(self) -> &'static str {
        match self {
            QueryKind::LeftOut => "left out",
            QueryKind::Near => "near the map",
            QueryKind::Block => "held-out block",
        }
    }
}

/// The frames of a cloud and its queries.
type CloudPlan = (Vec<u64>, Vec<(u64, QueryKind)>);

/// A query: a frame, its truth, its cloud, and its nearest map frame.
#[derive(Clone, Debug)]
pub struct Query {
    /// The frame number.
    pub frame: u64,
    /// Why it is a query.
    pub kind: QueryKind,
    /// Index of its cloud in [`Benchmark::clouds`].
    pub cloud: usize,
    /// `world_from_camera` of its colour picture.
    pub truth: Isometry3,
    /// The nearest frame of its cloud (by distance plus angle: 1° counts as 1 cm), its
    /// pose, and its distance and angle to the truth.
    pub nearest: (u64, Isometry3, f64, f64),
}

/// A benchmark ready to run: its clouds, queries and pictures.
#[derive(Debug)]
pub struct Benchmark {
    /// The benchmark file.
    pub spec: RealSpec,
    /// The queries' camera (at the benchmark's resolution).
    pub camera: Camera,
    /// The clouds (one, or one per left-out frame).
    pub clouds: Vec<PointCloud>,
    /// The frames of each cloud.
    pub cloud_frames: Vec<Vec<u64>>,
    /// The queries.
    pub queries: Vec<Query>,
    /// Their pictures.
    pub pictures: Vec<Image>,
    /// With `[catadioptric]`: the camera and the queries' pictures resampled to it.
    pub catadioptric: Option<(Camera, Vec<Image>)>,
    /// The dataset.
    pub dataset: rgbd::RgbdDataset,
}

/// One localisation of the benchmark.
#[derive(Clone, Debug, Serialize)]
pub struct RunRecord {
    /// The query's frame.
    pub query: u64,
    /// Why it is a query.
    pub kind: QueryKind,
    /// `pinhole` or the catadioptric camera (`ucm-xi0.9`).
    pub camera: String,
    /// Where it started (`truth`, `5cm-3deg`, `nearest-map-frame`).
    pub start: String,
    /// The start's distance and angle to the truth.
    pub start_error_m: f64,
    /// …degrees.
    pub start_error_deg: f64,
    /// The method (`localizer`, `rule2/convolved+region`, `global`, `reference`).
    pub method: String,
    /// Why it stopped.
    pub stop: String,
    /// Iterations (both steps).
    pub iterations: usize,
    /// Final distance to the truth, metres.
    pub error_m: f64,
    /// Final angle to the truth, degrees.
    pub error_deg: f64,
    /// Final distance to the query's photometric optimum (when computed), metres.
    pub to_reference_m: Option<f64>,
    /// …degrees.
    pub to_reference_deg: Option<f64>,
    /// Within the benchmark's thresholds of the truth and not diverged.
    pub success: bool,
    /// Time of the localisation, seconds.
    pub time_s: f64,
    /// The final `world_from_camera` as the paper's `(t, θw)`.
    pub tx: f64,
    /// …
    pub ty: f64,
    /// …
    pub tz: f64,
    /// …
    pub wx: f64,
    /// …
    pub wy: f64,
    /// …
    pub wz: f64,
}

/// One tracked frame.
#[derive(Clone, Debug, Serialize)]
pub struct TrackRecord {
    /// The method.
    pub method: String,
    /// 1 frame in N.
    pub frame_step: usize,
    /// The frame.
    pub frame: u64,
    /// Distance of the estimate to the truth, metres.
    pub error_m: f64,
    /// Angle, degrees.
    pub error_deg: f64,
    /// Why the alignment stopped.
    pub stop: String,
    /// Its iterations.
    pub iterations: usize,
    /// Its time, seconds.
    pub time_s: f64,
    /// Whether the track was lost (diverged, or farther than the threshold) at or
    /// before this frame.
    pub lost: bool,
}

/// One depth alignment of a query's depth picture (`[pose_check]`, `rgbd::align_depth`)
/// against one of its cloud's frames or several together, started at its truth.
#[derive(Clone, Debug, Serialize)]
pub struct PoseCheckRecord {
    /// The query's frame.
    pub query: u64,
    /// `frame N`, or `N nearest frames`.
    pub against: String,
    /// How many frames.
    pub frames: usize,
    /// The (farthest) frame's distance to the query's truth, metres…
    pub distance_m: f64,
    /// … and angle, degrees.
    pub angle_deg: f64,
    /// How far the alignment moved the query's colour camera from its truth, metres…
    pub correction_m: Option<f64>,
    /// … and turned it, degrees (none when the alignment failed).
    pub correction_deg: Option<f64>,
    /// Point-to-plane RMS at the truth, millimetres…
    pub rms_before_mm: Option<f64>,
    /// … and at the aligned pose.
    pub rms_after_mm: Option<f64>,
    /// Points paired at the truth…
    pub pairs_before: Option<usize>,
    /// … and at the aligned pose.
    pub pairs_after: Option<usize>,
    /// `rgbd::DepthAlignment::conditioning`: near 0, one direction is barely held.
    pub conditioning: Option<f64>,
    /// Why the alignment failed, if it did.
    pub failure: String,
}

/// Everything a benchmark measured.
#[derive(Clone, Debug, Default)]
pub struct RealResults {
    /// The localisations.
    pub runs: Vec<RunRecord>,
    /// The tracks, frame by frame.
    pub tracks: Vec<TrackRecord>,
    /// The depth alignments of `[pose_check]`.
    pub poses: Vec<PoseCheckRecord>,
}

/// One localisation to run.
#[derive(Clone, Debug)]
struct Job {
    query: usize,
    catadioptric: bool,
    start: String,
    initial: Isometry3,
    method: Option<BenchMethod>,
    global: bool,
    reference: bool,
    /// In a cloud of the frames nearest the start (`[local_map]`).
    local: bool,
}

/// A unit vector of a seeded direction.
fn direction(rng: &mut splat::rng::SplitMix64) -> glam::DVec3 {
    loop {
        let v = glam::DVec3::new(rng.normal(), rng.normal(), rng.normal());
        if v.length() > 1e-6 {
            return v.normalize();
        }
    }
}

/// `truth · (t, θw)` with `|t| = translation_m`, `|θw| = rotation_deg`, directions
/// drawn from `seed` and the query's frame.
fn offset_start(
    truth: &Isometry3,
    [t, r]: [f64; 2],
    seed: u64,
    frame: u64,
    index: usize,
) -> Isometry3 {
    let mut rng = splat::rng::SplitMix64::new(splat::rng::mix64(
        seed ^ frame.wrapping_mul(0x9e37_79b9) ^ ((index as u64) << 48),
    ));
    let (a, b) = (
        direction(&mut rng) * t,
        direction(&mut rng) * r.to_radians(),
    );
    *truth * Isometry3::from_pose_vector([a.x, a.y, a.z, b.x, b.y, b.z]).expect("a finite offset")
}

/// `frames` with their colour camera's pose, distance (m) and angle (degrees) to `pose`,
/// nearest first (a metre counts as 100°); ties in frame order.
fn by_distance(
    dataset: &rgbd::RgbdDataset,
    frames: &[u64],
    pose: &Isometry3,
) -> anyhow::Result<Vec<(u64, Isometry3, f64, f64)>> {
    let mut out = frames
        .iter()
        .map(|&f| {
            let frame_pose = dataset.world_from_color(f)?;
            let (t, r) = frame_pose.distance_to(pose);
            Ok((f, frame_pose, t, r.to_degrees()))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    out.sort_by(|a, b| (a.2 + a.3 / 100.0).total_cmp(&(b.2 + b.3 / 100.0)));
    Ok(out)
}

/// The name of a start offset: `truth` or `5cm-3deg`.
fn start_name([t, r]: [f64; 2]) -> String {
    if t == 0.0 && r == 0.0 {
        "truth".into()
    } else {
        format!("{}cm-{}deg", (t * 100.0).round(), r)
    }
}

/// The catadioptric camera of `[catadioptric]`: the pinhole's size and centre, ξ, and the
/// focal length that keeps the pinhole's scale at the centre (`α = f (1 + ξ)`), its
/// region the pixels the pinhole sees.
pub fn catadioptric_camera(pinhole: &Camera, xi: f64) -> anyhow::Result<Camera> {
    let i = *pinhole.intrinsics();
    let intrinsics = ucm::Intrinsics {
        alpha_u: i.alpha_u * (1.0 + xi),
        alpha_v: i.alpha_v * (1.0 + xi),
        xi,
        ..i
    };
    let full = Camera::new(
        intrinsics,
        None,
        pinhole.width(),
        pinhole.height(),
        ucm::ValidRegion::Full,
    )?;
    Ok(frame::seen_through(&full, pinhole)?)
}

impl Benchmark {
    /// Read the dataset under `data`, fuse the clouds, read the queries' pictures.
    pub fn prepare(spec: RealSpec, data: &Path) -> anyhow::Result<Self> {
        let dataset = rgbd::RgbdDataset::load(spec.resolve(&spec.dataset), data)
            .with_context(|| format!("the dataset of benchmark {}", spec.name))?;
        let full_camera = dataset.sensor().color_camera.clone();
        let camera = if spec.downsample > 1 {
            full_camera.downsampled(spec.downsample)?
        } else {
            full_camera.clone()
        };
        let parse = |text: &str| crate::parse_frames(text);
        // (cloud frames, queries of that cloud).
        let mut plan: Vec<CloudPlan> = Vec::new();
        match &spec.split {
            Split::LeaveOneOut { frames } => {
                let frames = parse(frames)?;
                ensure!(frames.len() >= 2, "leave one out needs two frames or more");
                for &q in &frames {
                    let others = frames.iter().copied().filter(|&f| f != q).collect();
                    plan.push((others, vec![(q, QueryKind::LeftOut)]));
                }
            }
            Split::Map {
                map,
                exclude,
                near,
                block,
            } => {
                let mut map = parse(map)?;
                if let Some(exclude) = exclude {
                    let exclude = parse(exclude)?;
                    map.retain(|f| !exclude.contains(f));
                }
                let mut queries: Vec<(u64, QueryKind)> = parse(near)?
                    .into_iter()
                    .map(|f| (f, QueryKind::Near))
                    .collect();
                if let Some(block) = block {
                    queries.extend(parse(block)?.into_iter().map(|f| (f, QueryKind::Block)));
                }
                for (q, _) in &queries {
                    ensure!(!map.contains(q), "query frame {q} is a map frame");
                }
                plan.push((map, queries));
            }
        }
        let mut clouds = Vec::with_capacity(plan.len());
        let mut cloud_frames = Vec::with_capacity(plan.len());
        let mut queries = Vec::new();
        for (index, (frames, cloud_queries)) in plan.into_iter().enumerate() {
            eprintln!(
                "fusing {} frames into cloud {} of {}",
                frames.len(),
                index + 1,
                clouds.capacity()
            );
            let progress = Progress::new(frames.len() as u64, "frames");
            let (cloud, report) = dataset.fuse(&frames, spec.fuse, |_, _| progress.inc(1, ""))?;
            progress.finish();
            eprintln!("{} points ({} voxels)", report.points, report.voxels);
            for (frame, kind) in cloud_queries {
                let truth = dataset.world_from_color(frame)?;
                let nearest = by_distance(&dataset, &frames, &truth)?
                    .into_iter()
                    .next()
                    .context("a cloud without frames")?;
                queries.push(Query {
                    frame,
                    kind,
                    cloud: index,
                    truth,
                    nearest,
                });
            }
            clouds.push(cloud);
            cloud_frames.push(frames);
        }
        let pictures = queries
            .par_iter()
            .map(|q| load_picture(&dataset, q.frame, &full_camera, &camera, spec.downsample))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let catadioptric = match &spec.catadioptric {
            None => None,
            Some(c) => {
                let ucm = catadioptric_camera(&camera, c.xi)?;
                let resampled = pictures
                    .iter()
                    .map(|p| p.resampled(&camera, &ucm))
                    .collect::<Result<Vec<_>, _>>()?;
                Some((ucm, resampled))
            }
        };
        Ok(Self {
            spec,
            camera,
            clouds,
            cloud_frames,
            queries,
            pictures,
            catadioptric,
            dataset,
        })
    }

    fn jobs(&self) -> anyhow::Result<Vec<Job>> {
        let spec = &self.spec;
        let methods = spec.methods()?;
        let mut jobs = Vec::new();
        let cameras: &[bool] = if spec.catadioptric.is_some() {
            &[false, true]
        } else {
            &[false]
        };
        for &catadioptric in cameras {
            let methods = if catadioptric {
                let c = spec.catadioptric.as_ref().expect("catadioptric settings");
                c.methods
                    .iter()
                    .map(|m| BenchMethod::parse(m))
                    .collect::<anyhow::Result<Vec<_>>>()?
            } else {
                methods.clone()
            };
            for (qi, q) in self.queries.iter().enumerate() {
                if spec.reference {
                    jobs.push(Job {
                        query: qi,
                        catadioptric,
                        start: "truth".into(),
                        initial: q.truth,
                        method: None,
                        global: false,
                        reference: true,
                        local: false,
                    });
                }
                let mut starts: Vec<(String, Isometry3)> = spec
                    .starts
                    .offsets
                    .iter()
                    .enumerate()
                    .map(|(i, &o)| {
                        (
                            start_name(o),
                            offset_start(&q.truth, o, spec.starts.seed, q.frame, i),
                        )
                    })
                    .collect();
                if spec.starts.nearest_map_frame && q.kind == QueryKind::Block {
                    starts.push(("nearest-map-frame".into(), q.nearest.1));
                }
                for (name, initial) in &starts {
                    for m in &methods {
                        jobs.push(Job {
                            query: qi,
                            catadioptric,
                            start: name.clone(),
                            initial: *initial,
                            method: Some(*m),
                            global: false,
                            reference: false,
                            local: false,
                        });
                    }
                }
                if let (Some(local), false) = (&spec.local_map, catadioptric) {
                    for (name, initial) in &starts {
                        for m in &local.methods {
                            jobs.push(Job {
                                query: qi,
                                catadioptric,
                                start: name.clone(),
                                initial: *initial,
                                method: Some(BenchMethod::parse(m)?),
                                global: false,
                                reference: false,
                                local: true,
                            });
                        }
                    }
                }
                if spec.global.is_some() && !catadioptric {
                    let has_block = self.queries.iter().any(|q| q.kind == QueryKind::Block);
                    let global_start = if has_block {
                        (q.kind == QueryKind::Block)
                            .then(|| ("nearest-map-frame".to_string(), q.nearest.1))
                    } else {
                        starts.iter().rev().find(|(n, _)| n != "truth").cloned()
                    };
                    if let Some((name, initial)) = global_start {
                        jobs.push(Job {
                            query: qi,
                            catadioptric,
                            start: name,
                            initial,
                            method: None,
                            global: true,
                            reference: false,
                            local: false,
                        });
                    }
                }
            }
        }
        Ok(jobs)
    }

    /// `[local_map]`: for each (query, start) of a local job, the cloud fused from the
    /// frames of the query's cloud nearest the start — once, whatever the number of
    /// methods run in it (all of them held until the localisations end).
    fn local_clouds(&self, jobs: &[Job]) -> anyhow::Result<HashMap<(usize, String), PointCloud>> {
        let Some(local) = &self.spec.local_map else {
            return Ok(HashMap::new());
        };
        let mut starts: Vec<&Job> = Vec::new();
        for job in jobs.iter().filter(|j| j.local) {
            if !starts
                .iter()
                .any(|s| s.query == job.query && s.start == job.start)
            {
                starts.push(job);
            }
        }
        if !starts.is_empty() {
            eprintln!(
                "fusing {} local maps of {} frames",
                starts.len(),
                local.frames
            );
        }
        starts
            .par_iter()
            .map(|job| {
                let q = &self.queries[job.query];
                let frames: Vec<u64> =
                    by_distance(&self.dataset, &self.cloud_frames[q.cloud], &job.initial)?
                        .into_iter()
                        .take(local.frames)
                        .map(|(f, ..)| f)
                        .collect();
                let options = rgbd::FuseOptions {
                    min_frames: self.spec.fuse.min_frames.min(frames.len() as u32),
                    ..self.spec.fuse
                };
                let (cloud, _) = self
                    .dataset
                    .fuse(&frames, options, |_, _| {})
                    .with_context(|| {
                        format!(
                            "the local map of query {} from start {} (frames {frames:?})",
                            q.frame, job.start
                        )
                    })?;
                Ok(((job.query, job.start.clone()), cloud))
            })
            .collect()
    }

    fn run_job(
        &self,
        job: &Job,
        local_clouds: &HashMap<(usize, String), PointCloud>,
        progress: &Progress,
    ) -> anyhow::Result<(Outcome, String)> {
        let q = &self.queries[job.query];
        let cloud = &self.clouds[q.cloud];
        let (camera, picture) = match (&self.catadioptric, job.catadioptric) {
            (Some((camera, pictures)), true) => (camera, &pictures[job.query]),
            _ => (&self.camera, &self.pictures[job.query]),
        };
        if job.reference {
            // The paper's gain, no damping, no lengthened steps and the paper's
            // convergence thresholds: small steps down to the optimum.
            let paper = VvsConfig::default();
            let config = VvsConfig {
                stall_window: 0,
                max_iterations: 400,
                gain: paper.gain,
                levenberg_marquardt: paper.levenberg_marquardt,
                extrapolate_steps: paper.extrapolate_steps,
                converged_translation_m: paper.converged_translation_m,
                converged_rotation_rad: paper.converged_rotation_rad,
                converged_px: paper.converged_px,
                ..BenchMethod::parse("povs")?.config()
            };
            let outcome =
                Servo::new(cloud, camera, config)?.run(Method::Povs, picture, job.initial)?;
            return Ok((outcome, "reference".into()));
        }
        if job.global {
            let settings = self.spec.global.as_ref().expect("global settings");
            let mut config = BenchMethod::parse("localizer")?.config();
            config.global.grid_spacing_m = settings.grid_spacing_m;
            // A search here takes tens of seconds: its phase beside the bar.
            let outcome = Servo::new(cloud, camera, config)?.localize_in_box_with_progress(
                picture,
                job.initial,
                &settings.prior,
                &mut |p| {
                    progress.note(&format!(
                        "query {}: global search, {} {}/{}",
                        q.frame,
                        p.phase.name(),
                        p.done,
                        p.total
                    ))
                },
            )?;
            return Ok((outcome, "global".into()));
        }
        let method = job.method.expect("a method");
        if job.local {
            let local = self.spec.local_map.as_ref().expect("local map settings");
            let cloud = local_clouds
                .get(&(job.query, job.start.clone()))
                .expect("a local cloud for every local job");
            let outcome = Servo::new(cloud, camera, method.config())?.run(
                method.method,
                picture,
                job.initial,
            )?;
            return Ok((outcome, format!("{}@local{}", method.name(), local.frames)));
        }
        let outcome =
            Servo::new(cloud, camera, method.config())?.run(method.method, picture, job.initial)?;
        Ok((outcome, method.name()))
    }

    /// Every localisation of the benchmark, with progress; records in job order.
    pub fn localize(&self) -> anyhow::Result<Vec<RunRecord>> {
        let jobs = self.jobs()?;
        let local_clouds = self.local_clouds(&jobs)?;
        let progress = Progress::new(jobs.len() as u64, "localisations");
        let outcomes = jobs
            .par_iter()
            .map(|job| {
                let result = self.run_job(job, &local_clouds, &progress);
                progress.inc(1, "");
                result
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        progress.finish();
        let ucm_name = self
            .spec
            .catadioptric
            .as_ref()
            .map(|c| format!("ucm-xi{}", c.xi))
            .unwrap_or_default();
        let mut records: Vec<RunRecord> = jobs
            .iter()
            .zip(outcomes)
            .map(|(job, (outcome, method))| {
                let q = &self.queries[job.query];
                let (start_m, start_rad) = job.initial.distance_to(&q.truth);
                let (error_m, error_rad) = outcome.world_from_camera.distance_to(&q.truth);
                let diverged = matches!(outcome.stop, StopReason::Diverged(_));
                let r = outcome.world_from_camera.to_pose_vector();
                RunRecord {
                    query: q.frame,
                    kind: q.kind,
                    camera: if job.catadioptric {
                        ucm_name.clone()
                    } else {
                        "pinhole".into()
                    },
                    start: job.start.clone(),
                    start_error_m: start_m,
                    start_error_deg: start_rad.to_degrees(),
                    method,
                    stop: outcome.stop.to_string(),
                    iterations: outcome.iterations[0] + outcome.iterations[1],
                    error_m,
                    error_deg: error_rad.to_degrees(),
                    to_reference_m: None,
                    to_reference_deg: None,
                    success: !diverged
                        && outcome.cost.is_finite()
                        && error_m < self.spec.success_m
                        && error_rad.to_degrees() < self.spec.success_deg,
                    time_s: outcome.time_s,
                    tx: r[0],
                    ty: r[1],
                    tz: r[2],
                    wx: r[3],
                    wy: r[4],
                    wz: r[5],
                }
            })
            .collect();
        // Distances to each query's reference (its photometric optimum).
        let references: Vec<(u64, String, Isometry3)> = records
            .iter()
            .filter(|r| r.method == "reference")
            .map(|r| {
                let pose = Isometry3::from_pose_vector([r.tx, r.ty, r.tz, r.wx, r.wy, r.wz])?;
                Ok((r.query, r.camera.clone(), pose))
            })
            .collect::<anyhow::Result<_>>()?;
        for record in records.iter_mut().filter(|r| !r.method.contains("@local")) {
            if let Some((_, _, reference)) = references
                .iter()
                .find(|(q, c, _)| *q == record.query && *c == record.camera)
            {
                let pose = Isometry3::from_pose_vector([
                    record.tx, record.ty, record.tz, record.wx, record.wy, record.wz,
                ])?;
                let (m, rad) = pose.distance_to(reference);
                record.to_reference_m = Some(m);
                record.to_reference_deg = Some(rad.to_degrees());
            }
        }
        Ok(records)
    }

    /// `[pose_check]`: each query's depth picture aligned, from its truth, to each of
    /// its cloud's nearest frames alone and to them together (`rgbd::align_depth`).
    /// Queries one after the other (memory: the frames' surfaces of one query), the
    /// alignments of a query in parallel.
    pub fn check_poses(&self) -> anyhow::Result<Vec<PoseCheckRecord>> {
        let Some(check) = &self.spec.pose_check else {
            return Ok(Vec::new());
        };
        let sensor = self.dataset.sensor();
        let depth_camera = &sensor.depth_camera;
        let options = rgbd::AlignOptions::default();
        eprintln!(
            "aligning each query's depth to its {} nearest frames'",
            check.frames
        );
        let progress = Progress::new(self.queries.len() as u64, "queries");
        let mut out = Vec::new();
        for q in &self.queries {
            let mut near = by_distance(&self.dataset, &self.cloud_frames[q.cloud], &q.truth)?;
            near.truncate(check.frames);
            let surfaces = near
                .par_iter()
                .map(|&(f, ..)| {
                    let depth = self.dataset.read_depth(f)?;
                    Ok(rgbd::Surface::new(
                        &depth,
                        depth_camera,
                        &self.dataset.world_from_depth(f)?,
                        options.max_depth_jump,
                    )?)
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            let depth = self.dataset.read_depth(q.frame)?;
            let start = self.dataset.world_from_depth(q.frame)?;
            let mut targets: Vec<(String, &[rgbd::Surface], f64, f64)> = near
                .iter()
                .zip(surfaces.chunks(1))
                .map(|(&(f, _, t, r), one)| (format!("frame {f}"), one, t, r))
                .collect();
            if near.len() > 1 {
                targets.push((
                    format!("{} nearest frames", near.len()),
                    &surfaces,
                    near.iter().map(|n| n.2).fold(0.0, f64::max),
                    near.iter().map(|n| n.3).fold(0.0, f64::max),
                ));
            }
            let rows: Vec<PoseCheckRecord> = targets
                .par_iter()
                .map(|(against, targets, distance_m, angle_deg)| {
                    let found = rgbd::align_depth(&depth, depth_camera, &start, targets, &options);
                    let mut record = PoseCheckRecord {
                        query: q.frame,
                        against: against.clone(),
                        frames: targets.len(),
                        distance_m: *distance_m,
                        angle_deg: *angle_deg,
                        correction_m: None,
                        correction_deg: None,
                        rms_before_mm: None,
                        rms_after_mm: None,
                        pairs_before: None,
                        pairs_after: None,
                        conditioning: None,
                        failure: String::new(),
                    };
                    match found {
                        Ok(a) => {
                            let aligned = sensor.world_from_color(&a.world_from_depth);
                            let (m, rad) = aligned.distance_to(&q.truth);
                            record.correction_m = Some(m);
                            record.correction_deg = Some(rad.to_degrees());
                            // No pair at the truth: no RMS there (not a NaN).
                            record.rms_before_mm =
                                a.rms_before_m.is_finite().then_some(1e3 * a.rms_before_m);
                            record.rms_after_mm =
                                a.rms_after_m.is_finite().then_some(1e3 * a.rms_after_m);
                            record.pairs_before = Some(a.pairs_before);
                            record.pairs_after = Some(a.pairs_after);
                            record.conditioning = Some(a.conditioning);
                        }
                        Err(e) => record.failure = e.to_string(),
                    }
                    record
                })
                .collect();
            out.extend(rows);
            progress.inc(1, "");
        }
        progress.finish();
        Ok(out)
    }

    /// Every track of `[tracking]`, frame after frame, with progress.
    pub fn track(&self) -> anyhow::Result<Vec<TrackRecord>> {
        let Some(spec) = &self.spec.tracking else {
            return Ok(Vec::new());
        };
        let frames = crate::parse_frames(&spec.frames)?;
        ensure!(
            self.clouds.len() == 1,
            "tracking needs one map cloud (split kind = \"map\")"
        );
        let map = &self.cloud_frames[0];
        ensure!(
            frames.iter().all(|f| !map.contains(f)),
            "tracked frames must be held out of the map"
        );
        let full_camera = self.dataset.sensor().color_camera.clone();
        let pictures = frames
            .par_iter()
            .map(|&f| {
                load_picture(
                    &self.dataset,
                    f,
                    &full_camera,
                    &self.camera,
                    self.spec.downsample,
                )
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let truths = frames
            .iter()
            .map(|&f| Ok(self.dataset.world_from_color(f)?))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let methods = spec
            .methods
            .iter()
            .map(|m| BenchMethod::parse(m))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let mut tracks: Vec<(BenchMethod, vvs::Prediction, usize)> = Vec::new();
        for &prediction in &spec.predictions {
            for &method in &methods {
                for &step in &spec.frame_steps {
                    tracks.push((method, prediction, step));
                }
            }
        }
        let total: usize = tracks.iter().map(|t| frames.len().div_ceil(t.2)).sum();
        let progress = Progress::new(total as u64, "tracked frames");
        let results = tracks
            .par_iter()
            .map(|&(method, prediction, step)| {
                let name = match prediction {
                    vvs::Prediction::Last => method.name(),
                    other => format!("{} ({})", method.name(), other.name().replace('_', " ")),
                };
                let servo = Servo::new(&self.clouds[0], &self.camera, method.config())?;
                let mut tracker =
                    Tracker::new(servo, method.method, truths[0])?.with_prediction(prediction);
                let mut records = Vec::new();
                let mut lost = false;
                for k in (0..frames.len()).step_by(step) {
                    let started = Instant::now();
                    let outcome = tracker.align(&pictures[k])?;
                    let (m, rad) = tracker.estimate().distance_to(&truths[k]);
                    lost |= tracker.is_lost() || m > spec.lost_threshold_m;
                    records.push(TrackRecord {
                        method: name.clone(),
                        frame_step: step,
                        frame: frames[k],
                        error_m: m,
                        error_deg: rad.to_degrees(),
                        stop: outcome.stop.to_string(),
                        iterations: outcome.iterations[0] + outcome.iterations[1],
                        time_s: started.elapsed().as_secs_f64(),
                        lost,
                    });
                    progress.inc(1, "");
                    if tracker.is_lost() {
                        // Its alignment diverged: the tracker takes no more frames.
                        progress.inc(((frames.len() - k - 1) / step) as u64, "");
                        break;
                    }
                }
                Ok(records)
            })
            .collect::<anyhow::Result<Vec<Vec<TrackRecord>>>>()?;
        progress.finish();
        Ok(results.into_iter().flatten().collect())
    }
}

/// A query's picture at the benchmark's resolution.
fn load_picture(
    dataset: &rgbd::RgbdDataset,
    frame: u64,
    full_camera: &Camera,
    camera: &Camera,
    downsample: u32,
) -> anyhow::Result<Image> {
    let picture = Image::load(dataset.color_path(frame)?, full_camera, None)?;
    Ok(if downsample > 1 {
        picture.downsampled(downsample, camera)?
    } else {
        picture
    })
}

/// Prepare and run a benchmark: its pose check, its localisations and its tracks.
pub fn run_benchmark(spec: RealSpec, data: &Path) -> anyhow::Result<(Benchmark, RealResults)> {
    let benchmark = Benchmark::prepare(spec, data)?;
    let poses = benchmark.check_poses()?;
    let runs = benchmark.localize()?;
    let tracks = benchmark.track()?;
    Ok((
        benchmark,
        RealResults {
            runs,
            tracks,
            poses,
        },
    ))
}
