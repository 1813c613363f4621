//! The convergence domain: success by method and offset scale (`domain.csv`, its
//! Markdown table and plot), and `bench-conv domain`'s results folder.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, ensure};
use serde::{Deserialize, Serialize};

use super::{
    RunRecord, axis_basins, axis_basins_markdown, begin_results, finish_results, write_atomically,
};
use crate::csv_io;

/// The success of one method at one offset scale: a point of the domain curve.
#[derive(Clone, Debug, PartialEq)]
pub struct DomainPoint {
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// Scale of the protocol's offsets.
    pub offset_scale: f64,
    /// Runs at this scale.
    pub runs: usize,
    /// Successful runs.
    pub successes: usize,
}

impl DomainPoint {
    /// Success rate, percent.
    pub fn rate(&self) -> f64 {
        100.0 * self.successes as f64 / self.runs.max(1) as f64
    }
}

/// The domain curve: success by method and offset scale (methods by name, scales
/// increasing).
pub fn domain(records: &[RunRecord]) -> Vec<DomainPoint> {
    let mut groups: BTreeMap<(&str, u64), (f64, usize, usize)> = BTreeMap::new();
    for r in records {
        // Scales are positive, so their bits order as the values.
        let entry = groups
            .entry((&r.config, r.offset_scale.to_bits()))
            .or_insert((r.offset_scale, 0, 0));
        entry.1 += 1;
        entry.2 += usize::from(r.success);
    }
    groups
        .into_iter()
        .map(
            |((method, _), (offset_scale, runs, successes))| DomainPoint {
                config: method.to_string(),
                offset_scale,
                runs,
                successes,
            },
        )
        .collect()
}

fn scales_of(points: &[DomainPoint]) -> Vec<f64> {
    let mut scales: Vec<f64> = points.iter().map(|p| p.offset_scale).collect();
    scales.sort_by(f64::total_cmp);
    scales.dedup();
    scales
}

/// The domain curve as a Markdown table: a row per method, a column per scale.
pub fn domain_markdown(points: &[DomainPoint]) -> String {
    let scales = scales_of(points);
    let mut s = String::from("| method |");
    for scale in &scales {
        let _ = write!(s, " s = {scale} |");
    }
    s.push_str("\n|---|");
    s.push_str(&"---:|".repeat(scales.len()));
    s.push('\n');
    let mut methods: Vec<&str> = points.iter().map(|p| p.config.as_str()).collect();
    methods.dedup();
    for method in methods {
        let _ = write!(s, "| {method} |");
        for scale in &scales {
            match points
                .iter()
                .find(|p| p.config == method && p.offset_scale == *scale)
            {
                Some(p) => {
                    let _ = write!(s, " {:.1} % ({}/{}) |", p.rate(), p.successes, p.runs);
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s
}

/// A row of `domain.csv`: a [`DomainPoint`] and its rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct DomainRow {
    config: String,
    #[serde(serialize_with = "csv_io::display")]
    offset_scale: f64,
    runs: usize,
    successes: usize,
    /// [`DomainPoint::rate`], two decimals (a reader takes the counts instead).
    #[serde(serialize_with = "csv_io::fixed::<2, _>")]
    success_percent: f64,
}

/// Write the domain curve as CSV (`config,offset_scale,runs,successes,success_percent`),
/// atomically.
pub fn write_domain_csv(path: &Path, points: &[DomainPoint]) -> anyhow::Result<()> {
    let rows: Vec<DomainRow> = points
        .iter()
        .map(|p| DomainRow {
            config: p.config.clone(),
            offset_scale: p.offset_scale,
            runs: p.runs,
            successes: p.successes,
            success_percent: p.rate(),
        })
        .collect();
    csv_io::write_records(path, &rows)
}

/// Read a domain curve written by [`write_domain_csv`].
pub fn read_domain_csv(path: &Path) -> anyhow::Result<Vec<DomainPoint>> {
    let rows: Vec<DomainRow> = csv_io::read_records(path, "domain CSV")?;
    Ok(rows
        .into_iter()
        .map(|r| DomainPoint {
            config: r.config,
            offset_scale: r.offset_scale,
            runs: r.runs,
            successes: r.successes,
        })
        .collect())
}

/// Plot the domain curve (success against offset scale, a line per method) as PNG and
/// SVG.
pub fn plot_domain(points: &[DomainPoint], png: &Path, svg: &Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    draw_domain(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        points,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw_domain(SVGBackend::new(svg, (900, 600)).into_drawing_area(), points)
        .with_context(|| format!("plotting {}", svg.display()))?;
    Ok(())
}

fn draw_domain<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    points: &[DomainPoint],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let largest = scales_of(points).last().copied().unwrap_or(1.0);
    root.fill(&WHITE).map_err(crate::plot::error)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Convergence domain: success against the scale of the offsets",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0f64..largest * 1.05, 0.0f64..105.0)
        .map_err(crate::plot::error)?;
    chart
        .configure_mesh()
        .x_desc("offset scale s (1: the protocol's offsets)")
        .y_desc("runs converged (%)")
        .draw()
        .map_err(crate::plot::error)?;
    let mut methods: Vec<&str> = points.iter().map(|p| p.config.as_str()).collect();
    methods.dedup();
    for (i, method) in methods.into_iter().enumerate() {
        let line: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.config == method)
            .map(|p| (p.offset_scale, p.rate()))
            .collect();
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, color.filled())),
            )
            .map_err(crate::plot::error)?;
        crate::plot::line(&mut chart, line, method, color.stroke_width(2))?;
    }
    crate::plot::finish(&mut chart, &root)
}

