//! Tracking by successive alignments (paper §4), one module per concept:
//!
//! - [`sequence`]: the sequence file (format below);
//! - [`acquisition`]: the acquired images, rendered at the true poses and degraded;
//! - [`track`](mod@track): the tracking runs and the record of each aligned frame;
//! - [`frames_csv`]: the per-frame CSV (`frames.csv`);
//! - [`summary`]: per-track statistics and the Markdown summary;
//! - [`plots`]: the plots and the superimpositions of the paper's Fig. 4d–e.
//!
//! Every item is also here, at `tracking::`, where the rest of the harness names it;
//! [`write_results`] writes them all into a results folder.
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

pub mod acquisition;
pub mod frames_csv;
pub mod plots;
pub mod sequence;
pub mod summary;
pub mod track;

use std::path::Path;

use anyhow::Context;
use frame::{Frame, Image};
use splat::{PointCloud, RenderOptions, Renderer};
use ucm::{Camera, Isometry3};

pub use acquisition::acquire;
pub use frames_csv::{read_csv, write_csv};
pub use plots::{plot, write_overlay};
pub use sequence::SequenceSpec;
pub use summary::{TrackSummary, display_name, summarize, summary_markdown};
pub use track::{FrameRecord, TrackingResults, run_sequence, track};

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
