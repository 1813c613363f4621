//! The benchmark file ([`RealSpec`]) and its methods ([`BenchMethod`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use serde::Deserialize;
use vvs::{Localizer, Method, PgmJacobian, PriorBox, Support, Tracker, VvsConfig};

/// A benchmark file (format in the [module documentation](super)).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealSpec {
    /// Name of the benchmark (titles, results).
    pub name: String,
    /// The dataset's description, relative to the benchmark file.
    pub dataset: PathBuf,
    /// The pictures are used at 1/`downsample` of their resolution.
    #[serde(default = "one")]
    pub downsample: u32,
    /// Methods run from every start.
    pub methods: Vec<String>,
    /// Compute each query's photometric optimum.
    #[serde(default)]
    pub reference: bool,
    /// A localisation succeeds within this distance and angle of the truth.
    #[serde(default = "success_m")]
    pub success_m: f64,
    /// …and this angle, degrees.
    #[serde(default = "success_deg")]
    pub success_deg: f64,
    /// The fusion of the clouds.
    #[serde(default)]
    pub fuse: rgbd::FuseOptions,
    /// Clouds and queries.
    pub split: Split,
    /// Where localisations start.
    pub starts: Starts,
    /// A global search inside a box that holds the truth.
    #[serde(default)]
    pub global: Option<GlobalSpec>,
    /// Tracking frame after frame.
    #[serde(default)]
    pub tracking: Option<TrackingSpec>,
    /// The queries resampled to a catadioptric camera.
    #[serde(default)]
    pub catadioptric: Option<CatadioptricSpec>,
    /// Each query's depth picture aligned to its cloud's nearest frames' (geometry
    /// alone): how well the dataset's poses agree with each other.
    #[serde(default)]
    pub pose_check: Option<PoseCheckSpec>,
    /// Each query also localised in a cloud of the map frames nearest its start.
    #[serde(default)]
    pub local_map: Option<LocalMapSpec>,
    /// The benchmark file's folder.
    #[serde(skip)]
    pub base_dir: PathBuf,
}

fn one() -> u32 {
    1
}

fn success_m() -> f64 {
    0.05
}

fn success_deg() -> f64 {
    2.0
}

/// How frames split into clouds and queries.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Split {
    /// Each frame a query, localised in the cloud of the others.
    LeaveOneOut {
        /// The frames (`1-5`).
        frames: String,
    },
    /// One cloud of map frames; queries near them and in a block held out of them.
    Map {
        /// The map frames (`0-999/10`).
        map: String,
        /// Frames left out of the map (`450-549`).
        #[serde(default)]
        exclude: Option<String>,
        /// Queries between map frames.
        near: String,
        /// Queries inside the excluded block.
        #[serde(default)]
        block: Option<String>,
    },
}

/// Where localisations start: the truth moved by each offset, in a seeded direction.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Starts {
    /// `[translation m, rotation deg]` of each start (`[0, 0]`: the truth).
    pub offsets: Vec<[f64; 2]>,
    /// Seed of the directions.
    #[serde(default)]
    pub seed: u64,
    /// Block queries also start from their nearest map frame's pose.
    #[serde(default)]
    pub nearest_map_frame: bool,
}

/// A global search (`Method::Global`) from each block query's nearest map frame (or,
/// without block queries, from the largest offset of every query).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlobalSpec {
    /// The box searched.
    pub prior: PriorBox,
    /// Largest distance between the search's grid nodes, metres.
    pub grid_spacing_m: [f64; 3],
}

/// Tracking frame after frame.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackingSpec {
    /// The frames tracked, in order (`450-549`); each track starts at the first's truth.
    pub frames: String,
    /// 1 frame in N.
    pub frame_steps: Vec<usize>,
    /// Methods (PoT: `povs`; PGMoT: `localizer` or a PGM rule).
    pub methods: Vec<String>,
    /// A frame farther than this from the truth is lost, metres (default 0.5, as the
    /// synthetic tracking's).
    #[serde(default = "lost_m")]
    pub lost_threshold_m: f64,
    /// Where each alignment starts (`vvs::Prediction`, default `["last"]`, the
    /// paper's): every method is tracked with each; a track with another prediction
    /// than `last` is named `method (prediction)`.
    #[serde(default = "last_only")]
    pub predictions: Vec<vvs::Prediction>,
}

