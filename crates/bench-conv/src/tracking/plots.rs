//! The plots of a tracking experiment (trajectories seen from above, position error
//! per frame, RMSE against N) and the superimpositions of the paper's Fig. 4d–e.

use std::path::Path;

use anyhow::{Context, ensure};
use frame::{Frame, Image};
use vvs::Method;

use super::{FrameRecord, TrackSummary, TrackingResults, display_name, summarize};

/// A plotted track: legend label, colour, points.
type Series = (String, plotters::style::RGBAColor, Vec<(f64, f64)>);

/// Every track as (legend label, colour, points given by `point`), in the order of
/// `results.lost`.
fn series(results: &TrackingResults, point: impl Fn(&FrameRecord) -> (f64, f64)) -> Vec<Series> {
    use plotters::style::{Color, Palette, Palette99};
    results
        .lost
        .iter()
        .enumerate()
        .map(|(i, (method, frame_step, _))| {
            (
                format!("{} N={frame_step}", display_name(*method)),
                Palette99::pick(i).to_rgba(),
                results.track(*method, *frame_step).map(&point).collect(),
            )
        })
        .collect()
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
    for (label, color, points) in series(results, |r| (r.estimated_pose[0], r.estimated_pose[1])) {
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
    for (label, color, points) in series(results, |r| {
        (r.frame as f64, r.position_error_m.clamp(1e-4, 10.0))
    }) {
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
