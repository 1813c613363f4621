//! A picture seen by another central camera at the same pose.

use ucm::Camera;

use crate::{AnyImage, FrameError, Image};

impl Image {
    /// This picture, taken by `from`, as `to` would have taken it from the same
    /// viewpoint with the same orientation: each pixel of `to` takes, bilinearly, this
    /// picture's intensity where its ray meets `from`'s image, and is valid where that
    /// point and its four neighbours are valid here and the pixel is in `to`'s region
    /// (a pinhole picture resampled to a catadioptric camera fills the part of its
    /// field the pinhole saw). [`FrameError::Size`] unless this picture has `from`'s
    /// size.
    pub fn resampled(&self, from: &Camera, to: &Camera) -> Result<Image, FrameError> {
        self.check_size("picture to resample", from)?;
        let (w, h) = (to.width() as usize, to.height() as usize);
        let (fw, fh) = (from.width() as usize, from.height() as usize);
        let mut out = Image::new(to.width(), to.height());
        let region = to.valid_pixels();
        for k in 0..w * h {
            if !region[k] {
                continue;
            }
            let Ok(ray) = to.unproject([(k % w) as f64, (k / w) as f64]) else {
                continue;
            };
            let Ok([u, v]) = from.project_unbounded(ray) else {
                continue;
            };
            if !(u >= 0.0 && v >= 0.0 && u <= (fw - 1) as f64 && v <= (fh - 1) as f64) {
                continue;
            }
            let (x0, y0) = (
                (u as usize).min(fw.saturating_sub(2)),
                (v as usize).min(fh.saturating_sub(2)),
            );
            let (x1, y1) = ((x0 + 1).min(fw - 1), (y0 + 1).min(fh - 1));
            let corners = [y0 * fw + x0, y0 * fw + x1, y1 * fw + x0, y1 * fw + x1];
            if !corners.iter().all(|&c| self.is_observed(c)) {
                continue;
            }
            let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
            let i = &self.intensity;
            let top = i[corners[0]] * (1.0 - fx) + i[corners[1]] * fx;
            let bottom = i[corners[2]] * (1.0 - fx) + i[corners[3]] * fx;
            out.intensity[k] = top * (1.0 - fy) + bottom * fy;
            out.valid[k] = true;
        }
        Ok(out)
    }
}

/// The camera `to` with its region cut down to the pixels whose ray `from` sees inside
/// its valid region: the camera of [`Image::resampled`] pictures, whose renderings
/// then hold pixels only where the resampled picture may.
pub fn seen_through(to: &Camera, from: &Camera) -> Result<Camera, FrameError> {
    let (w, h) = (to.width() as usize, to.height() as usize);
    let region = to.valid_pixels();
    let valid: Vec<bool> = (0..w * h)
        .map(|k| {
            region[k]
                && to
                    .unproject([(k % w) as f64, (k / w) as f64])
                    .ok()
                    .and_then(|ray| from.project(ray).ok())
                    .is_some()
        })
        .collect();
    let mask = ucm::Mask::new(to.width(), to.height(), valid)?;
    Ok(to.with_region(ucm::ValidRegion::Mask(mask))?)
}