fn lost_m() -> f64 {
    0.5
}

fn last_only() -> Vec<vvs::Prediction> {
    vec![vvs::Prediction::Last]
}

/// The queries resampled to a unified-central-model camera of the same pose.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CatadioptricSpec {
    /// The mirror parameter ξ.
    pub xi: f64,
    /// Methods run on the resampled queries.
    pub methods: Vec<String>,
}

/// The depth alignment of each query (`rgbd::align_depth`) against each of its cloud's
/// `frames` nearest frames alone and against them together.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseCheckSpec {
    /// How many of the cloud's frames nearest the query (at most 32).
    pub frames: usize,
}

/// Each query localised, from every start, in a cloud fused from the `frames` frames of
/// its cloud nearest that start (a keyframe map around the guess).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalMapSpec {
    /// How many frames (at most 32).
    pub frames: usize,
    /// Methods run in the local clouds; their runs are named `method@localN`.
    pub methods: Vec<String>,
}

/// The most frames a pose check or a local map takes.
pub const MAX_LOCAL_FRAMES: usize = 32;

/// A method of the benchmark: a rule, a Jacobian, the comparison.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BenchMethod {
    /// The method.
    pub method: Method,
    /// The PGM's Jacobian.
    pub jacobian: PgmJacobian,
    /// The pixels compared.
    pub support: Support,
    /// Whether this is `localizer` or `tracker` (their defaults, as they are).
    pub preset: Option<Preset>,
}

/// A method of the benchmark taken with its settings as the library gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// `localizer`: `vvs::Localizer::default()`.
    Localizer,
    /// `tracker`: Rule2 with `vvs::Tracker::default_config()`.
    Tracker,
}

impl BenchMethod {
    /// Parse `localizer`, `tracker` or `method[/jacobian][+region]`.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let text = text.trim();
        let defaults = Localizer::default();
        let preset = match text {
            "localizer" => Some(Preset::Localizer),
            "tracker" => Some(Preset::Tracker),
            _ => None,
        };
        if let Some(preset) = preset {
            let config = preset_config(preset);
            return Ok(Self {
                method: defaults.method,
                jacobian: config.jacobian,
                support: config.support,
                preset: Some(preset),
            });
        }
        let (name, support) = match text.strip_suffix("+region") {
            Some(name) => (name, Support::Region),
            None => (text, defaults.config.support),
        };
        let (method, jacobian) = match name.split_once('/') {
            Some((m, j)) => (m, j.parse::<PgmJacobian>()?),
            None => (name, defaults.config.jacobian),
        };
        let method: Method = method.parse()?;
        if method == Method::Global {
            bail!("`{text}`: the global search is the [global] table's");
        }
        Ok(Self {
            method,
            jacobian,
            support,
            preset: None,
        })
    }

    /// The name it was parsed from (canonical form).
    pub fn name(&self) -> String {
        match self.preset {
            Some(Preset::Localizer) => return "localizer".into(),
            Some(Preset::Tracker) => return "tracker".into(),
            None => {}
        }
        let mut name = match self.method {
            Method::Povs => "povs".to_string(),
            m => format!("{m}/{}", self.jacobian),
        };
        if self.support == Support::Region {
            name.push_str("+region");
        }
        name
    }

    /// Its optimiser settings, one thread per run: a preset's, or the localiser's with
    /// this Jacobian and comparison.
    pub fn config(&self) -> VvsConfig {
        let base = preset_config(self.preset.unwrap_or(Preset::Localizer));
        VvsConfig {
            jacobian: self.jacobian,
            support: self.support,
            parallel: false,
            ..base
        }
    }
}

