//! Rigid transforms (SE(3)) shared by every crate of the workspace.
//!
//! Conventions (see `docs/ARCHITECTURE.md` and `../shared/notes/math.md`):
//!
//! * A transform is named by its frames: `camera_from_world` maps a point expressed in
//!   the world frame to the camera frame (`point_in_camera = camera_from_world *
//!   point_in_world`). Its inverse is `world_from_camera`.
//! * A *twist* `v = (υ, ω)` (linear first, then angular) is a velocity of the camera,
//!   expressed in the camera frame. One step of an optimiser moves the camera as
//!   `world_from_camera ← world_from_camera · exp(v)`. A world point seen from the camera
//!   then moves as `Ẋ = −υ − ω × X`.
//! * The paper's pose vector `r = (tX, tY, tZ, θwX, θwY, θwZ)` is a translation and an
//!   axis-angle rotation vector `θw` ([`Isometry3::from_pose_vector`]); it is *not* the
//!   twist `log(T)`, whose linear part differs from the translation.
//!
//! Everything is `f64`: poses are composed many times and must not drift.

use glam::{DMat3, DQuat, DVec3, Mat3, Vec3};
use serde::{Deserialize, Serialize};
use std::ops::Mul;

use crate::UcmError;

/// A 6-vector twist `(υx, υy, υz, ωx, ωy, ωz)`: linear velocity, then angular velocity.
pub type Twist = [f64; 6];

/// A rigid transform `p ↦ R p + t`, stored as a unit quaternion and a translation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Isometry3 {
    /// The rotation `R` (unit quaternion).
    pub rotation: DQuat,
    /// The translation `t`, in metres.
    pub translation: DVec3,
}

impl Default for Isometry3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// `sin(θ)/θ`, accurate near 0.
fn sinc(theta: f64) -> f64 {
    if theta.abs() < 1e-4 {
        let t2 = theta * theta;
        1.0 - t2 / 6.0 + t2 * t2 / 120.0
    } else {
        theta.sin() / theta
    }
}

/// Rotation vector (axis-angle `θw`) to unit quaternion.
pub fn quat_from_rotation_vector(rotation_vector: DVec3) -> DQuat {
    let theta = rotation_vector.length();
    let half = 0.5 * theta;
    // sin(θ/2)/θ = sinc(θ/2)/2
    let k = 0.5 * sinc(half);
    DQuat::from_xyzw(
        rotation_vector.x * k,
        rotation_vector.y * k,
        rotation_vector.z * k,
        half.cos(),
    )
    .normalize()
}

/// Unit quaternion to rotation vector `θw`, with `θ ∈ [0, π]`; accurate near 0 and π.
pub fn rotation_vector_from_quat(rotation: DQuat) -> DVec3 {
    let q = if rotation.w < 0.0 {
        -rotation
    } else {
        rotation
    };
    let v = DVec3::new(q.x, q.y, q.z);
    let s = v.length();
    let w = q.w;
    // θ = 2 atan2(s, w), rotation vector = v θ / s.
    let k = if s < 1e-8 {
        // θ/s = 2/w (1 − s²/(3w²) + …) since atan2(s, w) ≈ s/w − s³/(3w³)
        2.0 / w * (1.0 - s * s / (3.0 * w * w))
    } else {
        2.0 * s.atan2(w) / s
    };
    v * k
}

/// The skew-symmetric matrix `[a]×`, such that `[a]× b = a × b`.
pub fn skew(a: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, a.z, -a.y),
        DVec3::new(-a.z, 0.0, a.x),
        DVec3::new(a.y, -a.x, 0.0),
    )
}

/// Coefficients `(a, b)` of `V = I + a [ω]× + b [ω]×²` (left Jacobian of SO(3)),
/// `a = (1 − cos θ)/θ²`, `b = (θ − sin θ)/θ³`, with series near 0.
fn left_jacobian_coefficients(theta: f64) -> (f64, f64) {
    if theta < 1e-3 {
        let t2 = theta * theta;
        (
            0.5 - t2 / 24.0 + t2 * t2 / 720.0,
            1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
        )
    } else {
        let t2 = theta * theta;
        (
            (1.0 - theta.cos()) / t2,
            (theta - theta.sin()) / (t2 * theta),
        )
    }
}

impl Isometry3 {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// A transform from a rotation and a translation (the quaternion is normalised).
    pub fn from_rotation_translation(rotation: DQuat, translation: DVec3) -> Self {
        Self {
            rotation: rotation.normalize(),
            translation,
        }
    }

    /// A pure translation.
    pub fn from_translation(translation: DVec3) -> Self {
        Self {
            rotation: DQuat::IDENTITY,
            translation,
        }
    }

