//! The desired picture as a camera turned about its centre would see it: a central
//! camera's rays do not depend on its orientation, so a global search renders each node
//! once and compares it with the picture turned back by each orientation.

use frame::{AnyImage, Image};
use ucm::Camera;

use crate::VvsError;

/// `picture` as the camera would see it turned by `angle_rad` about its optical axis
/// (`world_from_camera · Rz(angle)`): each pixel takes the bilinear interpolation of
/// `picture` where its ray, turned by the angle, meets the image. Pixels whose four
/// neighbours there are not all observed (outside the valid region, or unobserved) are
/// not observed. Exact up to the interpolation for any camera model: turning about the
/// optical axis changes no ray, only which pixel sees it.
pub fn turned_about_optical_axis(
    picture: &impl AnyImage,
    camera: &Camera,
    angle_rad: f64,
) -> Result<Image, VvsError> {
    let (sin, cos) = angle_rad.sin_cos();
    resampled_by_rays(picture, camera, |ray| {
        [
            cos * ray[0] - sin * ray[1],
            sin * ray[0] + cos * ray[1],
            ray[2],
        ]
    })
}

/// `picture` as the camera would see it turned by `rotation` about its centre
/// (`world_from_camera · rotation`), where the turned camera's field overlaps the
/// original one (elsewhere not observed): [`turned_about_optical_axis`] for any
/// rotation (a central camera's rays do not depend on its orientation).
pub fn turned(
    picture: &impl AnyImage,
    camera: &Camera,
    rotation: glam::DQuat,
) -> Result<Image, VvsError> {
    resampled_by_rays(picture, camera, |ray| {
        rotation.mul_vec3(glam::DVec3::from_array(ray)).to_array()
    })
}

/// Each pixel of the result takes the bilinear interpolation of `picture` where the
/// ray `turn(ray of the pixel)` meets the image.
fn resampled_by_rays(
    picture: &impl AnyImage,
    camera: &Camera,
    turn: impl Fn([f64; 3]) -> [f64; 3],
) -> Result<Image, VvsError> {
    if picture.width() != camera.width() || picture.height() != camera.height() {
        return Err(VvsError::DesiredSize {
            got_width: picture.width(),
            got_height: picture.height(),
            width: camera.width(),
            height: camera.height(),
        });
    }
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let source = picture.intensity();
    let valid = camera.valid_pixels();
    let observed = |k: usize| valid[k] && picture.is_observed(k);
    let mut intensity = vec![0.0f32; w * h];
    let mut seen = vec![false; w * h];
    for (k, (value, seen)) in intensity.iter_mut().zip(&mut seen).enumerate() {
        if !valid[k] {
            continue;
        }
        let Ok(ray) = camera.unproject([(k % w) as f64, (k / w) as f64]) else {
            continue;
        };
        // The turned camera's ray in the frame of the camera before the turn.
        let Ok([u, v]) = camera.project_unbounded(turn(ray)) else {
            continue;
        };
        let (u0, v0) = (u.floor(), v.floor());
        if !(u0 >= 0.0 && v0 >= 0.0 && u0 + 1.0 < w as f64 && v0 + 1.0 < h as f64) {
            continue;
        }
        let (i, j) = (u0 as usize, v0 as usize);
        let corners = [
            j * w + i,
            j * w + i + 1,
            (j + 1) * w + i,
            (j + 1) * w + i + 1,
        ];
        if !corners.iter().all(|&c| observed(c)) {
            continue;
        }
        let (fu, fv) = ((u - u0) as f32, (v - v0) as f32);
        let [a, b, c, d] = corners.map(|c| source[c]);
        *value = (a * (1.0 - fu) + b * fu) * (1.0 - fv) + (c * (1.0 - fu) + d * fu) * fv;
        *seen = true;
    }
    Ok(Image::from_parts(
        camera.width(),
        camera.height(),
        intensity,
        seen,
    )?)
}

/// Per pixel: valid and no valid-but-unobserved pixel within `radius` (a square window),
/// by a summed-area table of the missing pixels.
pub(super) fn clear_of_missing(camera: &Camera, observed: &[bool], radius: usize) -> Vec<bool> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let valid = camera.valid_pixels();
    let mut table = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u32;
        for x in 0..w {
            let k = y * w + x;
            row += u32::from(valid[k] && !observed[k]);
            table[(y + 1) * (w + 1) + x + 1] = table[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius + 1).min(w));
            let missing = table[y1 * (w + 1) + x1] + table[y0 * (w + 1) + x0]
                - table[y0 * (w + 1) + x1]
                - table[y1 * (w + 1) + x0];
            out[y * w + x] = valid[y * w + x] && observed[y * w + x] && missing == 0;
        }
    }
    out
}
