//! A synthetic image sequence for tracking (paper §4): a ground-truth trajectory with
//! the shaking of a robot on uneven ground, and "acquired" images that differ from the
//! renderer's the way real ones do.
//!
//! # Trajectory
//! The robot moves from `start` (the ground point under the camera, `[x, y, z]`,
//! metres) along `heading_deg` over `length_m`, in `frames` frames at `fps`, its speed
//! varying by `speed_variation` (relative, one slow sinusoid): in a straight line, or
//! through `turns` ([`Turn`]: at a distance along the path, an arc of a radius that
//! turns the heading by an angle, then straight on), e.g. from one street into
//! another. The camera (the omnidirectional camera looking down, camera X forward)
//! rides `camera_height_m` above the ground. On top of that ([`Shake`]):
//!
//! * **sway**: roll, pitch and yaw oscillations, each the sum of a sinusoid of amplitude
//!   `sway_deg[k]` at `sway_hz[k]` and one of half that amplitude at 2.3 × the
//!   frequency, with seeded phases (the robot rocking on its suspension);
//! * **bumps**: `bumps_per_m` Gaussian bumps of the ground per metre of path, each of
//!   a random height in `±bump_height_m` and of width `bump_length_m`; the camera
//!   rises with them and pitches with their slope;
//! * **kerb**: at `kerb_at_m` along the path the ground drops by `kerb_drop_m` (over
//!   5 cm), followed by a damped pitch oscillation of `kerb_pitch_deg` at 2.5 Hz
//!   (decay 4 s⁻¹);
//! * **lateral wander**: a sideways sinusoid of `lateral_m` at 0.4 Hz.
//!
//! # Acquired images ([`Acquisition`])
//! Rendered at the true pose from **another point sampling** of the same surfaces (the
//! synthetic city regenerated with `sampling_seed`; a LAS scene is reused as is), then
//! degraded in this order: vignetting `I · (1 − vignetting · (r / r_max)²)` (r from the
//! valid region's centre), a gain `1 + gain_amplitude · sin(2π t / gain_period_s)` and
//! an offset `offset_amplitude · cos(2π t / gain_period_s)` (auto-exposure drifting),
//! a Gaussian blur of `blur_sigma_px`, Gaussian sensor noise of `noise_sigma`, and
//! clamping to `[0, 1]`. Every random draw is seeded: the same file gives the same
//! images.

use frame::{AnyImage, Frame, Image};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use splat::rng::SplitMix64;
use ucm::{Camera, Isometry3, ValidRegion};

use crate::WorldError;

/// `Err(WorldError::Sequence(…))` unless `condition` holds.
macro_rules! ensure {
    ($condition:expr, $($message:tt)+) => {
        if !$condition {
            return Err(WorldError::Sequence(format!($($message)+)));
        }
    };
}

/// The highest frame rate of a trajectory, frames per second (a high-speed camera's).
pub const MAX_FPS: f64 = 10_000.0;

/// Most frames a sequence may have: every frame is rendered and kept (about 70 KB
/// at 320×240, per tracking configuration), so 10 000 frames take about 0.7 GB each.
pub const MAX_FRAMES: usize = 10_000;
/// Longest path of a sequence, metres.
pub const MAX_LENGTH_M: f64 = 100_000.0;

/// The trajectory and its shaking.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Trajectory {
    /// Number of frames. Paper: 210.
    pub frames: usize,
    /// Frame rate, frames per second. Paper: 30.
    pub fps: f64,
    /// Ground point under the camera at the first frame, `[x, y, z]`, metres.
    pub start: [f64; 3],
    /// Direction of travel, degrees from the world X axis.
    pub heading_deg: f64,
    /// Path length, metres. Paper: about 4.35.
    pub length_m: f64,
    /// Height of the camera above the ground, metres.
    pub camera_height_m: f64,
    /// Relative speed variation (0: constant speed).
    pub speed_variation: f64,
    /// The shaking.
    pub shake: Shake,
    /// Seed of the shaking's phases and bumps.
    pub seed: u64,
    /// Turns along the path, in order (none: a straight line).
    pub turns: Vec<Turn>,
}

