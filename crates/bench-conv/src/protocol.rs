//! The protocol file: which cloud, camera, desired poses, offsets, methods and budgets.
//!
//! ```toml
//! name = "fig3"
//! camera = "omni-320x240.toml"        # camera TOML, relative to this file
//! success_threshold_m = 0.02          # a run succeeds below this final position error
//! methods = ["povs", "rule0", "rule1", "rule2"]
//! jacobians = ["convolved", "paper"]  # every PGM method runs once per Jacobian; PoVS once
//! # initial_indices = [0, 63]         # optional subset of the 2^6 sign combinations
//!
//! [scene]
//! kind = "city"                       # the synthetic city: seed, spacing_m
//! seed = 1
//! spacing_m = 0.05
//! # street_width_m = 12.0, clutter = true, facade_detail = true  (the ablations)
//! # kind = "file", path = "cloud.e57"  # a LAS, LAZ, PLY or E57 file, relative to this file
//!
//! [offsets]                           # in the desired camera's frame
//! translation_m = [8.0, 2.0, 1.5]     # tX (along the street), tY (across), tZ (vertical)
//! rotation_deg = [10.0, 10.0, 15.0]   # θwX, θwY (tilts), θwZ (yaw)
//! # sampling = "corners"              # corners (64, the paper's), axes (12), uniform (64)
//! # scales = [0.25, 0.5, 0.75, 1.0]   # every initial pose at each scale of the offsets
//! # seed = 1                          # of the uniform draws
//! # adaptive = true                   # axes only: stop an axis beyond its basin
//!
//! # [prior]                           # the box of method "global" (default: [offsets])
//! # translation_m = [8.0, 2.0, 1.5]
//! # rotation_deg = [10.0, 10.0, 15.0]
//!
//! [[desired]]                         # world_from_camera of each desired camera, either
//! looking_down = [-40.0, 0.5, 3.0, 0.0]  # x, y, z (m) and heading (deg) of a camera looking down
//! # pose = [tx, ty, tz, θwx, θwy, θwz]  # or the paper's pose vector (m, rad)
//!
//! [vvs]                               # optional: any vvs::VvsConfig field (defaults: the paper's)
//! gain = 0.2
//!
//! [[variant]]                         # optional extra methods (run with --extras)
//! name = "rule2-lm"
//! method = "rule2"
//! jacobian = "convolved"
//! vvs = { levenberg_marquardt = 0.01 }
//! ```
//!
//! Every initial pose is `initial = desired · (t, θw)`, the offsets applied in the
//! desired camera's frame, each component scaled by the scale of the run:
//!
//! * `corners` (the paper's): initial pose `i` (0–63) takes the sign `−` for component
//!   `k` of `(tX, tY, tZ, θwX, θwY, θwZ)` where bit `k` of `i` is set, the magnitude of
//!   `[offsets]` for every component;
//! * `axes`: initial pose `i` (0–11) offsets component `i / 2` alone, positive for even
//!   `i`, negative for odd (the basin along each axis). With `adaptive = true` the
//!   scales run in increasing order and a method stops along an axis after the first
//!   scale at which one of its runs along that axis fails: the basin is the same as
//!   with every run, without the runs beyond it (such a protocol is not sharded);
//! * `uniform`: initial pose `i` (0–63) draws every component uniformly within
//!   `±[offsets]` (seeded by `seed`, the desired pose and `i`): starts anywhere inside
//!   the box rather than at its corners.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use serde::Deserialize;
use ucm::Isometry3;
use vvs::{Method, PgmJacobian, PriorBox, VvsConfig};

