//! The constants of one rendering ([`View`]: the camera's intrinsics, the pose, the
//! splats' sizes and the depth band) and the part of the image the renderer's buffers
//! cover ([`Region`]).

use glam::{DMat3, DVec3, Mat3, Vec3};
use ucm::Camera;

use super::options::RenderOptions;

/// The largest singular value of `[[a, s], [0, b]]`.
fn affine_norm(a: f64, b: f64, s: f64) -> f32 {
    let trace = a * a + s * s + b * b;
    let det = a * b;
    ((trace + (trace * trace - 4.0 * det * det).max(0.0).sqrt()) * 0.5).sqrt() as f32
}

/// The per-point constants of a rendering.
#[derive(Clone, Copy)]
pub(super) struct View {
    pub(super) undistorted: bool,
    pub(super) alpha_u: f32,
    pub(super) alpha_v: f32,
    pub(super) skew: f32,
    pub(super) u0: f32,
    pub(super) v0: f32,
    /// From the cloud's frame to the camera's (cells' centres).
    pub(super) rotation: Mat3,
    pub(super) translation: Vec3,
    /// The same in `f64` (cells' corners).
    rotation_f64: DMat3,
    translation_f64: DVec3,
    /// The projection's transform, from a point's steps to the camera frame: the
    /// rotation times the cloud's step
    /// ([`PointCloud::step_m`](crate::PointCloud::step_m)), and the corner of the cell
    /// being drawn in the camera frame ([`View::in_cell`]).
    pub(super) point_rotation: Mat3,
    pub(super) point_translation: Vec3,
    pub(super) alpha: f32,
    pub(super) xi: f32,
    /// The first column and row of the [`Region`] (splats' pixels are counted from it).
    pub(super) origin: [i32; 2],
    /// The [`Region`]'s width and height, pixels.
    pub(super) width: i32,
    pub(super) height: i32,
    pub(super) splat_scale: f32,
    /// Largest splat width, pixels (`2 · max_splat_radius_px + 1`).
    pub(super) max_width: i32,
    /// Largest singular value of the affine part of the intrinsics
    /// `[[α_u, skew], [0, α_v]]` (how much it can stretch a length).
    pub(super) affine_norm: f32,
    pub(super) depth_band: f32,
    /// `1 + depth_band`.
    pub(super) band_factor: f32,
}

impl View {
    /// The constants of a rendering with `camera` and `options` into `region` from
    /// the pose `rotation`, `translation` (camera from the cloud's frame), of a cloud
    /// whose positions are steps of `step_m` (the projection's transform is then the
    /// one of a cell whose corner is at the cloud's origin).
    pub(super) fn new(
        camera: &Camera,
        options: &RenderOptions,
        region: Region,
        rotation: DMat3,
        translation: DVec3,
        step_m: f64,
    ) -> Self {
        let i = camera.intrinsics();
        Self {
            undistorted: camera.distortion().is_none(),
            alpha_u: i.alpha_u as f32,
            alpha_v: i.alpha_v as f32,
            skew: i.skew as f32,
            u0: i.u0 as f32,
            v0: i.v0 as f32,
            rotation: rotation.as_mat3(),
            translation: translation.as_vec3(),
            rotation_f64: rotation,
            translation_f64: translation,
            point_rotation: (rotation * step_m).as_mat3(),
            point_translation: translation.as_vec3(),
            alpha: i.alpha_u.max(i.alpha_v) as f32,
            xi: i.xi as f32,
            origin: [region.u0 as i32, region.v0 as i32],
            width: region.width as i32,
            height: region.height as i32,
            splat_scale: options.splat_scale,
            max_width: 2 * options.max_splat_radius_px.min(16_000) as i32 + 1,
            affine_norm: affine_norm(i.alpha_u, i.alpha_v, i.skew),
            depth_band: options.depth_band,
            band_factor: 1.0 + options.depth_band,
        }
    }

    /// A cell's corner (relative to the cloud's origin) in the camera frame, rounded
    /// once from `f64`.
    pub(super) fn corner(&self, corner_m: [f64; 3]) -> Vec3 {
        (self.rotation_f64 * DVec3::from_array(corner_m) + self.translation_f64).as_vec3()
    }

    /// The view whose projection draws the points of the cell whose corner is at
    /// `corner` in the camera frame ([`View::corner`]).
    #[inline(always)]
    pub(super) fn in_cell(&self, corner: Vec3) -> Self {
        Self {
            point_translation: corner,
            ..*self
        }
    }
}

/// The smallest rectangle of the image that holds every valid pixel of the camera:
/// the renderer's buffers cover it alone, and splats are clipped to it (whatever would
/// be drawn outside it lands on masked pixels, so the frame is the same; at 640×480
/// the catadioptric disc's box holds 71 % of the pixels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Region {
    pub(super) u0: usize,
    pub(super) v0: usize,
    pub(super) width: usize,
    pub(super) height: usize,
}

impl Region {
    /// The box of `camera`'s valid pixels (one pixel at the origin if none is valid).
    pub(super) fn of(camera: &Camera) -> Self {
        let w = camera.width() as usize;
        let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
        for (k, _) in camera
            .valid_pixels()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
        {
            let (u, v) = (k % w, k / w);
            (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
        }
        if u0 > u1 {
            return Self {
                u0: 0,
                v0: 0,
                width: 1,
                height: 1,
            };
        }
        Self {
            u0,
            v0,
            width: u1 - u0 + 1,
            height: v1 - v0 + 1,
        }
    }

    pub(super) fn len(&self) -> usize {
        self.width * self.height
    }
}