/// A turn of the path: at `at_m` along it, an arc of radius `radius_m` that turns the
/// heading by `angle_deg` (positive: to the left, counter-clockwise seen from above).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Turn {
    /// Distance along the path where the arc begins, metres.
    pub at_m: f64,
    /// Heading change, degrees (positive: left).
    pub angle_deg: f64,
    /// Radius of the arc, metres.
    pub radius_m: f64,
}

impl Turn {
    /// Length of the arc, metres.
    pub fn arc_length_m(&self) -> f64 {
        self.radius_m * self.angle_deg.to_radians().abs()
    }
}

impl Default for Trajectory {
    fn default() -> Self {
        // The paper's robot: leaves the sidewalk of the X street and crosses it.
        Self {
            frames: 210,
            fps: 30.0,
            start: [-20.0, -4.75, crate::city::KERB_HEIGHT_M],
            heading_deg: 90.0,
            length_m: 4.35,
            camera_height_m: 1.2,
            speed_variation: 0.1,
            shake: Shake::default(),
            seed: 3,
            turns: Vec::new(),
        }
    }
}

/// The shaking of uneven ground (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Shake {
    /// Amplitudes of the roll, pitch and yaw sway, degrees.
    pub sway_deg: [f64; 3],
    /// Frequencies of the roll, pitch and yaw sway, hertz.
    pub sway_hz: [f64; 3],
    /// Bumps per metre of path.
    pub bumps_per_m: f64,
    /// Largest bump height, metres.
    pub bump_height_m: f64,
    /// Bump width (standard deviation of the Gaussian profile), metres.
    pub bump_length_m: f64,
    /// Distance along the path of a kerb step down, metres (none if absent).
    pub kerb_at_m: Option<f64>,
    /// Height of the kerb step, metres.
    pub kerb_drop_m: f64,
    /// Amplitude of the pitch oscillation after the kerb, degrees.
    pub kerb_pitch_deg: f64,
    /// Amplitude of the lateral wander, metres.
    pub lateral_m: f64,
}

impl Default for Shake {
    fn default() -> Self {
        Self {
            sway_deg: [2.0, 2.5, 1.5],
            sway_hz: [1.3, 1.9, 0.6],
            bumps_per_m: 2.0,
            bump_height_m: 0.02,
            bump_length_m: 0.08,
            // The default start is 1.25 m from the road's edge (|y| = 3.5 m).
            kerb_at_m: Some(1.25),
            kerb_drop_m: crate::city::KERB_HEIGHT_M,
            kerb_pitch_deg: 6.0,
            lateral_m: 0.05,
        }
    }
}

/// How acquired images differ from rendered ones (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Acquisition {
    /// Point sampling of the generated city for acquired images (ignored for LAS).
    pub sampling_seed: u64,
    /// Vignetting strength at the valid region's outer radius (0: none).
    pub vignetting: f64,
    /// Amplitude of the gain drift (relative).
    pub gain_amplitude: f64,
    /// Amplitude of the offset drift (intensity units).
    pub offset_amplitude: f64,
    /// Period of the gain and offset drift, seconds.
    pub gain_period_s: f64,
    /// Standard deviation of the blur, pixels (0: none).
    pub blur_sigma_px: f64,
    /// Standard deviation of the sensor noise (intensity units).
    pub noise_sigma: f64,
    /// Seed of the sensor noise.
    pub noise_seed: u64,
}

impl Default for Acquisition {
    fn default() -> Self {
        Self {
            sampling_seed: 2,
            vignetting: 0.3,
            gain_amplitude: 0.15,
            offset_amplitude: 0.03,
            gain_period_s: 3.0,
            blur_sigma_px: 0.7,
            noise_sigma: 0.02,
            noise_seed: 5,
        }
    }
}