/// A parsed protocol file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Protocol {
    /// Name, used in result file names.
    pub name: String,
    /// Camera TOML path (relative to the protocol file).
    pub camera: PathBuf,
    /// Success threshold on the final position error, metres.
    #[serde(default = "default_threshold")]
    pub success_threshold_m: f64,
    /// Methods to run.
    pub methods: Vec<Method>,
    /// PGM Jacobians to run every PGM method with.
    pub jacobians: Vec<PgmJacobian>,
    /// Optional subset of the 64 initial poses.
    #[serde(default)]
    pub initial_indices: Option<Vec<usize>>,
    /// The cloud.
    pub scene: Scene,
    /// Offsets of the initial poses.
    pub offsets: Offsets,
    /// Desired poses.
    pub desired: Vec<PoseSpec>,
    /// The prior box of [`Method::Global`] (default: the unscaled `[offsets]`).
    #[serde(default)]
    pub prior: Option<PriorBox>,
    /// Optimiser settings.
    #[serde(default)]
    pub vvs: toml::Table,
    /// Extra methods (beyond the paper), run with `--extras`.
    #[serde(default)]
    pub variant: Vec<Variant>,
    /// The folder of the protocol file (set when loading).
    #[serde(skip)]
    pub base_dir: PathBuf,
}

fn default_threshold() -> f64 {
    0.02
}

/// The cloud of a protocol.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Scene {
    /// The synthetic city.
    City {
        /// Seed.
        seed: u64,
        /// Point spacing, metres.
        #[serde(default = "default_spacing")]
        spacing_m: f64,
        /// Facade-to-facade width of the streets, metres (default: the city's, 12).
        #[serde(default)]
        street_width_m: Option<f64>,
        /// Trees, lamps and parked cars (default true).
        #[serde(default = "yes")]
        clutter: bool,
        /// Windows, doors, shopfronts and the walls' fine texture (default true).
        #[serde(default = "yes")]
        facade_detail: bool,
    },
    /// A cloud file (LAS, LAZ, PLY or E57, told apart by content): `kind = "file"`
    /// (`"las"` is read as the same).
    #[serde(alias = "las")]
    File {
        /// Path, relative to the protocol file.
        path: PathBuf,
    },
}

impl Scene {
    /// Generate the city or read the cloud file (a relative path is resolved against
    /// `base_dir`); returns the cloud and a short name of the scene. `sampling_seed`
    /// resamples the city's surfaces ([`world::city::CityParams::sampling_seed`]).
    pub fn load(
        &self,
        base_dir: &Path,
        sampling_seed: Option<u64>,
    ) -> anyhow::Result<(splat::PointCloud, String)> {
        match self {
            Scene::City {
                seed,
                spacing_m,
                street_width_m,
                clutter,
                facade_detail,
            } => {
                let defaults = world::city::CityParams::default();
                let city = world::city::City::generate(&world::city::CityParams {
                    seed: *seed,
                    spacing_m: *spacing_m,
                    sampling_seed,
                    street_width_m: street_width_m.unwrap_or(defaults.street_width_m),
                    clutter: *clutter,
                    facade_detail: *facade_detail,
                    ..defaults
                })?;
                eprintln!(
                    "city seed {seed}: {} points in {:.1} s",
                    city.cloud.len(),
                    city.generation_time_s
                );
                Ok((city.cloud, format!("city-{seed}")))
            }
            Scene::File { path } => {
                let path = crate::resolve(base_dir, path);
                let (cloud, _, _) = cloud_io::read_cloud(&path)
                    .with_context(|| format!("reading {}", path.display()))?;
                let name = path
                    .file_stem()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned();
                Ok((cloud, name))
            }
        }
    }
}

fn default_spacing() -> f64 {
    0.05
}

fn yes() -> bool {
    true
}

/// Offsets of the initial poses.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Offsets {
    /// `|tX|, |tY|, |tZ|`, metres.
    pub translation_m: [f64; 3],
    /// `|θwX|, |θwY|, |θwZ|`, degrees.
    pub rotation_deg: [f64; 3],
    /// How the initial poses are drawn.
    #[serde(default)]
    pub sampling: Sampling,
    /// Scales of the offsets: every initial pose is run at each (the domain curve).
    #[serde(default = "default_scales")]
    pub scales: Vec<f64>,
    /// Seed of the `uniform` draws.
    #[serde(default)]
    pub seed: u64,
    /// With `axes`: run the scales in increasing order and stop a method along an axis
    /// after the first scale at which one of its runs along it fails (module docs).
    #[serde(default)]
    pub adaptive: bool,
}

fn default_scales() -> Vec<f64> {
    vec![1.0]
}

