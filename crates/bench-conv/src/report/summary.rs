//! The summary of a protocol's runs: per-method statistics, the Markdown table with
//! the paper's rates beside ours, and the cumulative-distribution plot of Fig. 3.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use vvs::{Method, PgmJacobian};

use super::RunRecord;

/// A method configuration's name as the protocol writes it for the paper's
/// configurations: `method` (`povs`) or `method/jacobian` (`rule2/convolved`,
/// `rule1/paper-margin3`), parsed by [`Method`]'s and [`PgmJacobian`]'s `FromStr`.
/// `None` for any other name, such as a variant's (`rule2/convolved+lm`, `rule2-lm`).
///
/// Only names as the protocol spells them count: the `FromStr`s also take other cases
/// and surrounding spaces (`Rule2`, ` paper`), which a variant's free name may hold.
pub fn parse_config_name(name: &str) -> Option<(Method, Option<PgmJacobian>)> {
    let (method_name, jacobian_name) = match name.split_once('/') {
        Some((method, jacobian)) => (method, Some(jacobian)),
        None => (name, None),
    };
    let method = method_name
        .parse::<Method>()
        .ok()
        .filter(|m| m.name() == method_name)?;
    let jacobian = match jacobian_name {
        Some(text) if text.trim() != text => return None,
        Some(text) => Some(text.parse::<PgmJacobian>().ok()?),
        None => None,
    };
    Some((method, jacobian))
}

/// The paper's success rate (§3.2) of one of its configurations, by configuration name
/// (`povs`, `rule0/convolved`, `rule2/paper`, … : [`parse_config_name`]); `None` for
/// the variants beyond it and for the global search.
pub fn paper_success_rate(config: &str) -> Option<f64> {
    let (method, _) = parse_config_name(config)?;
    match method {
        Method::Rule2 => Some(97.0),
        Method::Rule1 => Some(78.0),
        Method::Rule0 => Some(70.0),
        Method::Povs => Some(0.0),
        Method::Global => None,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Per-method statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSummary {
    /// Method configuration name (`rule2/convolved`, `povs`, a variant's name).
    pub config: String,
    /// Runs.
    pub runs: usize,
    /// Successful runs.
    pub successes: usize,
    /// Median final position error, metres.
    pub median_position_error_m: f64,
    /// Median final rotation error, degrees.
    pub median_rotation_error_deg: f64,
    /// Median total iterations.
    pub median_iterations: f64,
    /// Median wall time per run, seconds.
    pub median_wall_time_s: f64,
    /// Total wall time of the method's runs, seconds.
    pub total_wall_time_s: f64,
}

/// Statistics of every method, by method name (a stable order whatever the shard).
pub fn summarize(records: &[RunRecord]) -> Vec<MethodSummary> {
    let mut groups: BTreeMap<&str, Vec<&RunRecord>> = BTreeMap::new();
    for r in records {
        groups.entry(&r.config).or_default().push(r);
    }
    groups
        .into_iter()
        .map(|(m, g)| MethodSummary {
            config: m.to_string(),
            runs: g.len(),
            successes: g.iter().filter(|r| r.success).count(),
            median_position_error_m: median(g.iter().map(|r| r.final_position_error_m).collect()),
            median_rotation_error_deg: median(
                g.iter().map(|r| r.final_rotation_error_deg).collect(),
            ),
            median_iterations: median(
                g.iter()
                    .map(|r| (r.iterations_step1 + r.iterations_step2) as f64)
                    .collect(),
            ),
            median_wall_time_s: median(g.iter().map(|r| r.wall_time_s).collect()),
            total_wall_time_s: g.iter().map(|r| r.wall_time_s).sum(),
        })
        .collect()
}

/// The Markdown summary table, with the paper's figures beside ours.
pub fn summary_markdown(
    title: &str,
    records: &[RunRecord],
    threshold_m: f64,
    wall_time_s: Option<f64>,
) -> String {
    let mut s = format!("# {title}\n\n");
    let _ = writeln!(
        s,
        "Success: final position error < {:.0} cm. {} runs.{}\n",
        threshold_m * 100.0,
        records.len(),
        wall_time_s.map_or(String::new(), |t| format!(
            " Wall time {:.1} min.",
            t / 60.0
        ))
    );
    s.push_str("| method | runs | success | paper | median position error | median rotation error | median iterations | median time per run |\n");
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for m in summarize(records) {
        let paper =
            paper_success_rate(&m.config).map_or("—".to_string(), |p| format!("{p:.0} %"));
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} % ({}) | {} | {:.4} m | {:.3}° | {:.0} | {:.1} s |",
            m.config,
            m.runs,
            100.0 * m.successes as f64 / m.runs.max(1) as f64,
            m.successes,
            paper,
            m.median_position_error_m,
            m.median_rotation_error_deg,
            m.median_iterations,
            m.median_wall_time_s
        );
    }
    s.push_str("\nThe paper's rates (§3.2) are for its own scans of four streets and its own camera; see the project's notes for why ours differ.\n");
    s
}

