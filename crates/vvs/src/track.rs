//! [`Tracker`]: tracking by successive alignments (the paper's §4, PoT and PGMoT).
//!
//! Every used frame is aligned from the estimate of the one before, with any
//! [`Method`]; using 1 frame in N (`frame_step`) tests how far the camera may move
//! between the frames a tracker sees. A diverged alignment loses the track: the tracker
//! keeps its last good estimate and aligns nothing more.
//!
//! A tracker aligns through the [`Servo`] it is given; [`Tracker::default_config`] is
//! the settings to build it with: the localiser's, with step 1 from λ* = 7.5 (the
//! camera moves little between frames).
//!
//! Beyond the paper, two settings, both off by default:
//! - [`Prediction`]: each alignment starts from an extrapolation of the last two
//!   estimates instead of the last one. For a hand-held camera, repeating the last
//!   displacement with the last orientation ([`Prediction::ConstantTranslation`]) is the
//!   one that holds: its sway alternates between the frames used, so repeating the
//!   rotation as well ([`Prediction::ConstantVelocity`]) doubles the rotation to
//!   recover (`docs/RESULTS.md`, tracking over 110 m).
//! - [`Recovery`]: every alignment is checked (diverged, out of iterations, or ended
//!   farther from its start than a camera moves between frames), and a failed one is
//!   followed by a global search in a box around its start ([`Servo::localize_in_box`]).

use std::ops::ControlFlow;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use frame::AnyImage;
use ucm::Isometry3;

use crate::{Method, Outcome, PriorBox, Servo, StopReason, VvsConfig, VvsError};

/// Where a tracker starts each alignment, from the estimates of the frames before.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Prediction {
    /// The paper's: from the last estimate.
    #[default]
    Last,
    /// The last motion between aligned frames repeated, rotation and translation
    /// (`estimate · (previous⁻¹ · estimate)`). A hand-held camera's rotation sways:
    /// sampled a few times per second it alternates, and repeating it doubles the
    /// rotation to recover.
    ConstantVelocity,
    /// The last displacement repeated (`t + (t − t_previous)` in the world frame),
    /// the orientation kept: a walking or driving camera's translation is smooth, its
    /// sway is not.
    ConstantTranslation,
}

impl Prediction {
    /// Its name in settings files (`last`, `constant_velocity`, `constant_translation`).
    pub fn name(self) -> &'static str {
        match self {
            Prediction::Last => "last",
            Prediction::ConstantVelocity => "constant_velocity",
            Prediction::ConstantTranslation => "constant_translation",
        }
    }

    /// The start of the next alignment from the last `estimate` and the one before.
    pub fn predict(self, estimate: Isometry3, previous: Option<Isometry3>) -> Isometry3 {
        match (self, previous) {
            (Prediction::Last, _) | (_, None) => estimate,
            (Prediction::ConstantVelocity, Some(previous)) => {
                estimate * (previous.inverse() * estimate)
            }
            (Prediction::ConstantTranslation, Some(previous)) => {
                Isometry3::from_rotation_translation(
                    estimate.rotation,
                    estimate.translation + (estimate.translation - previous.translation),
                )
            }
        }
    }
}

/// Beyond the paper: how a tracker checks each alignment, and searches again after a
/// failed one.
///
/// An alignment fails when it diverges, runs out of iterations, or ends farther from
/// where it started than `max_jump_m` or `max_jump_deg` (a camera does not jump between
/// frames: such an end is a local minimum of the cost, not the camera's motion). A
/// failed alignment is followed by a global localisation ([`Servo::localize_in_box`])
/// in `search` around the same start; if that fails too (diverged or out of
/// iterations), the track is lost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Recovery {
    /// Largest translation of an alignment from its start, metres.
    pub max_jump_m: f64,
    /// Largest rotation of an alignment from its start, degrees.
    pub max_jump_deg: f64,
    /// The region searched after a failed alignment, around its start.
    pub search: PriorBox,
}

impl Default for Recovery {
    /// Jumps of 0.3 m or 30°; a search of ±1 m, ±1 m, ±0.5 m and ±10°, ±10°, ±20°.
    /// (On the long sequence of `fixtures/sequence-long.toml`, a hand-held camera
    /// walking 0.6 m/s with 1 frame in 10 or 20 at 30 fps, the converged alignments
    /// end up to 0.17 m and 24° from their constant-translation prediction.)
    fn default() -> Self {
        Self {
            max_jump_m: 0.3,
            max_jump_deg: 30.0,
            search: PriorBox {
                translation_m: [1.0, 1.0, 0.5],
                rotation_deg: [10.0, 10.0, 20.0],
            },
        }
    }
}

