//! The experiment harness and command-line tools of the project.
//!
//! The `bench-conv` binary hosts the tools a user needs to look at data:
//!
//! * `bench-conv city --out city.las [--seed N] [--spacing-m S] [--textures DIR]`:
//!   generate the synthetic city and write it as a cloud file (LAS, LAZ, PLY, E57);
//! * `bench-conv render --camera CAM.toml (--cloud FILE.las | --city-seed N)
//!   (--pose tx,ty,tz,θwx,θwy,θwz | --looking-down x,y,z,heading_deg) --out IMG.png`:
//!   render a cloud at a pose, and report what was drawn.
//!
//! * `bench-conv run PROTOCOL.toml --out DIR [--shard i/n] [--extras]`: run a
//!   convergence protocol (format in [`protocol`]) and write `runs.csv`, `summary.md`
//!   and the cumulative distribution `cdf.png` / `cdf.svg` under `DIR`;
//! * `bench-conv merge SHARD.csv... --out DIR`: merge shards run on several machines
//!   (the merge of all shards equals a single run);
//! * `bench-conv pgm-image --image IMG --mei-yaml CALIB --crop x,y,w,h --out DIR`: the
//!   PGM of a real catadioptric image at several λ (the paper's Fig. 1);
//! * `bench-conv track SEQUENCE.toml --out DIR`: generate a shaken sequence with
//!   acquired-looking images ([`world::sequence`]) and track it by successive alignments
//!   ([`tracking`], the paper's §4): `frames.csv`, `summary.md`, trajectory and error
//!   plots, and the superimpositions of the paper's Fig. 4d–e;
//! * `bench-conv fuse --dataset D.toml --data DIR --frames 0-999/10 --out C.laz`: fuse
//!   RGB-D frames into a coloured cloud ([`rgbd`]);
//! * `bench-conv real BENCH.toml --data DIR --out DIR`: the real-data benchmark
//!   ([`real`]): real photographs localised and tracked in clouds fused from RGB-D
//!   frames;
//! * `bench-conv check PROTOCOL.toml --out DIR [--quick] [--extras]` and
//!   `bench-conv check-track SEQUENCE.toml --out DIR`: check a results folder against
//!   the file that made it ([`check`]).
#![deny(missing_docs)]

pub mod check;
pub mod csv_io;
pub mod progress;
pub mod protocol;
pub mod real;
pub mod real_image;
pub mod report;
pub mod run;
pub mod tracking;

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use ucm::Isometry3;

/// Read and parse a TOML file (`what` names it in errors); returns the value and the
/// file's folder, against which the paths it holds are resolved ([`resolve`]).
pub fn load_toml<T: serde::de::DeserializeOwned>(
    path: &Path,
    what: &str,
) -> anyhow::Result<(T, PathBuf)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading {what} {}", path.display()))?;
    let value =
        toml::from_str(&text).with_context(|| format!("parsing {what} {}", path.display()))?;
    Ok((value, path.parent().unwrap_or(Path::new(".")).to_path_buf()))
}

/// `path` resolved against `base_dir` when relative.
pub fn resolve(base_dir: &Path, path: &Path) -> PathBuf {
    if path.is_relative() {
        base_dir.join(path)
    } else {
        path.to_path_buf()
    }
}

/// Parse `N` comma-separated pixel counts (`x,y,width,height`…): non-negative integers
/// that fit in `u32`, nothing else (`-10`, `1e10`, `nan`, `2.5` are errors).
pub fn parse_pixels<const N: usize>(text: &str) -> anyhow::Result<[u32; N]> {
    let values: Vec<u32> = text
        .split(',')
        .map(|s| {
            s.trim().parse::<u32>().with_context(|| {
                format!(
                    "`{}` is not a pixel count (an integer from 0 to {})",
                    s.trim(),
                    u32::MAX
                )
            })
        })
        .collect::<anyhow::Result<_>>()?;
    if values.len() != N {
        bail!(
            "expected {N} comma-separated integers, got {}",
            values.len()
        );
    }
    let mut out = [0; N];
    out.copy_from_slice(&values);
    Ok(out)
}