impl Trajectory {
    /// Check every field.
    pub fn validate(&self) -> Result<(), WorldError> {
        let finite = |v: f64| v.is_finite();
        ensure!(
            (1..=MAX_FRAMES).contains(&self.frames),
            "trajectory.frames must be in 1..={MAX_FRAMES}, got {}",
            self.frames
        );
        ensure!(
            self.fps > 0.0 && self.fps <= MAX_FPS,
            "trajectory.fps must be in (0, {MAX_FPS}], got {}",
            self.fps
        );
        ensure!(
            self.start.iter().all(|v| finite(*v))
                && finite(self.heading_deg)
                && self.length_m >= 0.0
                && finite(self.length_m),
            "trajectory.start, heading_deg and length_m must be finite (length >= 0)"
        );
        ensure!(
            self.length_m <= MAX_LENGTH_M,
            "trajectory.length_m must be at most {MAX_LENGTH_M} m, got {}",
            self.length_m
        );
        ensure!(
            self.camera_height_m > 0.0 && finite(self.camera_height_m),
            "trajectory.camera_height_m must be > 0"
        );
        ensure!(
            (0.0..1.0).contains(&self.speed_variation),
            "trajectory.speed_variation must be in [0, 1)"
        );
        let s = &self.shake;
        ensure!(
            s.sway_deg
                .iter()
                .chain(&s.sway_hz)
                .chain([
                    &s.bumps_per_m,
                    &s.bump_height_m,
                    &s.kerb_drop_m,
                    &s.kerb_pitch_deg,
                    &s.lateral_m,
                ])
                .all(|v| *v >= 0.0 && finite(*v))
                && s.bump_length_m > 0.0
                && finite(s.bump_length_m),
            "trajectory.shake values must be finite and >= 0 (bump_length_m > 0)"
        );
        let mut free_from = 0.0;
        for (k, t) in self.turns.iter().enumerate() {
            ensure!(
                [t.at_m, t.angle_deg, t.radius_m].iter().all(|v| finite(*v))
                    && t.radius_m > 0.0
                    && t.angle_deg.abs() <= 360.0,
                "trajectory.turns[{k}]: at_m, angle_deg and radius_m must be finite, \
                 radius_m > 0 and |angle_deg| <= 360"
            );
            ensure!(
                t.at_m >= free_from && t.at_m <= self.length_m,
                "trajectory.turns[{k}] at {} m must start after the previous turn ends \
                 ({free_from} m) and within the path's {} m",
                t.at_m,
                self.length_m
            );
            free_from = t.at_m + t.arc_length_m();
        }
        ensure!(
            s.bumps_per_m * self.length_m <= 1e6,
            "trajectory: {} bumps per metre over {} m is more than a million bumps",
            s.bumps_per_m,
            self.length_m
        );
        Ok(())
    }

    /// The ground point under the camera (without shaking) and the heading, radians,
    /// at distance `d` along the path.
    pub fn centerline(&self, d: f64) -> (DVec3, f64) {
        let mut point = DVec3::from(self.start);
        let mut heading = self.heading_deg.to_radians();
        let mut reached = 0.0;
        let forward = |h: f64| DVec3::new(h.cos(), h.sin(), 0.0);
        let left = |h: f64| DVec3::new(-h.sin(), h.cos(), 0.0);
        for turn in &self.turns {
            if d <= turn.at_m {
                break;
            }
            point += forward(heading) * (turn.at_m - reached);
            // The arc about its centre, on the side the path turns to.
            let side = turn.angle_deg.signum();
            let centre = point + left(heading) * (side * turn.radius_m);
            let along = (d - turn.at_m).min(turn.arc_length_m());
            let turned = side * along / turn.radius_m;
            let at = centre - left(heading + turned) * (side * turn.radius_m);
            if d < turn.at_m + turn.arc_length_m() {
                return (at, heading + turned);
            }
            point = at;
            heading += turn.angle_deg.to_radians();
            reached = turn.at_m + turn.arc_length_m();
        }
        (point + forward(heading) * (d - reached), heading)
    }