impl Recovery {
    /// Check the settings: positive finite jumps, a valid box.
    pub fn validate(&self) -> Result<(), VvsError> {
        for (name, value) in [
            ("recovery.max_jump_m", self.max_jump_m),
            ("recovery.max_jump_deg", self.max_jump_deg),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(VvsError::Config {
                    name,
                    message: format!("must be > 0 and finite, got {value}"),
                });
            }
        }
        self.search.validate()
    }

    /// Whether an alignment that started at `start` failed.
    pub fn failed(&self, outcome: &Outcome, start: &Isometry3) -> bool {
        let (jump_m, jump_rad) = outcome.world_from_camera.distance_to(start);
        matches!(
            outcome.stop,
            StopReason::Diverged(_) | StopReason::IterationBudget
        ) || !(jump_m <= self.max_jump_m && jump_rad.to_degrees() <= self.max_jump_deg)
    }
}

/// One aligned frame of a track.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackedFrame {
    /// Index of the frame in the sequence.
    pub frame: usize,
    /// The alignment's outcome (its pose is the frame's estimate).
    pub outcome: Outcome,
    /// Whether the first alignment failed and the frame was searched again
    /// ([`Recovery`]); `outcome` is then the search's.
    pub recovered: bool,
    /// Wall time of the alignment, seconds.
    pub wall_time_s: f64,
}

/// What [`Tracker::track`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackReport {
    /// Every aligned frame, in order.
    pub frames: Vec<TrackedFrame>,
    /// Whether the track was lost: an alignment diverged, or the caller stopped it.
    pub lost: bool,
}

/// Successive alignments of the frames of a sequence.
#[derive(Debug)]
pub struct Tracker<'a> {
    servo: Servo<'a>,
    method: Method,
    estimate: Isometry3,
    /// The estimate before the last one, for the prediction (`None` until two frames
    /// were aligned: the initial pose is a guess, not an estimate).
    previous: Option<Isometry3>,
    /// Whether a frame was aligned (then `estimate` is an alignment's).
    aligned: bool,
    prediction: Prediction,
    recovery: Option<Recovery>,
    /// Whether the last alignment was a recovery.
    recovered: bool,
    lost: bool,
}

impl<'a> Tracker<'a> {
    /// The settings to build a tracker's [`Servo`] with (beyond the paper): the
    /// [`crate::Localizer`]'s, with step 1 from λ* = 7.5 instead of 15 (then the λ
    /// schedule `[3]`), each stage at the coarsest of three pyramid levels where its λ*
    /// stays 1.5 pixels (`pyramid_levels = 3`: at 640×480, λ* = 7.5 at 160×120 and 3 at
    /// 320×240). A tracker starts each alignment where the camera was a frame or a few
    /// before, well inside λ = 7.5's basin; λ = 15 widens the basin for starts metres
    /// away, but its optimum lies centimetres from the picture's and step 2 does not
    /// always come back. Measured (`docs/RESULTS.md`, "Tracking"): on the city's shaken
    /// sequence with 1 frame in 1 to 20, RMSE 1.5–1.8 cm against the localiser's
    /// 1.6–4.6, in 11–13 iterations a frame against 18–19, never lost; on 7-Scenes'
    /// held-out block (KinectFusion poses, 1 frame in 1 to 10) the largest error 13 cm
    /// against 22, never lost, in less time. From λ* = 3 alone
    /// (`lambda_schedule` empty) tracks are lost with 1 frame in 10 or 20.
    /// Step 2's updates are not lengthened (`extrapolate_steps = None`): a frame's step 2
    /// takes two or three iterations, and on the shaken sequence lengthening them
    /// brought nothing but one frame of 1 in 10 7.9 cm off (RMSE 2.6 cm, not 1.6).
    /// With a [`Recovery`], the search screens at this λ*₁ too (divided by
    /// `global.search_downsampling`) and refines with this plan; for the localiser's
    /// search, build the servo with `lambda_star_step1 = 15`, `lambda_schedule =
    /// [7.5, 3]`, `pyramid_levels = 2` and `extrapolate_steps = Some(4.0)`.
    pub fn default_config() -> VvsConfig {
        VvsConfig {
            lambda_star_step1: 7.5,
            lambda_schedule: vec![3.0],
            pyramid_levels: 3,
            extrapolate_steps: None,
            ..crate::Localizer::default().config
        }
    }

