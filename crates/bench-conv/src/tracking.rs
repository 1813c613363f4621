//! Tracking by successive alignments (paper §4): the sequence file, the tracking runs,
//! their per-frame records, summary and plots.
//!
//! ```toml
//! name = "fig4"
//! camera = "omni-320x240.toml"     # camera TOML, relative to this file
//! methods = ["povs", "rule2"]      # PoT and PGMoT
//! frame_steps = [1, 2, 5, 10, 20]  # use 1 frame in N
//! lost_threshold_m = 0.5           # a track is lost beyond this position error
//! initial_offset = [0.05, -0.05, 0.02, 0.01, -0.01, 0.02]  # first frame's start, (t, θw) in the true camera's frame
//!
//! [scene]                          # as in a protocol file
//! kind = "city"
//! seed = 1
//!
//! [trajectory]                     # sequence::Trajectory (defaults: the paper's robot)
//! frames = 210
//! [trajectory.shake]               # sequence::Shake
//! [acquisition]                    # sequence::Acquisition
//! [vvs]                            # any vvs::VvsConfig field; normalize = true by default
//! ```
//!
//! Each track (method, N) aligns frames `0, N, 2N, …` of the sequence; frame `0`
//! starts from the true pose composed with `initial_offset`, every later one from the
//! previous frame's estimate. The brightness of the acquired and rendered images is
//! centred and normalised (the paper's §4) unless the file's `[vvs]` says otherwise.
//! A track stops at the first frame whose position error exceeds `lost_threshold_m`
//! (or whose optimisation diverges): it is lost.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use std::ops::ControlFlow;

use anyhow::{Context, bail, ensure};
use frame::{Frame, Image};
use rayon::prelude::*;
use serde::Deserialize;
use splat::{PointCloud, RenderOptions, Renderer};
use ucm::{Camera, Isometry3};
use vvs::{Method, Prediction, Recovery, Servo, StopReason, Tracker, VvsConfig};

use crate::progress::Progress;
use crate::protocol::Scene;
use world::sequence::{Acquisition, Trajectory};

/// A parsed sequence file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SequenceSpec {
    /// Name, used in titles.
    pub name: String,
    /// Camera TOML path (relative to the file).
    pub camera: PathBuf,
    /// Methods: `povs` (PoT) and PGM rules (PGMoT with `rule2`).
    pub methods: Vec<Method>,
    /// Frame steps N (use 1 frame in N).
    pub frame_steps: Vec<usize>,
    /// Position error beyond which a track is lost, metres.
    #[serde(default = "default_lost")]
    pub lost_threshold_m: f64,
    /// Offset of the first frame's initial pose from the truth, `(t, θw)` (m, rad) in
    /// the true camera's frame.
    #[serde(default = "default_initial_offset")]
    pub initial_offset: [f64; 6],
    /// Where each alignment starts ([`vvs::Prediction`]: `last`, the paper's and the
    /// default, `constant_velocity` or `constant_translation`).
    #[serde(default)]
    pub prediction: Prediction,
    /// Beyond the paper: a `[recovery]` table checks every alignment and searches again
    /// after a failed one ([`vvs::Recovery`]; absent: off, as in the paper).
    #[serde(default)]
    pub recovery: Option<Recovery>,
    /// The cloud.
    pub scene: Scene,
    /// The trajectory.
    #[serde(default)]
    pub trajectory: Trajectory,
    /// The acquired images.
    #[serde(default)]
    pub acquisition: Acquisition,
    /// Optimiser settings (TOML table of `vvs::VvsConfig` fields).
    #[serde(default)]
    pub vvs: toml::Table,
    /// The folder of the file (set when loading).
    #[serde(skip)]
    pub base_dir: PathBuf,
}

fn default_lost() -> f64 {
    0.5
}

fn default_initial_offset() -> [f64; 6] {
    [0.05, -0.05, 0.02, 0.01, -0.01, 0.02]
}