    /// A transform from a rotation matrix (assumed orthonormal) and a translation.
    pub fn from_mat3_translation(rotation: DMat3, translation: DVec3) -> Self {
        Self::from_rotation_translation(DQuat::from_mat3(&rotation), translation)
    }

    /// The paper's pose vector `r = (tX, tY, tZ, θwX, θwY, θwZ)`: translation in metres
    /// and axis-angle rotation vector in radians. Non-finite input is an error.
    pub fn from_pose_vector(r: [f64; 6]) -> Result<Self, UcmError> {
        if r.iter().any(|x| !x.is_finite()) {
            return Err(UcmError::NonFinitePose { values: r });
        }
        Ok(Self {
            rotation: quat_from_rotation_vector(DVec3::new(r[3], r[4], r[5])),
            translation: DVec3::new(r[0], r[1], r[2]),
        })
    }

    /// The paper's pose vector `(t, θw)` of this transform, `θ ∈ [0, π]`.
    pub fn to_pose_vector(&self) -> [f64; 6] {
        let w = rotation_vector_from_quat(self.rotation);
        let t = self.translation;
        [t.x, t.y, t.z, w.x, w.y, w.z]
    }

    /// The exponential map of SE(3): the transform reached by following the twist
    /// `v = (υ, ω)` for unit time. Non-finite input is an error.
    pub fn exp(v: Twist) -> Result<Self, UcmError> {
        if v.iter().any(|x| !x.is_finite()) {
            return Err(UcmError::NonFinitePose { values: v });
        }
        let upsilon = DVec3::new(v[0], v[1], v[2]);
        let omega = DVec3::new(v[3], v[4], v[5]);
        let theta = omega.length();
        let (a, b) = left_jacobian_coefficients(theta);
        let w_cross_u = omega.cross(upsilon);
        let translation = upsilon + a * w_cross_u + b * omega.cross(w_cross_u);
        Ok(Self {
            rotation: quat_from_rotation_vector(omega),
            translation,
        })
    }

    /// The logarithm of SE(3), inverse of [`Isometry3::exp`] for rotation angles in
    /// `[0, π)`.
    pub fn log(&self) -> Twist {
        let omega = rotation_vector_from_quat(self.rotation);
        let theta = omega.length();
        // V⁻¹ = I − ½[ω]× + c [ω]×², c = (1 − θ sin θ / (2 (1 − cos θ))) / θ²
        let c = if theta < 1e-3 {
            let t2 = theta * theta;
            1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
        } else {
            (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / (theta * theta)
        };
        let t = self.translation;
        let w_cross_t = omega.cross(t);
        let upsilon = t - 0.5 * w_cross_t + c * omega.cross(w_cross_t);
        [upsilon.x, upsilon.y, upsilon.z, omega.x, omega.y, omega.z]
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        let rotation = self.rotation.inverse();
        Self {
            rotation,
            translation: -(rotation * self.translation),
        }
    }

    /// `R p + t`.
    #[inline]
    pub fn transform_point(&self, point: DVec3) -> DVec3 {
        self.rotation * point + self.translation
    }

    /// `R d`.
    #[inline]
    pub fn transform_vector(&self, vector: DVec3) -> DVec3 {
        self.rotation * vector
    }

    /// The rotation matrix `R`.
    pub fn rotation_matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    /// `(R, t)` rounded to `f32`, for hot loops over points expressed near the origin
    /// of a cloud (see `splat`).
    pub fn to_f32(&self) -> (Mat3, Vec3) {
        (self.rotation_matrix().as_mat3(), self.translation.as_vec3())
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation.is_finite()
    }

    /// Angle of the rotation, in radians, in `[0, π]`.
    pub fn angle_rad(&self) -> f64 {
        rotation_vector_from_quat(self.rotation).length()
    }

    /// Position error (m) and rotation error (rad) between two transforms:
    /// `|t_a − t_b|` and the angle of `R_a R_bᵀ`. For `world_from_camera` transforms this
    /// is the distance between the two camera centres.
    pub fn distance_to(&self, other: &Self) -> (f64, f64) {
        let dt = (self.translation - other.translation).length();
        let dr = rotation_vector_from_quat(self.rotation * other.rotation.inverse()).length();
        (dt, dr)
    }
}

impl Mul for Isometry3 {
    type Output = Isometry3;
    /// Composition: `(a * b) p = a (b p)`, so `a_from_c = a_from_b * b_from_c`.
    fn mul(self, rhs: Isometry3) -> Isometry3 {
        Isometry3 {
            rotation: (self.rotation * rhs.rotation).normalize(),
            translation: self.rotation * rhs.translation + self.translation,
        }
    }
}

impl Mul<DVec3> for Isometry3 {
    type Output = DVec3;
    fn mul(self, rhs: DVec3) -> DVec3 {
        self.transform_point(rhs)
    }
}
