//! [`Localizer`]: localise a measured picture in a cloud, from files a user has.
//!
//! The paper's §4 aligns pictures of a real catadioptric camera with renderings of a
//! Lidar cloud. This is that call: a picture (PNG or JPEG, 8 or 16 bits, colour becomes
//! luminance), its camera (a camera TOML file, or a Mei calibration in the YAML of
//! `omniunwarp` with the picture's size and an annulus), a cloud (LAS, LAZ, PLY or E57, told
//! apart by content), an initial
//! pose, and optionally the prior box of the global search ([`crate::global`]). The
//! brightness of the picture and of the renderings is centred and normalised (§4), so
//! that the exposure of the camera and the colours of the cloud need not agree.
//!
//! ```no_run
//! use vvs::localize::{CameraFile, LocalizeFiles, Localizer};
//!
//! let files = LocalizeFiles {
//!     picture: "image.png".into(),
//!     crop: None,
//!     camera: CameraFile::Toml("camera.toml".into()),
//!     cloud: "city.laz".into(),
//! };
//! let initial = ucm::Isometry3::from_pose_vector([-18.0, 1.0, 3.2, 3.14159, 0.0, 0.1])?;
//! let localized = Localizer::default().localize_files(&files, initial)?;
//! println!("{:?}: {:?}", localized.outcome.stop, localized.outcome.world_from_camera);
//! # Ok::<(), vvs::VvsError>(())
//! ```

use std::path::PathBuf;
use std::time::Instant;

use frame::{AnyImage, Image};
use splat::PointCloud;
use ucm::{Camera, Isometry3};

use crate::{
    Divergence, GlobalConfig, Method, Outcome, PriorBox, SearchProgress, Servo, StopReason,
    Support, VvsConfig, VvsError,
};

/// Where the camera's calibration comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum CameraFile {
    /// A camera TOML file (`ucm::Camera::load_toml`), of the picture's (cropped) size.
    Toml(PathBuf),
    /// A Mei calibration in the YAML layout of `omniunwarp` (`ucm::Camera::load_mei_yaml`):
    /// the camera takes the (cropped) picture's size; its valid region is the annulus of
    /// these radii around the principal point, or the whole picture.
    MeiYaml {
        /// The YAML file.
        path: PathBuf,
        /// Inner and outer radius of the mirror's annulus, pixels (`None`: every pixel).
        annulus_radii_px: Option<[f64; 2]>,
    },
}

/// The files of a localisation.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalizeFiles {
    /// The picture (PNG or JPEG).
    pub picture: PathBuf,
    /// The calibrated part of the picture, `[x, y, width, height]` pixels (`None`: all).
    pub crop: Option<[u32; 4]>,
    /// The camera.
    pub camera: CameraFile,
    /// The cloud (LAS, LAZ, PLY or E57: the format is read from the file's content).
    pub cloud: PathBuf,
}

/// A localisation and what it used.
#[derive(Clone, Debug)]
pub struct Localized {
    /// The optimiser's outcome: final `world_from_camera`, cost, stop reason, iterations
    /// (and the search's report for a global localisation).
    pub outcome: Outcome,
    /// The camera as read.
    pub camera: Camera,
    /// Points of the cloud.
    pub cloud_points: usize,
    /// Valid pixels of the picture.
    pub valid_pixels: usize,
    /// Time spent reading the files, seconds.
    pub load_time_s: f64,
}