impl SequenceSpec {
    /// Load and check a sequence file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let (mut spec, base_dir): (SequenceSpec, _) = crate::load_toml(path, "sequence")?;
        spec.base_dir = base_dir;
        spec.check()?;
        Ok(spec)
    }

    fn check(&self) -> anyhow::Result<()> {
        ensure!(!self.methods.is_empty(), "the sequence names no method");
        crate::check_frame_steps(&self.frame_steps, self.trajectory.frames)?;
        ensure!(
            self.lost_threshold_m > 0.0 && self.lost_threshold_m.is_finite(),
            "lost_threshold_m must be > 0"
        );
        ensure!(
            self.initial_offset.iter().all(|v| v.is_finite()),
            "initial_offset must be finite"
        );
        if let Some(recovery) = &self.recovery {
            recovery.validate()?;
        }
        self.trajectory.validate()?;
        self.acquisition.validate()?;
        self.vvs_config()?;
        Ok(())
    }

    /// A path of the file, resolved against its folder.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        crate::resolve(&self.base_dir, path)
    }

    /// The optimiser configuration: the paper's defaults, brightness normalised (§4),
    /// then the file's `[vvs]` table.
    pub fn vvs_config(&self) -> anyhow::Result<VvsConfig> {
        let base = VvsConfig {
            normalize: true,
            keep_history: false,
            ..VvsConfig::default()
        };
        base.with_overrides(&self.vvs)
            .context("the sequence's [vvs] table")
    }

    /// The camera.
    pub fn load_camera(&self) -> anyhow::Result<Camera> {
        let path = self.resolve(&self.camera);
        Camera::load_toml(&path).with_context(|| format!("reading camera {}", path.display()))
    }

    /// The cloud the images are rendered from, and the cloud the acquired images are
    /// rendered from (another sampling of the generated city; the same LAS cloud).
    pub fn load_clouds(&self) -> anyhow::Result<(PointCloud, Option<PointCloud>)> {
        let (model, _) = self.scene.load(&self.base_dir, None)?;
        let acquired = match self.scene {
            Scene::City { .. } => {
                let seed = Some(self.acquisition.sampling_seed);
                Some(self.scene.load(&self.base_dir, seed)?.0)
            }
            Scene::File { .. } => None,
        };
        Ok((model, acquired))
    }
}

/// The acquired images of every frame in `needed` (others left empty), rendered at
/// the true poses and degraded ([`Acquisition::acquire`]).
pub fn acquire(
    cloud: &PointCloud,
    camera: &Camera,
    poses: &[Isometry3],
    trajectory: &Trajectory,
    acquisition: &Acquisition,
    needed: &[bool],
) -> anyhow::Result<Vec<Option<Image>>> {
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default())?;
    let mut frames = Vec::with_capacity(poses.len());
    for (k, pose) in poses.iter().enumerate() {
        if !needed[k] {
            frames.push(None);
            continue;
        }
        let mut frame = Frame::for_camera(camera);
        let stats = renderer.render(cloud, &pose.inverse(), &mut frame)?;
        if stats.pixels_hit == 0 {
            bail!("frame {k}: the camera sees no point of the cloud at its true pose");
        }
        frames.push(Some(acquisition.acquire(
            &frame,
            camera,
            k,
            trajectory.time_s(k),
        )));
    }
    Ok(frames)
}

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

