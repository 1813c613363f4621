//! The benchmark's results: `runs.csv`, `tracking.csv`, `summary.md`, the error plots
//! (PNG and SVG) and, per query, the picture beside the rendering at the localiser's
//! estimate.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use frame::Frame;
use splat::{RenderOptions, Renderer};
use ucm::Isometry3;

use super::run::{Benchmark, PoseCheckRecord, QueryKind, RealResults, RunRecord, TrackRecord};
use crate::csv_io;
use crate::report::write_atomically;

fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The order of first appearance of the values of `key`.
fn ordered<'a>(records: &'a [RunRecord], key: impl Fn(&'a RunRecord) -> &'a str) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for r in records {
        let k = key(r);
        if !out.contains(&k) {
            out.push(k);
        }
    }
    out
}

/// The table of one camera's runs: per query kind and start, per method, successes and
/// median errors.
fn runs_table(text: &mut String, records: &[&RunRecord], spec_m: f64, spec_deg: f64) {
    let _ = writeln!(
        text,
        "| queries | start | method | within {:.0} cm and {spec_deg}° | median error | median rotation error | median to the photometric optimum | median iterations | median time |\n|---|---|---|---:|---:|---:|---:|---:|---:|",
        spec_m * 100.0
    );
    let owned: Vec<RunRecord> = records.iter().map(|r| (*r).clone()).collect();
    let kinds: Vec<QueryKind> = {
        let mut k: Vec<QueryKind> = Vec::new();
        for r in &owned {
            if !k.contains(&r.kind) {
                k.push(r.kind);
            }
        }
        k
    };
    for kind in kinds {
        let of_kind: Vec<RunRecord> = owned.iter().filter(|r| r.kind == kind).cloned().collect();
        for start in ordered(&of_kind, |r| &r.start) {
            for method in ordered(&of_kind, |r| &r.method) {
                let runs: Vec<&RunRecord> = of_kind
                    .iter()
                    .filter(|r| r.start == start && r.method == method)
                    .collect();
                if runs.is_empty() {
                    continue;
                }
                let successes = runs.iter().filter(|r| r.success).count();
                let to_reference: Vec<f64> = runs.iter().filter_map(|r| r.to_reference_m).collect();
                let _ = writeln!(
                    text,
                    "| {} | {start} | {method} | {successes}/{} | {:.1} cm | {:.2}° | {} | {:.0} | {:.2} s |",
                    kind.name(),
                    runs.len(),
                    100.0 * median(runs.iter().map(|r| r.error_m).collect()),
                    median(runs.iter().map(|r| r.error_deg).collect()),
                    if to_reference.is_empty() || method == "reference" {
                        "—".to_string()
                    } else {
                        format!("{:.1} cm", 100.0 * median(to_reference))
                    },
                    median(runs.iter().map(|r| r.iterations as f64).collect()),
                    median(runs.iter().map(|r| r.time_s).collect()),
                );
            }
        }
    }
}