/// Plot the cumulative distribution of the final position errors per method (log
/// error axis, threshold marked), as PNG and SVG.
pub fn plot_cdf(
    records: &[RunRecord],
    threshold_m: f64,
    png: &Path,
    svg: &Path,
) -> anyhow::Result<()> {
    let summaries = summarize(records);
    let series: Vec<(String, Vec<f64>)> = summaries
        .iter()
        .map(|m| {
            let errors: Vec<f64> = records
                .iter()
                .filter(|r| r.config == m.config)
                .map(|r| r.final_position_error_m)
                .collect();
            // One decimal, so that 3 and 5 successes of 448 (0.7 and 1.1 %) read apart.
            let label = format!(
                "{} ({:.1} %, {}/{})",
                m.config,
                100.0 * m.successes as f64 / errors.len().max(1) as f64,
                m.successes,
                errors.len()
            );
            (label, errors)
        })
        .collect();
    plot_error_cdf(
        "Cumulative distribution of final position errors",
        [1e-4, 100.0],
        &series,
        threshold_m,
        png,
        svg,
    )
}

/// The cumulative distribution of each series' errors (label, final position errors
/// in metres, clamped to `range_m`), on a log scale, with a line at `threshold_m`;
/// written as PNG and SVG.
pub(crate) fn plot_error_cdf(
    title: &str,
    range_m: [f64; 2],
    series: &[(String, Vec<f64>)],
    threshold_m: f64,
    png: &Path,
    svg: &Path,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::register_font();
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        title: &str,
        [lo, hi]: [f64; 2],
        series: &[(String, Vec<f64>)],
        threshold_m: f64,
    ) -> anyhow::Result<()> {
        root.fill(&WHITE).map_err(crate::plot::error)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d((lo..hi).log_scale(), 0.0f64..100.0)
            .map_err(crate::plot::error)?;
        chart
            .configure_mesh()
            .x_desc("final position error (m)")
            .y_desc("runs (%)")
            .draw()
            .map_err(crate::plot::error)?;
        crate::plot::line(
            &mut chart,
            vec![(threshold_m, 0.0), (threshold_m, 100.0)],
            format!("{:.0} cm threshold", threshold_m * 100.0),
            BLACK.stroke_width(1),
        )?;
        for (i, (label, errors)) in series.iter().enumerate() {
            let mut errors: Vec<f64> = errors.iter().map(|e| e.clamp(lo, hi)).collect();
            errors.sort_by(f64::total_cmp);
            let n = errors.len() as f64;
            let mut points = vec![(lo, 0.0)];
            for (k, e) in errors.iter().enumerate() {
                points.push((*e, 100.0 * k as f64 / n));
                points.push((*e, 100.0 * (k + 1) as f64 / n));
            }
            points.push((hi, 100.0));
            let color = Palette99::pick(i).to_rgba();
            crate::plot::line(&mut chart, points, label.clone(), color.stroke_width(2))?;
        }
        crate::plot::finish(&mut chart, &root)
    }
    let range = [range_m[0], range_m[1]];
    draw(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        title,
        range,
        series,
        threshold_m,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw(
        SVGBackend::new(svg, (900, 600)).into_drawing_area(),
        title,
        range,
        series,
        threshold_m,
    )
    .with_context(|| format!("plotting {}", svg.display()))
}