/// Parse `N` comma-separated numbers.
pub fn parse_numbers<const N: usize>(text: &str) -> anyhow::Result<[f64; N]> {
    let values: Vec<f64> = text
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .with_context(|| format!("`{s}` is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    if values.len() != N {
        bail!("expected {N} comma-separated numbers, got {}", values.len());
    }
    let mut out = [0.0; N];
    out.copy_from_slice(&values);
    Ok(out)
}

/// `world_from_camera` from the command line's `--pose` (the paper's `(t, θw)`) or
/// `--looking-down` (`x, y, z, heading_deg`): a [`protocol::PoseSpec`].
pub fn parse_pose(pose: Option<&str>, looking_down: Option<&str>) -> anyhow::Result<Isometry3> {
    let pose = pose.map(parse_numbers::<6>).transpose()?;
    let looking_down = looking_down.map(parse_numbers::<4>).transpose()?;
    protocol::PoseSpec::from_options(looking_down, pose)?.world_from_camera()
}

/// Check the `frame_steps` of a tracking experiment over `frames` frames (1 frame in
/// N for each N): a non-empty list, each N at least 1, below the frame count (else
/// the track holds one frame), and listed once.
pub fn check_frame_steps(steps: &[usize], frames: usize) -> anyhow::Result<()> {
    anyhow::ensure!(
        !steps.is_empty() && steps.iter().all(|&n| n >= 1),
        "frame_steps must be a non-empty list of N >= 1"
    );
    let mut sorted = steps.to_vec();
    sorted.sort_unstable();
    if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
        anyhow::bail!("frame_steps lists {} twice", w[0]);
    }
    if let Some(n) = sorted.iter().find(|&&n| n >= frames) {
        anyhow::bail!(
            "frame_steps: 1 frame in {n} of {frames} frames tracks one frame (N must be \
             below the frame count)"
        );
    }
    Ok(())
}

/// Parse a list of frame numbers: comma-separated numbers and inclusive ranges
/// `first-last`, a range optionally stepped (`0-999/10`: 0, 10, …, 990), in the order
/// given, without repeats. At most [`rgbd::MAX_FRAMES`] frames.
pub fn parse_frames(text: &str) -> anyhow::Result<Vec<u64>> {
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (range, step) = match item.split_once('/') {
            Some((range, step)) => (
                range,
                step.trim()
                    .parse::<u64>()
                    .ok()
                    .filter(|&s| s > 0)
                    .with_context(|| format!("`{item}`: the step must be an integer >= 1"))?,
            ),
            None => (item, 1),
        };
        let number = |s: &str| {
            s.trim()
                .parse::<u64>()
                .with_context(|| format!("`{item}`: `{s}` is not a frame number"))
        };
        let (first, last) = match range.split_once('-') {
            Some((a, b)) => (number(a)?, number(b)?),
            None => (number(range)?, number(range)?),
        };
        if last < first {
            bail!("`{item}`: the range's last frame comes before its first");
        }
        let count = (last - first) / step + 1;
        if frames.len() as u64 + count > rgbd::MAX_FRAMES {
            bail!("more than {} frames", rgbd::MAX_FRAMES);
        }
        for k in (first..=last).step_by(step as usize) {
            if seen.insert(k) {
                frames.push(k);
            }
        }
    }
    if frames.is_empty() {
        bail!("no frame in `{text}`");
    }
    Ok(frames)
}

/// Register the plots' font (Hack, embedded by `epaint_default_fonts`) once, so that
/// plotting needs no system font.
pub fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Registration only fails on a malformed font, which the embedded one is not.
        let _ = plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            epaint_default_fonts::HACK_REGULAR,
        );
    });
}

/// What every chart of the harness shares: labelled lines and the legend.
pub(crate) mod plot {
    use plotters::coord::Shift;
    use plotters::prelude::*;

    /// A plotting error as an `anyhow` error.
    pub(crate) fn error<E: std::error::Error + Send + Sync>(
        e: DrawingAreaErrorKind<E>,
    ) -> anyhow::Error {
        anyhow::anyhow!("{e}")
    }

    /// Draw `points` as a line of `style`, listed in the legend as `label`.
    pub(crate) fn line<'a, DB, X, Y>(
        chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        points: Vec<(f64, f64)>,
        label: impl Into<String>,
        style: ShapeStyle,
    ) -> anyhow::Result<()>
    where
        DB: DrawingBackend + 'a,
        X: Ranged<ValueType = f64>,
        Y: Ranged<ValueType = f64>,
    {
        chart
            .draw_series(LineSeries::new(points, style))
            .map_err(error)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        Ok(())
    }

    /// Draw the legend (upper left, on white) and write the picture out.
    pub(crate) fn finish<'a, DB, X, Y>(
        chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        root: &DrawingArea<DB, Shift>,
    ) -> anyhow::Result<()>
    where
        DB: DrawingBackend + 'a,
        X: Ranged,
        Y: Ranged,
    {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(error)?;
        root.present().map_err(error)?;
        Ok(())
    }
}
