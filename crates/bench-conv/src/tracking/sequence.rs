//! The sequence file: the scene, camera, trajectory, acquisition, methods and frame
//! steps of a tracking experiment (format in [`super`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, ensure};
use serde::Deserialize;
use splat::PointCloud;
use ucm::Camera;
use vvs::{Method, Prediction, Recovery, VvsConfig};
use world::sequence::{Acquisition, Trajectory};

use crate::protocol::Scene;

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