/// A plotted track: legend label, colour, points.
type Series = (String, plotters::style::RGBAColor, Vec<(f64, f64)>);

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

    /// Every track as (legend label, colour, points given by `point`), in the order of
    /// `lost`, for the plots.
    fn series(&self, point: impl Fn(&FrameRecord) -> (f64, f64)) -> Vec<Series> {
        use plotters::style::{Color, Palette, Palette99};
        self.lost
            .iter()
            .enumerate()
            .map(|(i, (method, frame_step, _))| {
                (
                    format!("{} N={frame_step}", display_name(*method)),
                    Palette99::pick(i).to_rgba(),
                    self.track(*method, *frame_step).map(&point).collect(),
                )
            })
            .collect()
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

const CSV_HEADER: [&str; 23] = [
    "method",
    "frame_step",
    "frame",
    "time_s",
    "true_tx",
    "true_ty",
    "true_tz",
    "true_wx",
    "true_wy",
    "true_wz",
    "est_tx",
    "est_ty",
    "est_tz",
    "est_wx",
    "est_wy",
    "est_wz",
    "position_error_m",
    "rotation_error_deg",
    "iterations_step1",
    "iterations_step2",
    "stop",
    "recovered",
    "wall_time_s",
];

/// Write the per-frame CSV (through the `csv` crate; numbers in fixed formats, so
/// that two runs compare as text), atomically.
pub fn write_csv(path: &Path, records: &[FrameRecord]) -> anyhow::Result<()> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer.write_record(CSV_HEADER)?;
    for r in records {
        let mut row = vec![
            r.method.to_string(),
            r.frame_step.to_string(),
            r.frame.to_string(),
            format!("{:.6}", r.time_s),
        ];
        row.extend(
            r.true_pose
                .iter()
                .chain(&r.estimated_pose)
                .map(|v| format!("{v:.9}")),
        );
        row.extend([
            format!("{:.9}", r.position_error_m),
            format!("{:.6}", r.rotation_error_deg),
            r.iterations[0].to_string(),
            r.iterations[1].to_string(),
            r.stop.to_string(),
            r.recovered.to_string(),
            format!("{:.6}", r.wall_time_s),
        ]);
        writer.write_record(&row)?;
    }
    let bytes = writer.into_inner().context("encoding the tracking CSV")?;
    crate::report::write_atomically(path, &bytes)
}

/// Read a per-frame CSV written by [`write_csv`]; errors name the file, line and field.
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<FrameRecord>> {
    let mut records = Vec::new();
    for (line, f) in crate::report::csv_rows(path, &CSV_HEADER, "tracking CSV")? {
        macro_rules! parse {
            ($i:expr) => {
                f[$i].parse().with_context(|| {
                    format!(
                        "{}:{line}: field {}: `{}`",
                        path.display(),
                        CSV_HEADER[$i],
                        &f[$i]
                    )
                })?
            };
        }
        let mut true_pose = [0.0; 6];
        let mut estimated_pose = [0.0; 6];
        for j in 0..6 {
            true_pose[j] = parse!(4 + j);
            estimated_pose[j] = parse!(10 + j);
        }
        records.push(FrameRecord {
            method: parse!(0),
            frame_step: parse!(1),
            frame: parse!(2),
            time_s: parse!(3),
            true_pose,
            estimated_pose,
            position_error_m: parse!(16),
            rotation_error_deg: parse!(17),
            iterations: [parse!(18), parse!(19)],
            stop: parse!(20),
            recovered: parse!(21),
            wall_time_s: parse!(22),
        });
    }
    Ok(records)
}

/// Summary of one track.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackSummary {
    /// The method.
    pub method: Method,
    /// Frame step N.
    pub frame_step: usize,
    /// Frames aligned.
    pub frames: usize,
    /// Frames the track should have aligned.
    pub expected_frames: usize,
    /// Root mean square position error over the aligned frames, metres.
    pub rmse_position_m: f64,
    /// Root mean square rotation error, degrees.
    pub rmse_rotation_deg: f64,
    /// Position error at the last aligned frame (the drift), metres.
    pub final_drift_m: f64,
    /// Largest position error, metres.
    pub max_position_error_m: f64,
    /// Whether the track was lost, and at which frame.
    pub lost_at: Option<usize>,
    /// Mean wall time per frame, seconds.
    pub mean_time_per_frame_s: f64,
    /// Mean iterations per frame.
    pub mean_iterations: f64,
    /// Frames searched again after a failed alignment ([`vvs::Recovery`]).
    pub recoveries: usize,
}