/// How to localise: the optimiser's settings, the method, and an optional prior box.
#[derive(Clone, Debug, PartialEq)]
pub struct Localizer {
    /// The optimiser's settings. [`Localizer::default`] is the paper's rules with the
    /// brightness normalised (§4), and beyond the paper: the pictures compared on their
    /// common support ([`Support::Common`]: a real cloud has holes and never saw
    /// everything a picture sees), Levenberg–Marquardt steps of gain 1
    /// (`levenberg_marquardt = 0.1`: half the iterations of the paper's gain of 0.2),
    /// and step 1 continued at λ* = 7.5 then 3 pixels after 15 (`lambda_schedule`:
    /// on a real picture the widest PGM's optimum is centimetres from the picture's, and
    /// step 2 at λ = 1 does not come back from every such start), each of step 1's
    /// stages ended after 3 iterations without a 1 % decrease
    /// (`intermediate_stall_window`: they only bring the pose into the next stage's
    /// basin; step 2 keeps 10); step 1 coarse to fine (`pyramid_levels = 2`,
    /// `coarse_min_lambda_px = 1.5`: its stages at half the resolution, as λ* = 7.5,
    /// 3.75 and 1.5 there); a stage converged once a step moves the camera by less than
    /// 0.5 mm and 0.1 mrad (`converged_translation_m`, `converged_rotation_rad`: with
    /// steps of gain 1, the paper's 20 µm are below the renderings' noise and the
    /// stall test ends every run), or moves the image by less than 0.05 pixel of the
    /// stage's level (`converged_px`: a street seen from metres away, or a picture at
    /// half the resolution, settles below 0.5 mm only after steps that change nothing
    /// it can show); and a PGM stage renders only when the pose has moved the image by
    /// more than λ pixels (at least one) since its last rendering (`rerender_px = 1`: in
    /// between, the picture warped into that rendering is compared with it, with its
    /// `L_G`; a prepared local localisation in about 0.4 of the time, the same
    /// success on the city's protocols, ending 1–3 mm further from the truth on
    /// renderings, where `end_on_rendering` brings it back); and in step 2 an update
    /// that continues the last one, `r` times as long, lengthened by `1 / (1 − r)`, at
    /// most 4 times (`extrapolate_steps`: on a photograph Gauss–Newton crawls along a
    /// valley, each step about 0.9 times the last, until the 0.5 mm threshold ends it
    /// short of the optimum; the house's localisations in a sixth fewer iterations, no
    /// run of the city's protocols that succeeds changed). On the synthetic city the
    /// paper's settings' convergence domain, in a quarter of their iterations
    /// (`docs/RESULTS.md`, "Real pictures" and "Speed"). No
    /// per-iteration history. One thread (`parallel = false`, what the speed goals are
    /// stated for); `parallel = true` spreads each rendering (in up to 8 runs) and the
    /// PGM's convolutions over rayon's threads, and a global search's nodes, descents
    /// and refinements (on two cores a global search in 0.52–0.68 of the time; a
    /// prepared local localisation no faster since its warped iterations run on one:
    /// `docs/RESULTS.md`, "Speed"), the same bits. With a
    /// prior box, the global search's descents pruned (`global.prune_after_iterations
    /// = 3`, `global.pruned_to = 10`: every screened candidate descends 3 iterations,
    /// the 10 best run on to 10; a search 1.96 → 1.55 s, the same success on the
    /// protocols but one run of 448: `docs/RESULTS.md`, "Nothing lost on renderings"),
    /// and up to 3 descents refined when their ranks are within 25 % of the best's
    /// (`global.refined = 3`: on a photograph two basins may rank alike at low
    /// resolution, "Real pictures"), each refinement's stages run to the full stall
    /// window (not `intermediate_stall_window`: a descent may end a grid spacing away);
    /// the screening and the descents, at a quarter of the resolution, render one point
    /// in 16 of the cloud in 4 m cells (`global.thin_search_cloud`: a search from the
    /// paper's box 1.4–2.4 times faster on the Intel VM, with the same success on the
    /// city's protocols and on 7-Scenes' held-out block, 6/6 against the SfM poses:
    /// `docs/RESULTS.md`, "Speed" and "Real pictures"). A tracker's recovery searches so
    /// too.
    pub config: VvsConfig,
    /// The local method run without a prior box (default: Rule2; [`Method::Global`]
    /// asks for the prior box below, [`VvsError::GlobalWithoutPrior`] without one).
    pub method: Method,
    /// The prior box: with one, the global search of [`crate::global`] inside it
    /// around the initial pose (then `method` is ignored; the search refines with
    /// `config.global.refine_method`). The one place a localisation's box is given,
    /// like its initial pose: no configuration holds one.
    pub prior: Option<PriorBox>,
}

impl Default for Localizer {
    fn default() -> Self {
        Self {
            config: VvsConfig {
                normalize: true,
                support: Support::Common,
                gain: 1.0,
                levenberg_marquardt: Some(0.1),
                extrapolate_steps: Some(4.0),
                lambda_schedule: vec![7.5, 3.0],
                intermediate_stall_window: Some(3),
                pyramid_levels: 2,
                coarse_min_lambda_px: Some(1.5),
                converged_translation_m: 5e-4,
                converged_rotation_rad: 1e-4,
                converged_px: Some(0.05),
                rerender_px: Some(1.0),
                keep_history: false,
                parallel: false,
                global: GlobalConfig {
                    prune_after_iterations: 3,
                    pruned_to: 10,
                    refined: 3,
                    thin_search_cloud: true,
                    ..GlobalConfig::default()
                },
                ..VvsConfig::default()
            },
            method: Method::Rule2,
            prior: None,
        }
    }
}

impl Localizer {
    /// Localise `picture`, taken by `camera`, in `cloud` from `initial`
    /// (`world_from_camera`). Divergence is an outcome, not an error; but a camera that
    /// sees too little of the cloud at `initial` to take one step (without a prior box)
    /// is [`VvsError::CloudNotInView`].
    pub fn localize<D: AnyImage + Clone + Sync>(
        &self,
        cloud: &PointCloud,
        camera: &Camera,
        picture: &D,
        initial: Isometry3,
    ) -> Result<Outcome, VvsError> {
        self.localize_with_progress(cloud, camera, picture, initial, &mut |_| ())
    }

