//! [`Tracker`]: tracking by successive alignments (the paper's §4, PoT and PGMoT).
//!
//! Every used frame is aligned from the estimate of the one before, with any
//! [`Method`]; using 1 frame in N (`frame_step`) tests how far the camera may move
//! between the frames a tracker sees. A diverged alignment loses the track: the tracker
//! keeps its last good estimate and aligns nothing more.

use std::ops::ControlFlow;
use std::time::Instant;

use frame::AnyImage;
use ucm::Isometry3;

use crate::{Method, Outcome, Servo, StopReason, VvsError};

/// One aligned frame of a track.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackedFrame {
    /// Index of the frame in the sequence.
    pub frame: usize,
    /// The alignment's outcome (its pose is the frame's estimate).
    pub outcome: Outcome,
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
    /// The estimate before the last one, for the constant-velocity prediction.
    previous: Option<Isometry3>,
    constant_velocity: bool,
    lost: bool,
}

impl<'a> Tracker<'a> {
    /// A tracker aligning with `method` through `servo`, starting at `initial`
    /// (`world_from_camera` of the first frame, roughly). [`Method::Global`] is
    /// allowed (each frame then searches its prior box around the previous estimate).
    pub fn new(servo: Servo<'a>, method: Method, initial: Isometry3) -> Result<Self, VvsError> {
        if !initial.is_finite() {
            return Err(VvsError::NonFinitePose);
        }
        Ok(Self {
            servo,
            method,
            estimate: initial,
            previous: None,
            constant_velocity: false,
            lost: false,
        })
    }

    /// Beyond the paper (off by default): start each alignment from a constant-velocity
    /// prediction, the last motion between aligned frames repeated
    /// (`estimate · (previous⁻¹ · estimate)`), instead of from the last estimate.
    pub fn with_constant_velocity(mut self, on: bool) -> Self {
        self.constant_velocity = on;
        self
    }

    /// Where the next alignment starts.
    pub fn prediction(&self) -> Isometry3 {
        match self.previous {
            Some(previous) if self.constant_velocity => {
                self.estimate * (previous.inverse() * self.estimate)
            }
            _ => self.estimate,
        }
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

    /// Align one frame from the current estimate (or [`Tracker::prediction`]), which
    /// becomes the result unless the alignment diverged (then the track is lost). [`VvsError::TrackLost`] once lost.
    pub fn align<D: AnyImage + Clone>(&mut self, picture: &D) -> Result<Outcome, VvsError> {
        if self.lost {
            return Err(VvsError::TrackLost);
        }
        let outcome = self.servo.run(self.method, picture, self.prediction())?;
        if matches!(outcome.stop, StopReason::Diverged(_)) {
            self.lost = true;
        } else {
            self.previous = Some(self.estimate);
            self.estimate = outcome.world_from_camera;
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
    pub fn track<'p, D: AnyImage + Clone + 'p>(
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
                wall_time_s: started.elapsed().as_secs_f64(),
            };
            let stop = on_frame(&tracked).is_break();
            report.lost = self.lost || stop;
            report.frames.push(tracked);
        }
        Ok(report)
    }
}