/// Summarise every track, in the order of `lost`.
pub fn summarize(results: &TrackingResults) -> Vec<TrackSummary> {
    results
        .lost
        .iter()
        .map(|&(method, frame_step, lost)| {
            let rs: Vec<&FrameRecord> = results.track(method, frame_step).collect();
            let n = rs.len().max(1) as f64;
            let rms = |f: &dyn Fn(&FrameRecord) -> f64| {
                (rs.iter().map(|r| f(r).powi(2)).sum::<f64>() / n).sqrt()
            };
            TrackSummary {
                method,
                frame_step,
                frames: rs.len(),
                expected_frames: results.truth.len().div_ceil(frame_step),
                rmse_position_m: rms(&|r| r.position_error_m),
                rmse_rotation_deg: rms(&|r| r.rotation_error_deg),
                final_drift_m: rs.last().map_or(f64::NAN, |r| r.position_error_m),
                max_position_error_m: rs.iter().map(|r| r.position_error_m).fold(0.0, f64::max),
                lost_at: if lost {
                    rs.last().map(|r| r.frame)
                } else {
                    None
                },
                mean_time_per_frame_s: rs.iter().map(|r| r.wall_time_s).sum::<f64>() / n,
                mean_iterations: rs
                    .iter()
                    .map(|r| (r.iterations[0] + r.iterations[1]) as f64)
                    .sum::<f64>()
                    / n,
                recoveries: rs.iter().filter(|r| r.recovered).count(),
            }
        })
        .collect()
}

/// Display name of a method in tracking (the paper's PoT and PGMoT).
pub fn display_name(method: Method) -> String {
    match method {
        Method::Povs => "PoT".into(),
        Method::Rule2 => "PGMoT".into(),
        other => format!("PGMoT ({other})"),
    }
}

/// The Markdown summary table.
pub fn summary_markdown(title: &str, results: &TrackingResults, lost_threshold_m: f64) -> String {
    let mut s = format!("# {title}\n\n");
    // Distance travelled by the camera up to each frame, metres.
    let travelled: Vec<f64> = std::iter::once(0.0)
        .chain(results.truth.windows(2).scan(0.0, |d, w| {
            *d += (w[1].translation - w[0].translation).length();
            Some(*d)
        }))
        .collect();
    let _ = writeln!(
        s,
        "{} frames of ground truth over {:.1} m of path; a track is lost when its position \
         error exceeds {:.2} m or its optimisation diverges. Wall time {:.1} min.\n",
        results.truth.len(),
        travelled.last().copied().unwrap_or(0.0),
        lost_threshold_m,
        results.wall_time_s / 60.0
    );
    s.push_str("| method | N | frames | position RMSE | rotation RMSE | final drift | max error | lost | time per frame | iterations per frame | searches |\n");
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|\n");
    for t in summarize(results) {
        let _ = writeln!(
            s,
            "| {} | {} | {}/{} | {:.4} m | {:.3}° | {:.4} m | {:.4} m | {} | {:.2} s | {:.0} | {} |",
            display_name(t.method),
            t.frame_step,
            t.frames,
            t.expected_frames,
            t.rmse_position_m,
            t.rmse_rotation_deg,
            t.final_drift_m,
            t.max_position_error_m,
            t.lost_at
                .map_or("no".to_string(), |k| format!("at frame {k}")),
            t.mean_time_per_frame_s,
            t.mean_iterations,
            t.recoveries
        );
    }
    let lost: Vec<String> = summarize(results)
        .iter()
        .filter_map(|t| {
            t.lost_at.map(|k| {
                format!(
                    "{} N = {} (at frame {k}, {:.1} m along the path)",
                    display_name(t.method),
                    t.frame_step,
                    travelled.get(k).copied().unwrap_or(f64::NAN)
                )
            })
        })
        .collect();
    let _ = writeln!(
        s,
        "\nLost tracks: {}.",
        if lost.is_empty() {
            "none".to_string()
        } else {
            lost.join(", ")
        }
    );
    s.push_str(
        "\nPaper (§4, qualitative, against a Lidar SLAM trajectory): PoT drifts as N grows \
         and fails at N = 20; PGMoT keeps tracking.\n",
    );
    s
}