    /// [`Localizer::localize`], calling `progress` as a global search goes on (a local
    /// localisation does not call it).
    pub fn localize_with_progress<D: AnyImage + Clone + Sync>(
        &self,
        cloud: &PointCloud,
        camera: &Camera,
        picture: &D,
        initial: Isometry3,
        progress: &mut dyn FnMut(SearchProgress),
    ) -> Result<Outcome, VvsError> {
        self.prepare(cloud, camera)?
            .localize_with_progress(picture, initial, progress)
    }

    /// This localiser set up for `cloud` and `camera`: its buffers (renderings,
    /// features, pyramid levels) allocated once, for picture after picture (a robot
    /// relocalising, a batch of photographs). Each localisation gives what
    /// [`Localizer::localize`] gives.
    pub fn prepare<'a>(
        &self,
        cloud: &'a PointCloud,
        camera: &Camera,
    ) -> Result<PreparedLocalizer<'a>, VvsError> {
        if self.prior.is_none() && self.method == Method::Global {
            return Err(VvsError::GlobalWithoutPrior);
        }
        Ok(PreparedLocalizer {
            servo: Servo::new(cloud, camera, self.config.clone())?,
            method: self.method,
            prior: self.prior.clone(),
        })
    }

    /// Read the files and localise the picture from `initial`.
    pub fn localize_files(
        &self,
        files: &LocalizeFiles,
        initial: Isometry3,
    ) -> Result<Localized, VvsError> {
        self.localize_files_with_progress(files, initial, &mut |_| ())
    }

    /// [`Localizer::localize_files`], calling `progress` as a global search goes on.
    pub fn localize_files_with_progress(
        &self,
        files: &LocalizeFiles,
        initial: Isometry3,
        progress: &mut dyn FnMut(SearchProgress),
    ) -> Result<Localized, VvsError> {
        if !initial.is_finite() {
            return Err(VvsError::NonFinitePose);
        }
        let started = Instant::now();
        let camera = load_camera(files)?;
        let picture = Image::load(&files.picture, &camera, files.crop)?;
        let (cloud, _, _) = cloud_io::read_cloud(&files.cloud)?;
        let load_time_s = started.elapsed().as_secs_f64();
        let outcome = self.localize_with_progress(&cloud, &camera, &picture, initial, progress)?;
        Ok(Localized {
            outcome,
            valid_pixels: picture.valid_count(),
            cloud_points: cloud.len(),
            camera,
            load_time_s,
        })
    }
}

/// A [`Localizer`] set up for one cloud and camera ([`Localizer::prepare`]).
#[derive(Debug)]
pub struct PreparedLocalizer<'a> {
    /// The optimiser, with the localiser's settings.
    servo: Servo<'a>,
    /// The local method, run without a prior box.
    method: Method,
    /// The box of the global search, if any.
    prior: Option<PriorBox>,
}

impl PreparedLocalizer<'_> {
    /// Localise `picture` from `initial` (`world_from_camera`), as
    /// [`Localizer::localize`] does.
    pub fn localize<D: AnyImage + Clone + Sync>(
        &mut self,
        picture: &D,
        initial: Isometry3,
    ) -> Result<Outcome, VvsError> {
        self.localize_with_progress(picture, initial, &mut |_| ())
    }

    /// [`PreparedLocalizer::localize`], calling `progress` as a global search goes on.
    pub fn localize_with_progress<D: AnyImage + Clone + Sync>(
        &mut self,
        picture: &D,
        initial: Isometry3,
        progress: &mut dyn FnMut(SearchProgress),
    ) -> Result<Outcome, VvsError> {
        match &self.prior {
            Some(prior) => self
                .servo
                .localize_in_box_with_progress(picture, initial, prior, progress),
            None => {
                let outcome = self.servo.run(self.method, picture, initial)?;
                // Nothing seen before the first step: an input to fix, not a divergence.
                if outcome.stop == StopReason::Diverged(Divergence::NoValidPixels)
                    && outcome.iterations.iter().sum::<usize>() == 0
                {
                    return Err(VvsError::CloudNotInView {
                        min_percent: 100.0 * self.servo.config().min_hit_fraction,
                    });
                }
                Ok(outcome)
            }
        }
    }
}

/// The camera of `files`, of the (cropped) picture's size.
fn load_camera(files: &LocalizeFiles) -> Result<Camera, VvsError> {
    match &files.camera {
        CameraFile::Toml(path) => Ok(Camera::load_toml(path)?),
        CameraFile::MeiYaml {
            path,
            annulus_radii_px,
        } => {
            let (width, height) = match files.crop {
                Some([_, _, w, h]) => (w, h),
                None => Image::dimensions(&files.picture)?,
            };
            let camera = Camera::load_mei_yaml(path, width, height, ucm::ValidRegion::Full)?;
            match annulus_radii_px {
                None => Ok(camera),
                Some([inner, outer]) => {
                    let i = camera.intrinsics();
                    let region = ucm::ValidRegion::Annulus(ucm::Annulus {
                        center_px: [i.u0, i.v0],
                        inner_radius_px: *inner,
                        outer_radius_px: *outer,
                    });
                    Ok(camera.with_region(region)?)
                }
            }
        }
    }
}