/// Tracking: per method and N, frames used, lost, RMSE and largest error.
fn tracking_table(text: &mut String, tracks: &[TrackRecord], threshold_m: f64) {
    let _ = writeln!(
        text,
        "| method | N | frames used | lost (diverged or > {:.0} cm) | RMSE | largest error | median rotation error | median time per frame |\n|---|---:|---:|---|---:|---:|---:|---:|",
        threshold_m * 100.0
    );
    let mut keys: Vec<(String, usize)> = Vec::new();
    for t in tracks {
        let key = (t.method.clone(), t.frame_step);
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    for (method, step) in keys {
        let frames: Vec<&TrackRecord> = tracks
            .iter()
            .filter(|t| t.method == method && t.frame_step == step)
            .collect();
        let lost = frames
            .iter()
            .find(|t| t.lost)
            .map_or("never".to_string(), |t| format!("at frame {}", t.frame));
        let rmse = (frames.iter().map(|t| t.error_m * t.error_m).sum::<f64>()
            / frames.len().max(1) as f64)
            .sqrt();
        let largest = frames.iter().map(|t| t.error_m).fold(0.0, f64::max);
        let _ = writeln!(
            text,
            "| {method} | {step} | {} | {lost} | {:.1} cm | {:.1} cm | {:.2}° | {:.2} s |",
            frames.len(),
            100.0 * rmse,
            100.0 * largest,
            median(frames.iter().map(|t| t.error_deg).collect()),
            median(frames.iter().map(|t| t.time_s).collect()),
        );
    }
}

/// `[pose_check]`: per query, its depth aligned to its nearest frame, the frame that
/// moves it most, and its nearest frames together.
fn pose_check_table(text: &mut String, poses: &[PoseCheckRecord]) {
    let cell = |r: &PoseCheckRecord| match (r.correction_m, r.correction_deg) {
        (Some(m), Some(deg)) => format!("{:.1} cm, {deg:.2}°", 100.0 * m),
        _ => format!("failed: {}", r.failure),
    };
    let rms = |r: &PoseCheckRecord| match (r.rms_before_mm, r.rms_after_mm) {
        (Some(a), Some(b)) => format!("{a:.1} → {b:.1} mm"),
        _ => "—".into(),
    };
    let together = poses.iter().map(|r| r.frames).max().unwrap_or(0);
    let _ = writeln!(
        text,
        "| query | its nearest frame: correction | RMS at the truth → aligned | the frame that moves it most: correction | that frame's distance | {together} nearest together: correction | RMS at the truth → aligned |\n|---:|---|---|---|---:|---|---|"
    );
    let mut queries: Vec<u64> = Vec::new();
    for r in poses {
        if !queries.contains(&r.query) {
            queries.push(r.query);
        }
    }
    for q in queries {
        let rows: Vec<&PoseCheckRecord> = poses.iter().filter(|r| r.query == q).collect();
        let singles: Vec<&&PoseCheckRecord> = rows.iter().filter(|r| r.frames == 1).collect();
        let Some(nearest) = singles.first() else {
            continue;
        };
        let most = singles
            .iter()
            .max_by(|a, b| {
                a.correction_m
                    .unwrap_or(f64::INFINITY)
                    .total_cmp(&b.correction_m.unwrap_or(f64::INFINITY))
            })
            .expect("one frame at least");
        let all = rows.iter().find(|r| r.frames > 1);
        let _ = writeln!(
            text,
            "| {q} | {} ({}) | {} | {} ({}) | {:.2} m, {:.1}° | {} | {} |",
            cell(nearest),
            nearest.against,
            rms(nearest),
            cell(most),
            most.against,
            most.distance_m,
            most.angle_deg,
            all.map_or("—".into(), |r| cell(r)),
            all.map_or("—".into(), |r| rms(r)),
        );
    }
}

/// The picture (left), the rendering at `pose` (middle) and their superimposition
/// (right: the picture in red, the rendering in green and blue), side by side.
fn write_comparison(
    benchmark: &Benchmark,
    query: usize,
    pose: &Isometry3,
    path: &Path,
) -> anyhow::Result<()> {
    let q = &benchmark.queries[query];
    let camera = &benchmark.camera;
    let picture = &benchmark.pictures[query];
    let mut renderer = Renderer::new(
        camera.clone(),
        RenderOptions {
            parallel: false,
            ..RenderOptions::default()
        },
    )?;
    let mut frame = Frame::for_camera(camera);
    renderer.render(&benchmark.clouds[q.cloud], &pose.inverse(), &mut frame)?;
    let (w, h) = (camera.width(), camera.height());
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let mut out = image::RgbImage::new(3 * w, h);
    for y in 0..h {
        for x in 0..w {
            let k = (y * w + x) as usize;
            let p = if picture.valid[k] {
                to_u8(picture.intensity[k])
            } else {
                0
            };
            let r = match frame.status[k] {
                frame::PixelStatus::Masked => 0,
                _ => to_u8(frame.intensity[k]),
            };
            out.put_pixel(x, y, image::Rgb([p, p, p]));
            out.put_pixel(w + x, y, image::Rgb([r, r, r]));
            out.put_pixel(2 * w + x, y, image::Rgb([p, r, r]));
        }
    }
    out.save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// The cumulative distribution of the pinhole runs' errors off the truth, per method.
fn plot_errors(
    records: &[RunRecord],
    threshold_m: f64,
    png: &Path,
    svg: &Path,
) -> anyhow::Result<()> {
    let pinhole: Vec<&RunRecord> = records
        .iter()
        .filter(|r| r.camera == "pinhole" && r.start != "truth")
        .collect();
    let mut series: Vec<(String, Vec<f64>)> = Vec::new();
    for r in &pinhole {
        match series.iter_mut().find(|(m, _)| *m == r.method) {
            Some((_, errors)) => errors.push(r.error_m),
            None => series.push((r.method.clone(), vec![r.error_m])),
        }
    }
    crate::report::plot_error_cdf(
        "Cumulative distribution of final position errors (pinhole, starts off the truth)",
        [1e-3, 10.0],
        &series,
        threshold_m,
        png,
        svg,
    )
}

/// The tracking errors per frame, one line per track.
fn plot_tracks(tracks: &[TrackRecord], png: &Path, svg: &Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        tracks: &[TrackRecord],
    ) -> anyhow::Result<()> {
        root.fill(&WHITE).map_err(crate::plot::error)?;
        let first = tracks.iter().map(|t| t.frame).min().unwrap_or(0) as f64;
        let last = tracks.iter().map(|t| t.frame).max().unwrap_or(1) as f64;
        let mut chart = ChartBuilder::on(&root)
            .caption("Tracking: position error per frame", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(first..last.max(first + 1.0), (1e-3f64..10.0f64).log_scale())
            .map_err(crate::plot::error)?;
        chart
            .configure_mesh()
            .x_desc("frame")
            .y_desc("position error (m)")
            .draw()
            .map_err(crate::plot::error)?;
        let mut keys: Vec<(String, usize)> = Vec::new();
        for t in tracks {
            let key = (t.method.clone(), t.frame_step);
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        for (i, (method, step)) in keys.iter().enumerate() {
            let points: Vec<(f64, f64)> = tracks
                .iter()
                .filter(|t| &t.method == method && t.frame_step == *step)
                .map(|t| (t.frame as f64, t.error_m.clamp(1e-3, 10.0)))
                .collect();
            let color = Palette99::pick(i).to_rgba();
            crate::plot::line(
                &mut chart,
                points,
                format!("{method} N={step}"),
                color.stroke_width(2),
            )?;
        }
        crate::plot::finish(&mut chart, &root)
    }
    draw(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        tracks,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw(SVGBackend::new(svg, (900, 600)).into_drawing_area(), tracks)
        .with_context(|| format!("plotting {}", svg.display()))
}

/// Write every result of a benchmark under `out` and return the summary.
pub fn write_results(
    benchmark: &Benchmark,
    results: &RealResults,
    wall_time_s: f64,
    out: &Path,
) -> anyhow::Result<String> {
    let spec = &benchmark.spec;
    let records = &results.runs;
    let tracks = &results.tracks;
    csv_io::write_table(&out.join("runs.csv"), records)?;
    plot_errors(
        records,
        spec.success_m,
        &out.join("errors.png"),
        &out.join("errors.svg"),
    )?;
    let mut text = format!("# Real pictures: {}\n\n", spec.name);
    let points: Vec<String> = benchmark
        .clouds
        .iter()
        .map(|c| c.len().to_string())
        .collect();
    let _ = writeln!(
        text,
        "{} queries of {}×{} pixels; {} cloud(s) of {} points fused from RGB-D frames ({}); {} localisations in {:.1} min.\n",
        benchmark.queries.len(),
        benchmark.camera.width(),
        benchmark.camera.height(),
        benchmark.clouds.len(),
        points.join(", "),
        match &spec.split {
            super::Split::LeaveOneOut { .. } => "each query left out of its cloud".to_string(),
            super::Split::Map { .. } => format!("{} map frames", benchmark.cloud_frames[0].len()),
        },
        records.len(),
        wall_time_s / 60.0,
    );
    let _ = writeln!(
        text,
        "Success: within {:.0} cm and {}° of the truth. *To the photometric optimum*: the distance to the query's reference, PoVS from the truth on the common support run until it converges (where the picture and the cloud agree best).\n",
        spec.success_m * 100.0,
        spec.success_deg
    );
    let _ = writeln!(
        text,
        "## Queries\n\n| frame | kind | nearest frame of its cloud | its distance | its angle |\n|---:|---|---:|---:|---:|"
    );
    for q in &benchmark.queries {
        let _ = writeln!(
            text,
            "| {} | {} | {} | {:.2} m | {:.1}° |",
            q.frame,
            q.kind.name(),
            q.nearest.0,
            q.nearest.2,
            q.nearest.3
        );
    }
    if !results.poses.is_empty() {
        csv_io::write_table(&out.join("poses.csv"), &results.poses)?;
        let _ = writeln!(
            text,
            "\n## The dataset's poses, by geometry alone\n\nEach query's depth picture aligned from its truth to the depth pictures of its cloud's nearest frames, each alone and all together (point-to-plane ICP, `rgbd::align_depth`; colour plays no part). *Correction*: how far the alignment moves the query's colour camera from its truth. Where a frame moves it by centimetres, that frame's pose and the query's disagree by as much, and a cloud fused with that frame places the query's surfaces elsewhere than its truth does (`poses.csv`).\n"
        );
        pose_check_table(&mut text, &results.poses);
    }
    for camera in ordered(records, |r| &r.camera) {
        let runs: Vec<&RunRecord> = records.iter().filter(|r| r.camera == camera).collect();
        let _ = writeln!(text, "\n## Localisation, {camera} pictures\n");
        runs_table(&mut text, &runs, spec.success_m, spec.success_deg);
    }
    if !tracks.is_empty() {
        csv_io::write_table(&out.join("tracking.csv"), tracks)?;
        plot_tracks(tracks, &out.join("tracking.png"), &out.join("tracking.svg"))?;
        let threshold = spec.tracking.as_ref().map_or(0.2, |t| t.lost_threshold_m);
        let _ = writeln!(
            text,
            "\n## Tracking\n\nEach track starts at the truth of its first frame; every used frame is aligned from the estimate of the one before (with *constant velocity*: from the last motion between aligned frames repeated).\n"
        );
        tracking_table(&mut text, tracks, threshold);
    }
    // The picture beside the rendering at the localiser's estimate, from the first start
    // that is not the truth.
    let pictures = out.join("pictures");
    std::fs::create_dir_all(&pictures)
        .with_context(|| format!("creating {}", pictures.display()))?;
    for (index, q) in benchmark.queries.iter().enumerate() {
        let Some(run) = records.iter().find(|r| {
            r.query == q.frame
                && r.camera == "pinhole"
                && r.method == "localizer"
                && r.start != "truth"
        }) else {
            continue;
        };
        let pose = Isometry3::from_pose_vector([run.tx, run.ty, run.tz, run.wx, run.wy, run.wz])?;
        write_comparison(
            benchmark,
            index,
            &pose,
            &pictures.join(format!("{}.png", q.frame)),
        )?;
    }
    let _ = writeln!(
        text,
        "\n`pictures/<frame>.png`: the picture, the rendering at the localiser's estimate from the first start off the truth, and both superimposed (picture red, rendering cyan). `runs.csv`, `errors.png/svg`{}{}.",
        if tracks.is_empty() {
            ""
        } else {
            ", `tracking.csv`, `tracking.png/svg`"
        },
        if results.poses.is_empty() {
            ""
        } else {
            ", `poses.csv`"
        }
    );
    write_atomically(&out.join("summary.md"), text.as_bytes())?;
    Ok(text)
}