/// Plot the trajectories seen from above (ground truth and every track) and the
/// position error per frame, as PNG and SVG under `out`.
pub fn plot(results: &TrackingResults, out: &Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    let trajectories = |name: &str| out.join(name);
    draw_trajectories(
        BitMapBackend::new(&trajectories("trajectories.png"), (900, 700)).into_drawing_area(),
        results,
    )?;
    draw_trajectories(
        SVGBackend::new(&trajectories("trajectories.svg"), (900, 700)).into_drawing_area(),
        results,
    )?;
    draw_errors(
        BitMapBackend::new(&out.join("errors.png"), (900, 600)).into_drawing_area(),
        results,
    )?;
    draw_errors(
        SVGBackend::new(&out.join("errors.svg"), (900, 600)).into_drawing_area(),
        results,
    )?;
    let summaries = summarize(results);
    draw_rmse(
        BitMapBackend::new(&out.join("rmse.png"), (800, 600)).into_drawing_area(),
        &summaries,
    )?;
    draw_rmse(
        SVGBackend::new(&out.join("rmse.svg"), (800, 600)).into_drawing_area(),
        &summaries,
    )?;
    Ok(())
}

/// Position RMSE against the frame step N, a line per method through the tracks that
/// were not lost; a lost track is a cross at the top of the plot.
fn draw_rmse<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    summaries: &[TrackSummary],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    root.fill(&WHITE).map_err(crate::plot::error)?;
    let largest = summaries.iter().map(|t| t.frame_step).max().unwrap_or(1) as f64;
    let (top, bottom) = (1.0f64, 1e-3f64);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Position RMSE against N (crosses: lost)",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (0.8f64..largest * 1.25).log_scale(),
            (bottom..top).log_scale(),
        )
        .map_err(crate::plot::error)?;
    chart
        .configure_mesh()
        .x_desc("N (1 frame in N)")
        .y_desc("position RMSE (m)")
        .draw()
        .map_err(crate::plot::error)?;
    let mut methods: Vec<Method> = Vec::new();
    for t in summaries {
        if !methods.contains(&t.method) {
            methods.push(t.method);
        }
    }
    for (i, &method) in methods.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let tracks: Vec<&TrackSummary> = summaries.iter().filter(|t| t.method == method).collect();
        let kept: Vec<(f64, f64)> = tracks
            .iter()
            .filter(|t| t.lost_at.is_none())
            .map(|t| (t.frame_step as f64, t.rmse_position_m.clamp(bottom, top)))
            .collect();
        chart
            .draw_series(kept.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(crate::plot::error)?;
        chart
            .draw_series(
                tracks.iter().filter(|t| t.lost_at.is_some()).map(|t| {
                    Cross::new((t.frame_step as f64, 0.8 * top), 6, color.stroke_width(2))
                }),
            )
            .map_err(crate::plot::error)?;
        crate::plot::line(
            &mut chart,
            kept,
            display_name(method),
            color.stroke_width(2),
        )?;
    }
    crate::plot::finish(&mut chart, &root)
}