/// How the initial poses are drawn from `[offsets]` (module docs).
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Sampling {
    /// The 64 sign combinations of the offsets (the paper's).
    #[default]
    Corners,
    /// The 12 offsets along one axis, both signs.
    Axes,
    /// 64 offsets drawn uniformly within the box.
    Uniform,
}

impl Sampling {
    /// How many initial poses a desired pose has.
    pub fn count(self) -> usize {
        match self {
            Sampling::Corners | Sampling::Uniform => 64,
            Sampling::Axes => 12,
        }
    }
}

/// A pose as a user gives it, in a file (`pose = […]` or `looking_down = […]`, exactly
/// one) or on the command line (`--pose` or `--looking-down`, exactly one).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(try_from = "PoseFields")]
pub enum PoseSpec {
    /// `x, y, z` (m) and heading (deg) of a camera looking down.
    LookingDown([f64; 4]),
    /// The paper's pose vector `(t, θw)` of `world_from_camera` (m, rad).
    Pose([f64; 6]),
}

/// A [`PoseSpec`]'s table as written, before exactly one of its fields is checked.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseFields {
    #[serde(default)]
    looking_down: Option<[f64; 4]>,
    #[serde(default)]
    pose: Option<[f64; 6]>,
}

impl TryFrom<PoseFields> for PoseSpec {
    type Error = String;

    fn try_from(fields: PoseFields) -> Result<Self, String> {
        PoseSpec::from_options(fields.looking_down, fields.pose).map_err(|e| e.to_string())
    }
}

impl PoseSpec {
    /// The pose given by exactly one of `looking_down` and `pose`.
    pub fn from_options(
        looking_down: Option<[f64; 4]>,
        pose: Option<[f64; 6]>,
    ) -> anyhow::Result<Self> {
        match (looking_down, pose) {
            (Some(l), None) => Ok(PoseSpec::LookingDown(l)),
            (None, Some(r)) => Ok(PoseSpec::Pose(r)),
            _ => bail!("give exactly one of `looking_down` and `pose`"),
        }
    }

    /// `world_from_camera`.
    pub fn world_from_camera(&self) -> anyhow::Result<Isometry3> {
        match *self {
            PoseSpec::LookingDown(l) if !l.iter().all(|v| v.is_finite()) => {
                bail!("looking_down {l:?} is not finite")
            }
            PoseSpec::LookingDown([x, y, z, heading]) => Ok(world::city::camera_looking_down(
                glam::DVec3::new(x, y, z),
                heading.to_radians(),
            )),
            PoseSpec::Pose(r) => Ok(Isometry3::from_pose_vector(r)?),
        }
    }
}

/// An extra method.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    /// Name in the results.
    pub name: String,
    /// Method.
    pub method: Method,
    /// Jacobian (PGM methods).
    #[serde(default = "default_jacobian")]
    pub jacobian: PgmJacobian,
    /// Settings overriding the protocol's `[vvs]`.
    #[serde(default)]
    pub vvs: toml::Table,
}

fn default_jacobian() -> PgmJacobian {
    PgmJacobian::Convolved
}

/// One method configuration of a protocol: what a row of the summary is about.
#[derive(Clone, Debug)]
pub struct MethodConfig {
    /// Name in the results (`rule2/convolved`, `povs`, a variant's name).
    pub name: String,
    /// The method.
    pub method: Method,
    /// The optimiser settings.
    pub config: VvsConfig,
}

/// One run of a protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunSpec {
    /// Global index of the run (stable: shards and merges use it).
    pub id: usize,
    /// Index of the desired pose.
    pub desired: usize,
    /// Index of the offset scale in `[offsets] scales`.
    pub scale: usize,
    /// Index of the initial pose (0–63 or 0–11, see [`Sampling`]).
    pub initial: usize,
    /// Index of the method configuration.
    pub method: usize,
}

