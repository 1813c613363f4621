//! Synthetic RGB-D frames with known geometry and colour, ray-cast analytically.

use glam::DVec3;
use rgbd::{ColorImage, DepthImage};
use ucm::{Camera, Intrinsics, Isometry3, ValidRegion};

/// A 64×48 pinhole camera, focal 60 pixels (56° across).
pub fn pinhole(focal: f64) -> Camera {
    Camera::new(
        Intrinsics {
            alpha_u: focal,
            alpha_v: focal,
            u0: 31.5,
            v0: 23.5,
            xi: 0.0,
            skew: 0.0,
        },
        None,
        64,
        48,
        ValidRegion::Full,
    )
    .unwrap()
}

/// The colour of a world point on the wall: smooth stripes along x and y, so that a
/// bilinear sample is near the true colour and a shifted sample is not.
pub fn texture(p: DVec3) -> [f64; 3] {
    [
        128.0 + 100.0 * (p.x * 9.0).sin(),
        128.0 + 100.0 * (p.y * 7.0).cos(),
        128.0 + 50.0 * ((p.x + p.y) * 5.0).sin(),
    ]
}

/// The scene: a wall `z = 2` (world) and, optionally, a small near square
/// `|x|, |y| < half`, `z = 1` in front of it, coloured black.
#[derive(Clone, Copy)]
pub struct Scene {
    pub square_half_m: Option<f64>,
}

impl Scene {
    /// The first surface a ray from `origin` along `direction` meets: point and colour.
    pub fn cast(&self, origin: DVec3, direction: DVec3) -> Option<(DVec3, [f64; 3])> {
        if let Some(half) = self.square_half_m {
            let t = (1.0 - origin.z) / direction.z;
            let p = origin + t * direction;
            if t > 0.0 && p.x.abs() < half && p.y.abs() < half {
                return Some((p, [0.0; 3]));
            }
        }
        let t = (2.0 - origin.z) / direction.z;
        (t > 0.0).then(|| {
            let p = origin + t * direction;
            (p, texture(p))
        })
    }

    /// The depth picture of a camera at `world_from_camera` (depth along its Z).
    pub fn depth(&self, camera: &Camera, world_from_camera: &Isometry3) -> DepthImage {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let depth = (0..w * h)
            .map(|k| {
                let ray = camera.unproject([(k % w) as f64, (k / w) as f64]).unwrap();
                let direction = world_from_camera.transform_vector(DVec3::from(ray));
                match self.cast(world_from_camera.translation, direction) {
                    Some((p, _)) => world_from_camera.inverse().transform_point(p).z as f32,
                    None => 0.0,
                }
            })
            .collect();
        DepthImage::from_metres(w as u32, h as u32, depth).unwrap()
    }

    /// The colour picture of a camera at `world_from_camera`.
    pub fn color(&self, camera: &Camera, world_from_camera: &Isometry3) -> ColorImage {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let rgb = (0..w * h)
            .map(|k| {
                let ray = camera.unproject([(k % w) as f64, (k / w) as f64]).unwrap();
                let direction = world_from_camera.transform_vector(DVec3::from(ray));
                match self.cast(world_from_camera.translation, direction) {
                    Some((_, c)) => c.map(|v| v.round().clamp(0.0, 255.0) as u8),
                    None => [0; 3],
                }
            })
            .collect();
        ColorImage::from_rgb(w as u32, h as u32, rgb).unwrap()
    }
}

/// A camera at `(x, y, 0)` looking along world +Z (the camera frame is the world's).
pub fn at(x: f64, y: f64) -> Isometry3 {
    Isometry3::from_translation(DVec3::new(x, y, 0.0))
}