fn draw_trajectories<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    results: &TrackingResults,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    root.fill(&WHITE).map_err(crate::plot::error)?;
    let truth: Vec<(f64, f64)> = results
        .truth
        .iter()
        .map(|p| (p.translation.x, p.translation.y))
        .collect();
    // Frame the ground truth with a margin; lost tracks leave the plot.
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &truth {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = ((x1 - x0).max(y1 - y0) / 2.0 + 0.5).max(1.0);
    let mut chart = ChartBuilder::on(&root)
        .caption("Trajectories seen from above", ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(
            (cx - half * 1.3)..(cx + half * 1.3),
            (cy - half)..(cy + half),
        )
        .map_err(crate::plot::error)?;
    chart
        .configure_mesh()
        .x_desc("world X (m)")
        .y_desc("world Y (m)")
        .draw()
        .map_err(crate::plot::error)?;
    crate::plot::line(&mut chart, truth, "ground truth", BLACK.stroke_width(3))?;
    for (label, color, points) in results.series(|r| (r.estimated_pose[0], r.estimated_pose[1])) {
        crate::plot::line(&mut chart, points.clone(), label, color.stroke_width(2))?;
        chart
            .draw_series(
                points
                    .into_iter()
                    .map(|p| Circle::new(p, 2, color.filled())),
            )
            .map_err(crate::plot::error)?;
    }
    crate::plot::finish(&mut chart, &root)
}

fn draw_errors<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    results: &TrackingResults,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    root.fill(&WHITE).map_err(crate::plot::error)?;
    let frames = results.truth.len().max(2) as f64;
    let mut chart = ChartBuilder::on(&root)
        .caption("Position error per frame", ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..frames, (1e-4f64..10.0f64).log_scale())
        .map_err(crate::plot::error)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc("position error (m)")
        .draw()
        .map_err(crate::plot::error)?;
    for (label, color, points) in
        results.series(|r| (r.frame as f64, r.position_error_m.clamp(1e-4, 10.0)))
    {
        crate::plot::line(&mut chart, points, label, color.stroke_width(2))?;
    }
    crate::plot::finish(&mut chart, &root)
}

/// The superimposition of an acquired image (red) and the image rendered at the
/// estimated pose (green and blue), as the paper's Fig. 4d–e: where they agree the
/// picture is grey, where they differ colour fringes appear. Masked pixels are black.
pub fn write_overlay(acquired: &Image, rendered: &Frame, path: &Path) -> anyhow::Result<()> {
    ensure!(
        acquired.width() == rendered.width() && acquired.height() == rendered.height(),
        "overlay of images of different sizes"
    );
    let (w, h) = (acquired.width(), acquired.height());
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let mut image = image::RgbImage::new(w, h);
    for (i, pixel) in image.pixels_mut().enumerate() {
        if rendered.status[i] == frame::PixelStatus::Masked {
            continue;
        }
        let (a, r) = (to_u8(acquired.intensity[i]), to_u8(rendered.intensity[i]));
        *pixel = image::Rgb([a, r, r]);
    }
    image
        .save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// Write `frames.csv`, `summary.md`, the plots (`trajectories`, `errors`, PNG and
/// SVG), and for the largest N the last acquired image and, per method, the
/// superimposition of the acquired image and the image rendered at the estimate of the
/// last frame the track reached (`overlay-nN-METHOD-frameK.png`). Returns the summary.
pub fn write_results(
    spec: &SequenceSpec,
    camera: &Camera,
    cloud: &PointCloud,
    results: &TrackingResults,
    acquired: &[Option<Image>],
    out: &Path,
) -> anyhow::Result<String> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_csv(&out.join("frames.csv"), &results.records)?;
    let summary = summary_markdown(&spec.name, results, spec.lost_threshold_m);
    crate::report::write_atomically(&out.join("summary.md"), summary.as_bytes())?;
    plot(results, out)?;
    let Some(&n) = spec.frame_steps.iter().max() else {
        return Ok(summary);
    };
    let last = results.truth.len().saturating_sub(1) / n * n;
    if let Some(frame) = &acquired[last] {
        frame.save_png(out.join(format!("acquired-n{n}-frame{last}.png")))?;
        let mut renderer = Renderer::new(camera.clone(), RenderOptions::default())?;
        for method in &spec.methods {
            let name = *method;
            // The estimate at the last frame the track reached.
            let Some(r) = results.track(name, n).next_back() else {
                continue;
            };
            let pose = Isometry3::from_pose_vector(r.estimated_pose)?;
            let mut rendered = Frame::for_camera(camera);
            renderer.render(cloud, &pose.inverse(), &mut rendered)?;
            let target = acquired[r.frame].as_ref().unwrap_or(frame);
            write_overlay(
                target,
                &rendered,
                &out.join(format!(
                    "overlay-n{n}-{}-frame{}.png",
                    display_name(name),
                    r.frame
                )),
            )?;
        }
    }
    Ok(summary)
}