    /// A tracker aligning with `method` through `servo`, starting at `initial`
    /// (`world_from_camera` of the first frame, roughly). `method` is a local one
    /// ([`Method::Global`]: [`VvsError::GlobalWithoutPrior`]; a tracker searches a box
    /// only to recover, [`Tracker::with_recovery`]).
    pub fn new(servo: Servo<'a>, method: Method, initial: Isometry3) -> Result<Self, VvsError> {
        if !initial.is_finite() {
            return Err(VvsError::NonFinitePose);
        }
        if method == Method::Global {
            return Err(VvsError::GlobalWithoutPrior);
        }
        Ok(Self {
            servo,
            method,
            estimate: initial,
            previous: None,
            aligned: false,
            prediction: Prediction::Last,
            recovery: None,
            recovered: false,
            lost: false,
        })
    }

    /// Beyond the paper: start each alignment from a [`Prediction`] instead of the
    /// last estimate ([`Prediction::Last`], the default).
    pub fn with_prediction(mut self, prediction: Prediction) -> Self {
        self.prediction = prediction;
        self
    }

    /// Beyond the paper: check every alignment and search again after a failed one
    /// ([`Recovery`]; `None`, the default, keeps every alignment that did not diverge).
    pub fn with_recovery(mut self, recovery: Option<Recovery>) -> Result<Self, VvsError> {
        if let Some(r) = &recovery {
            r.validate()?;
        }
        self.recovery = recovery;
        Ok(self)
    }

    /// Where the next alignment starts.
    pub fn prediction(&self) -> Isometry3 {
        self.prediction.predict(self.estimate, self.previous)
    }

    /// The current estimate: the last aligned frame's `world_from_camera` (the initial
    /// pose before the first).
    pub fn estimate(&self) -> Isometry3 {
        self.estimate
    }

    /// Whether an alignment diverged (nothing more is aligned).
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// The method.
    pub fn method(&self) -> Method {
        self.method
    }

    /// Whether the last alignment failed and was searched again ([`Recovery`]).
    pub fn recovered(&self) -> bool {
        self.recovered
    }

    /// Align one frame from [`Tracker::prediction`], which becomes the result unless the
    /// alignment diverged (then the track is lost). With a [`Recovery`], a failed
    /// alignment is followed by a search, and the track is lost if that fails too.
    /// [`VvsError::TrackLost`] once lost.
    pub fn align<D: AnyImage + Clone + Sync>(&mut self, picture: &D) -> Result<Outcome, VvsError> {
        if self.lost {
            return Err(VvsError::TrackLost);
        }
        let start = self.prediction();
        let mut outcome = self.servo.run(self.method, picture, start)?;
        self.recovered = false;
        if let Some(recovery) = &self.recovery
            && recovery.failed(&outcome, &start)
        {
            self.recovered = true;
            outcome = self
                .servo
                .localize_in_box(picture, start, &recovery.search)?;
        }
        let lost = match (&self.recovery, self.recovered) {
            (Some(_), true) => matches!(
                outcome.stop,
                StopReason::Diverged(_) | StopReason::IterationBudget
            ),
            _ => matches!(outcome.stop, StopReason::Diverged(_)),
        };
        if lost {
            self.lost = true;
        } else {
            self.previous = self.aligned.then_some(self.estimate);
            self.estimate = outcome.world_from_camera;
            self.aligned = true;
            // The camera's vignetting does not change from frame to frame.
            if let Some(c) = outcome.vignetting {
                self.servo.set_vignetting_start(c);
            }
        }
        Ok(outcome)
    }

    /// Track a sequence using 1 frame in `frame_step`: `frames` yields every frame of
    /// the sequence in order (`None` for one that is not available: an error if it is
    /// one to use). After each aligned frame `on_frame` may stop the track
    /// (`ControlFlow::Break`, e.g. when a ground truth says it is lost); a diverged
    /// alignment stops it too. Both count as lost.
    pub fn track<'p, D: AnyImage + Clone + Sync + 'p>(
        &mut self,
        frames: impl IntoIterator<Item = Option<&'p D>>,
        frame_step: usize,
        mut on_frame: impl FnMut(&TrackedFrame) -> ControlFlow<()>,
    ) -> Result<TrackReport, VvsError> {
        if frame_step == 0 {
            return Err(VvsError::Config {
                name: "frame_step",
                message: "must be at least 1".into(),
            });
        }
        let mut report = TrackReport {
            frames: Vec::new(),
            lost: self.lost,
        };
        for (frame, picture) in frames.into_iter().enumerate().step_by(frame_step) {
            if report.lost {
                break;
            }
            let picture = picture.ok_or(VvsError::MissingFrame(frame))?;
            let started = Instant::now();
            let outcome = self.align(picture)?;
            let tracked = TrackedFrame {
                frame,
                outcome,
                recovered: self.recovered,
                wall_time_s: started.elapsed().as_secs_f64(),
            };
            let stop = on_frame(&tracked).is_break();
            report.lost = self.lost || stop;
            report.frames.push(tracked);
        }
        Ok(report)
    }
}