    /// Time of frame `k`, seconds.
    pub fn time_s(&self, k: usize) -> f64 {
        k as f64 / self.fps
    }

    /// The ground-truth `world_from_camera` of every frame.
    pub fn poses(&self) -> Vec<Isometry3> {
        let mut rng = SplitMix64::new(self.seed);
        let s = &self.shake;
        let phases: Vec<f64> = (0..7)
            .map(|_| rng.uniform(0.0, std::f64::consts::TAU))
            .collect();
        let bump_count = (s.bumps_per_m * self.length_m).round() as usize;
        let bumps: Vec<(f64, f64)> = (0..bump_count)
            .map(|_| {
                (
                    rng.uniform(0.0, self.length_m),
                    rng.uniform(-s.bump_height_m, s.bump_height_m),
                )
            })
            .collect();
        let duration = self.time_s(self.frames.saturating_sub(1)).max(1e-9);
        // Distance travelled: mean speed × (t + variation term), normalised so the path
        // ends at length_m.
        let travelled = |t: f64| {
            let w = std::f64::consts::TAU * 0.5;
            t - self.speed_variation / w * ((w * t + phases[6]).cos() - phases[6].cos())
        };
        let total = travelled(duration);
        let sigma = s.bump_length_m;
        let bump_height = |d: f64| -> (f64, f64) {
            bumps.iter().fold((0.0, 0.0), |(h, slope), &(c, a)| {
                let g = a * (-(d - c).powi(2) / (2.0 * sigma * sigma)).exp();
                (h + g, slope - g * (d - c) / (sigma * sigma))
            })
        };
        (0..self.frames)
            .map(|k| {
                let t = self.time_s(k);
                let d = if self.frames > 1 && total > 0.0 {
                    self.length_m * travelled(t) / total
                } else {
                    0.0
                };
                let (mut ground, slope) = bump_height(d);
                let mut kerb_pitch = 0.0;
                if let Some(at) = s.kerb_at_m {
                    // Smooth drop over 5 cm, then a damped pitch oscillation.
                    let x = ((d - at) / 0.05).clamp(0.0, 1.0);
                    ground -= s.kerb_drop_m * x * x * (3.0 - 2.0 * x);
                    let speed = self.length_m / duration;
                    let since = (d - at) / speed.max(1e-9);
                    if since > 0.0 {
                        kerb_pitch = s.kerb_pitch_deg.to_radians()
                            * (-4.0 * since).exp()
                            * (std::f64::consts::TAU * 2.5 * since).sin();
                    }
                }
                let sway = |i: usize| {
                    let w = std::f64::consts::TAU * s.sway_hz[i];
                    s.sway_deg[i].to_radians()
                        * ((w * t + phases[i]).sin() + 0.5 * (2.3 * w * t + phases[3 + i]).sin())
                };
                let lateral =
                    s.lateral_m * (std::f64::consts::TAU * 0.4 * t + phases[2] + 1.0).sin();
                let (on_path, heading) = self.centerline(d);
                let left = DVec3::new(-heading.sin(), heading.cos(), 0.0);
                let position =
                    on_path + left * lateral + DVec3::Z * (ground + self.camera_height_m);
                let base = crate::city::camera_looking_down(position, heading);
                // Camera X is forward: roll about X, pitch about Y (with the ground's
                // slope and the kerb), yaw about Z.
                let pitch = sway(1) + slope.atan() + kerb_pitch;
                let rotation =
                    Isometry3::from_pose_vector([0.0, 0.0, 0.0, sway(0), pitch, sway(2)])
                        .unwrap_or(Isometry3::IDENTITY);
                base * rotation
            })
            .collect()
    }
}