/// The convergence domain from finished runs, into `out` (created): the curve of every
/// method over the runs of `curve` (each element the rows of one results folder;
/// `domain.csv`, `domain.png`, `domain.svg`) and, from an axes protocol and its rows,
/// the basin along each axis; both as Markdown in `domain.md`, which is returned.
/// `force`: as [`begin_results`]'s.
pub fn write_domain(
    out: &Path,
    curve: &[Vec<RunRecord>],
    axes: Option<&(crate::protocol::Protocol, Vec<RunRecord>)>,
    force: bool,
) -> anyhow::Result<String> {
    let records: Vec<RunRecord> = curve.iter().flatten().cloned().collect();
    ensure!(!records.is_empty(), "the results folders hold no run");
    let points = domain(&records);
    let _lock = begin_results(out, force)?;
    let mut text = String::from(
        "# The convergence domain\n\nSuccess (final position error below the protocol's \
         threshold) against the scale s of every offset of the protocol (s = 1: the \
         paper's offsets); the runs behind each cell are given beside its rate.\n\n",
    );
    text.push_str(&domain_markdown(&points));
    write_domain_csv(&out.join("domain.csv"), &points)?;
    plot_domain(&points, &out.join("domain.png"), &out.join("domain.svg"))?;
    if let Some((protocol, rows)) = axes {
        ensure!(
            protocol.offsets.sampling == crate::protocol::Sampling::Axes,
            "the axes protocol `{}` does not sample along the axes (sampling = \"axes\")",
            protocol.name
        );
        let (t, r) = (
            protocol.offsets.translation_m,
            protocol.offsets.rotation_deg,
        );
        let _ = write!(
            text,
            "\n## The basin along each axis alone\n\nProtocol `{}`: one offset at a time, \
             both signs, every desired pose, at scales {:?} of the magnitudes below; the \
             largest offset from which every run along the axis converged, at that and \
             every smaller scale ({} runs{}).\n\n",
            protocol.name,
            protocol.offsets.scales,
            rows.len(),
            if protocol.offsets.adaptive {
                "; adaptive: a method stops along an axis after its first failing scale"
            } else {
                ""
            }
        );
        let top = protocol.offsets.scales.iter().copied().fold(0.0, f64::max);
        text.push_str(&axis_basins_markdown(
            &axis_basins(rows),
            [t[0], t[1], t[2], r[0], r[1], r[2]],
            top,
        ));
    }
    write_atomically(&out.join("domain.md"), text.as_bytes())?;
    finish_results(out)?;
    Ok(text)
}