impl Protocol {
    /// Read and check a protocol file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let (mut protocol, base_dir): (Protocol, _) = crate::load_toml(path, "protocol")?;
        protocol.base_dir = base_dir;
        protocol.check()?;
        Ok(protocol)
    }

    fn check(&self) -> anyhow::Result<()> {
        if self.methods.is_empty() {
            bail!("the protocol names no method");
        }
        if self.desired.is_empty() {
            bail!("the protocol has no desired pose");
        }
        if self.methods.iter().any(|m| *m != Method::Povs) && self.jacobians.is_empty() {
            bail!("PGM methods need at least one Jacobian in `jacobians`");
        }
        if !(self.success_threshold_m > 0.0 && self.success_threshold_m.is_finite()) {
            bail!(
                "success_threshold_m must be finite and > 0, got {}",
                self.success_threshold_m
            );
        }
        let count = self.offsets.sampling.count();
        if let Some(indices) = &self.initial_indices {
            if let Some(bad) = indices.iter().find(|&&i| i >= count) {
                bail!("initial index {bad} is not in 0..{count}");
            }
            if indices.is_empty() {
                bail!("initial_indices is empty: the protocol would run nothing");
            }
            let mut sorted = indices.clone();
            sorted.sort_unstable();
            if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
                bail!("initial_indices lists {} twice", w[0]);
            }
        }
        let (t, r) = (self.offsets.translation_m, self.offsets.rotation_deg);
        if let Some(bad) = t.iter().find(|v| !(**v >= 0.0 && v.is_finite())) {
            bail!("[offsets] translation_m {bad} is not a finite length >= 0 (in {t:?})");
        }
        if let Some(bad) = r.iter().find(|v| !(**v >= 0.0 && **v <= 180.0)) {
            bail!("[offsets] rotation_deg {bad} is not an angle in [0, 180] (in {r:?})");
        }
        // Settings that a protocol sets elsewhere would be overwritten without a word.
        let tables = std::iter::once(("[vvs]".to_string(), &self.vvs)).chain(
            self.variant
                .iter()
                .map(|v| (format!("variant {}'s [vvs]", v.name), &v.vvs)),
        );
        for (name, table) in tables {
            if table.contains_key("jacobian") {
                bail!(
                    "{name} sets `jacobian`, which the protocol's `jacobians` list (or a \
                     variant's own `jacobian`) decides"
                );
            }
            if let Some(toml::Value::Table(global)) = table.get("global")
                && global.contains_key("prior")
            {
                bail!(
                    "{name} sets `global.prior`, which the protocol's `[prior]` table (or \
                     its `[offsets]`) decides"
                );
            }
        }
        if self.offsets.scales.is_empty() {
            bail!("[offsets] scales is empty");
        }
        if let Some(bad) = self
            .offsets
            .scales
            .iter()
            .find(|s| !(**s > 0.0 && **s <= 100.0))
        {
            bail!("offset scale {bad} is not in (0, 100]");
        }
        let mut scales = self.offsets.scales.clone();
        scales.sort_by(f64::total_cmp);
        if scales.windows(2).any(|w| w[0] == w[1]) {
            bail!("[offsets] scales lists a scale twice");
        }
        if self.offsets.adaptive {
            if self.offsets.sampling != Sampling::Axes {
                bail!("[offsets] adaptive = true needs sampling = \"axes\"");
            }
            if scales != self.offsets.scales {
                bail!("[offsets] adaptive = true needs the scales in increasing order");
            }
        }
        if let Some(prior) = &self.prior {
            prior.validate()?;
        }
        for (k, d) in self.desired.iter().enumerate() {
            self.desired_pose(k).with_context(|| match d {
                PoseSpec::LookingDown(l) => format!("desired pose {k}: looking_down = {l:?}"),
                PoseSpec::Pose(p) => format!("desired pose {k}: pose = {p:?}"),
            })?;
        }
        let configs = self.method_configs(true)?;
        let mut names: Vec<&str> = configs.iter().map(|c| c.name.as_str()).collect();
        names.sort_unstable();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            bail!(
                "two method configurations are named `{}` (a variant's name must differ from \
                 every other, and from the methods' own names such as `povs` or `rule2/convolved`)",
                w[0]
            );
        }
        Ok(())
    }

    /// A path of the protocol, resolved against its folder.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        crate::resolve(&self.base_dir, path)
    }

    /// `world_from_camera` of desired pose `k`.
    pub fn desired_pose(&self, k: usize) -> anyhow::Result<Isometry3> {
        self.desired[k].world_from_camera()
    }

    /// The offset `(t, θw)` of initial pose `index` of desired pose `desired`, at
    /// offset scale `scale` (a factor, not an index; see the module docs).
    pub fn offset(&self, desired: usize, index: usize, scale: f64) -> [f64; 6] {
        let t = self.offsets.translation_m;
        let r = self.offsets.rotation_deg.map(f64::to_radians);
        let mag = [t[0], t[1], t[2], r[0], r[1], r[2]].map(|m| m * scale);
        match self.offsets.sampling {
            Sampling::Corners => {
                std::array::from_fn(|k| if index >> k & 1 == 1 { -mag[k] } else { mag[k] })
            }
            Sampling::Axes => std::array::from_fn(|k| {
                let sign = if index % 2 == 1 { -1.0 } else { 1.0 };
                if k == Self::axis_of(index) {
                    sign * mag[k]
                } else {
                    0.0
                }
            }),
            Sampling::Uniform => {
                let mut rng = splat::rng::SplitMix64::new(self.offsets.seed)
                    .fork(desired as u64)
                    .fork(index as u64);
                std::array::from_fn(|k| rng.uniform(-mag[k], mag[k]))
            }
        }
    }

    /// `world_from_camera` of initial pose `index` of desired pose `k` at offset scale
    /// `scale` (a factor).
    pub fn initial_pose(&self, k: usize, index: usize, scale: f64) -> anyhow::Result<Isometry3> {
        Ok(self.desired_pose(k)? * Isometry3::from_pose_vector(self.offset(k, index, scale))?)
    }

    /// The prior box of [`Method::Global`]: `[prior]`, or the unscaled `[offsets]`.
    pub fn prior_box(&self) -> PriorBox {
        self.prior.clone().unwrap_or(PriorBox {
            translation_m: self.offsets.translation_m,
            rotation_deg: self.offsets.rotation_deg,
        })
    }

    /// The method configurations, in order (paper methods, then variants if `extras`).
    pub fn method_configs(&self, extras: bool) -> anyhow::Result<Vec<MethodConfig>> {
        let base = VvsConfig::default()
            .with_overrides(&self.vvs)
            .context("[vvs]")?;
        let mut out = Vec::new();
        for &method in &self.methods {
            if method == Method::Povs {
                out.push(MethodConfig {
                    name: "povs".into(),
                    method,
                    config: base.clone(),
                });
            } else {
                for &j in &self.jacobians {
                    let config = VvsConfig {
                        jacobian: j,
                        ..base.clone()
                    };
                    out.push(MethodConfig {
                        name: format!("{}/{}", method.name(), j.name()),
                        method,
                        config,
                    });
                }
            }
        }
        if extras {
            for v in &self.variant {
                let mut config = base
                    .with_overrides(&v.vvs)
                    .with_context(|| format!("variant {}", v.name))?;
                config.jacobian = v.jacobian;
                out.push(MethodConfig {
                    name: v.name.clone(),
                    method: v.method,
                    config,
                });
            }
        }
        Ok(out)
    }

    /// The initial pose indices of the protocol.
    pub fn initial_indices(&self) -> Vec<usize> {
        self.initial_indices
            .clone()
            .unwrap_or_else(|| (0..self.offsets.sampling.count()).collect())
    }

    /// The axis (0–5: `tX, tY, tZ, θwX, θwY, θwZ`) that initial pose `initial` offsets,
    /// for `axes` sampling.
    pub fn axis_of(initial: usize) -> usize {
        initial / 2
    }

    /// Every run, in a stable order: desired, scale, initial, method (for an adaptive
    /// protocol, every run it may need; see [`Offsets::adaptive`]).
    pub fn runs(&self, extras: bool) -> anyhow::Result<Vec<RunSpec>> {
        let methods = self.method_configs(extras)?.len();
        let mut runs = Vec::new();
        for desired in 0..self.desired.len() {
            for scale in 0..self.offsets.scales.len() {
                for initial in self.initial_indices() {
                    for method in 0..methods {
                        runs.push(RunSpec {
                            id: runs.len(),
                            desired,
                            scale,
                            initial,
                            method,
                        });
                    }
                }
            }
        }
        Ok(runs)
    }
}