impl Acquisition {
    /// Check every field.
    pub fn validate(&self) -> Result<(), WorldError> {
        let values = [
            self.vignetting,
            self.gain_amplitude,
            self.offset_amplitude,
            self.blur_sigma_px,
            self.noise_sigma,
        ];
        ensure!(
            values.iter().all(|v| *v >= 0.0 && v.is_finite()),
            "acquisition values must be finite and >= 0"
        );
        ensure!(
            self.vignetting < 1.0 && self.gain_amplitude < 1.0,
            "acquisition.vignetting and gain_amplitude must be < 1"
        );
        ensure!(
            self.gain_period_s > 0.0 && self.gain_period_s.is_finite(),
            "acquisition.gain_period_s must be > 0"
        );
        ensure!(
            self.blur_sigma_px <= 5.0,
            "acquisition.blur_sigma_px must be <= 5"
        );
        Ok(())
    }

    /// The picture a camera would acquire where `rendered` was rendered, for frame
    /// `index` at time `time_s`: every pixel of the camera's valid region is a
    /// measurement (the sky included, as a real camera sees it), degraded as the module
    /// documentation says. Fails on settings [`Acquisition::validate`] refuses
    /// ([`WorldError::Sequence`]), and on a rendering that is not of `camera`'s size or
    /// whose buffers are not ([`WorldError::Picture`]).
    pub fn acquire(
        &self,
        rendered: &Frame,
        camera: &Camera,
        index: usize,
        time_s: f64,
    ) -> Result<Image, WorldError> {
        self.validate()?;
        rendered.check_size("rendering to acquire", camera)?;
        if !time_s.is_finite() {
            return Err(WorldError::Sequence(format!(
                "acquisition time must be finite, got {time_s}"
            )));
        }
        let (w, h) = (rendered.width() as usize, rendered.height() as usize);
        let valid = camera.valid_pixels();
        let mut intensity = rendered.intensity.clone();
        let (centre, radius) = match camera.region() {
            ValidRegion::Annulus(a) => (a.center_px, a.outer_radius_px),
            _ => {
                let c = [(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0];
                (c, (c[0] * c[0] + c[1] * c[1]).sqrt().max(1.0))
            }
        };
        let phase = std::f64::consts::TAU * time_s / self.gain_period_s;
        let gain = 1.0 + self.gain_amplitude * phase.sin();
        let offset = self.offset_amplitude * phase.cos();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !valid[i] {
                    continue;
                }
                let r2 = ((x as f64 - centre[0]).powi(2) + (y as f64 - centre[1]).powi(2))
                    / (radius * radius);
                let v = f64::from(intensity[i]) * (1.0 - self.vignetting * r2.min(1.0));
                intensity[i] = (gain * v + offset) as f32;
            }
        }
        if self.blur_sigma_px > 0.0 {
            intensity = blur(&intensity, w, h, valid, self.blur_sigma_px);
        }
        let mut rng = SplitMix64::new(
            splat::rng::mix64(self.noise_seed) ^ (index as u64).wrapping_mul(0x9E37_79B9),
        );
        for i in 0..w * h {
            if valid[i] {
                let noisy = f64::from(intensity[i]) + self.noise_sigma * rng.normal();
                intensity[i] = noisy.clamp(0.0, 1.0) as f32;
            }
        }
        Image::from_parts(
            rendered.width(),
            rendered.height(),
            intensity,
            valid.to_vec(),
        )
        .map_err(WorldError::from)
    }
}

/// Separable Gaussian blur of the valid pixels (normalised over the valid
/// neighbours, so the mask's edge does not darken).
fn blur(intensity: &[f32], w: usize, h: usize, valid: &[bool], sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-(d * d) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = src.to_vec();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !valid[i] {
                    continue;
                }
                let (mut sum, mut weight) = (0.0f64, 0.0f64);
                for (k, g) in kernel.iter().enumerate() {
                    let d = k as isize - radius;
                    let (xx, yy) = if horizontal {
                        (x as isize + d, y as isize)
                    } else {
                        (x as isize, y as isize + d)
                    };
                    if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                        continue;
                    }
                    let j = yy as usize * w + xx as usize;
                    if valid[j] {
                        sum += g * f64::from(src[j]);
                        weight += g;
                    }
                }
                out[i] = (sum / weight) as f32;
            }
        }
        out
    };
    let rows = pass(intensity, true);
    pass(&rows, false)
}