/// The settings of a preset.
fn preset_config(preset: Preset) -> VvsConfig {
    match preset {
        Preset::Localizer => Localizer::default().config,
        Preset::Tracker => Tracker::default_config(),
    }
}

impl RealSpec {
    /// Read and check a benchmark file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let (mut spec, base_dir): (RealSpec, PathBuf) = crate::load_toml(path, "benchmark")?;
        spec.base_dir = base_dir;
        spec.validate()
            .with_context(|| format!("benchmark {}", path.display()))?;
        Ok(spec)
    }

    fn validate(&self) -> anyhow::Result<()> {
        ensure!(
            (1..=8).contains(&self.downsample),
            "downsample must be in 1..=8, got {}",
            self.downsample
        );
        ensure!(!self.methods.is_empty(), "no method");
        self.methods()?;
        ensure!(!self.starts.offsets.is_empty(), "no start offset");
        for &[t, r] in &self.starts.offsets {
            ensure!(
                (0.0..=10.0).contains(&t) && (0.0..=90.0).contains(&r),
                "start offset [{t}, {r}]: the translation must be in [0, 10] m, the rotation in [0, 90]°"
            );
        }
        ensure!(
            self.success_m > 0.0 && self.success_deg > 0.0,
            "success thresholds must be > 0"
        );
        self.fuse.validate()?;
        match &self.split {
            Split::LeaveOneOut { frames } => {
                crate::parse_frames(frames).context("split.frames")?;
            }
            Split::Map {
                map,
                exclude,
                near,
                block,
            } => {
                crate::parse_frames(map).context("split.map")?;
                crate::parse_frames(near).context("split.near")?;
                for (name, text) in [("split.exclude", exclude), ("split.block", block)] {
                    if let Some(text) = text {
                        crate::parse_frames(text).context(name)?;
                    }
                }
            }
        }
        if let Some(global) = &self.global {
            global.prior.validate()?;
            ensure!(
                global
                    .grid_spacing_m
                    .iter()
                    .all(|&g| g > 0.0 && g.is_finite()),
                "global.grid_spacing_m must be > 0"
            );
        }
        if let Some(tracking) = &self.tracking {
            let frames = crate::parse_frames(&tracking.frames)
                .context("tracking.frames")?
                .len();
            crate::check_frame_steps(&tracking.frame_steps, frames).context("tracking")?;
            for m in &tracking.methods {
                BenchMethod::parse(m)?;
            }
            let mut predictions = tracking.predictions.clone();
            predictions.sort_by_key(|p| *p as u8);
            ensure!(
                !predictions.is_empty() && predictions.windows(2).all(|w| w[0] != w[1]),
                "tracking.predictions must list each prediction once"
            );
        }
        if let Some(check) = &self.pose_check {
            ensure!(
                (1..=MAX_LOCAL_FRAMES).contains(&check.frames),
                "pose_check.frames must be in 1..={MAX_LOCAL_FRAMES}, got {}",
                check.frames
            );
        }
        if let Some(local) = &self.local_map {
            ensure!(
                (1..=MAX_LOCAL_FRAMES).contains(&local.frames),
                "local_map.frames must be in 1..={MAX_LOCAL_FRAMES}, got {}",
                local.frames
            );
            ensure!(!local.methods.is_empty(), "local_map.methods is empty");
            for m in &local.methods {
                BenchMethod::parse(m)?;
            }
        }
        if let Some(c) = &self.catadioptric {
            ensure!(
                (0.0..=1.0).contains(&c.xi),
                "catadioptric.xi must be in [0, 1], got {}",
                c.xi
            );
            for m in &c.methods {
                BenchMethod::parse(m)?;
            }
        }
        Ok(())
    }

    /// The methods, parsed.
    pub fn methods(&self) -> anyhow::Result<Vec<BenchMethod>> {
        self.methods.iter().map(|m| BenchMethod::parse(m)).collect()
    }

    /// A path of the benchmark file, resolved against its folder.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        crate::resolve(&self.base_dir, path)
    }
}
