//! [`Camera`]: the unified central model with its pixel mapping, optional distortion,
//! image size and valid region. Every method is generic over `f32`/`f64`.

use crate::intrinsics::Params;
use crate::model::{self, OutOfView};
use crate::{Distortion, Intrinsics, Real, UcmError, ValidRegion};

/// A calibrated catadioptric (or pinhole, ξ = 0) camera.
///
/// Built only through [`Camera::new`] (or the loaders), which validates every parameter;
/// a `Camera` is therefore always usable.
#[derive(Clone)]
pub struct Camera {
    intrinsics: Intrinsics,
    distortion: Option<Distortion>,
    width: u32,
    height: u32,
    region: ValidRegion,
    valid: Vec<bool>,
    valid_count: usize,
    pub(crate) params_f32: Params<f32>,
    pub(crate) params_f64: Params<f64>,
}

impl std::fmt::Debug for Camera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Camera")
            .field("intrinsics", &self.intrinsics)
            .field("distortion", &self.distortion)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("region", &self.region)
            .field("valid_pixel_count", &self.valid_count)
            .finish_non_exhaustive()
    }
}

impl PartialEq for Camera {
    fn eq(&self, other: &Self) -> bool {
        self.intrinsics == other.intrinsics
            && self.distortion == other.distortion
            && self.width == other.width
            && self.height == other.height
            && self.region == other.region
    }
}

impl Camera {
    /// Validate and build a camera. A distortion whose coefficients are all zero is
    /// dropped.
    pub fn new(
        intrinsics: Intrinsics,
        distortion: Option<Distortion>,
        width: u32,
        height: u32,
        region: ValidRegion,
    ) -> Result<Self, UcmError> {
        intrinsics.validate()?;
        if let Some(d) = &distortion {
            d.validate()?;
        }
        if width == 0 || height == 0 {
            return Err(UcmError::EmptyImage { width, height });
        }
        if u64::from(width) * u64::from(height) > crate::MAX_PIXELS {
            return Err(UcmError::TooManyPixels { width, height });
        }
        region.validate(width, height)?;
        let distortion = distortion.filter(|d| !d.is_identity());
        let valid = region.rasterise(width, height);
        let valid_count = valid.iter().filter(|&&v| v).count();
        if valid_count == 0 {
            return Err(UcmError::EmptyRegion);
        }
        Ok(Self {
            params_f32: Params::new(&intrinsics, distortion.as_ref()),
            params_f64: Params::new(&intrinsics, distortion.as_ref()),
            intrinsics,
            distortion,
            width,
            height,
            region,
            valid,
            valid_count,
        })
    }

    /// The same camera with another valid region.
    pub fn with_region(&self, region: ValidRegion) -> Result<Self, UcmError> {
        Self::new(
            self.intrinsics,
            self.distortion,
            self.width,
            self.height,
            region,
        )
    }

    /// The same camera (same field of view and region) at `factor` times the resolution:
    /// focal lengths and radii scale by `factor`, the principal point maps pixel centres
    /// to pixel centres. An explicit mask cannot be rescaled and is an error
    /// ([`UcmError::MaskSizeMismatch`]).
    pub fn rescaled(&self, factor: u32) -> Result<Self, UcmError> {
        let (width, height) = match (
            self.width.checked_mul(factor),
            self.height.checked_mul(factor),
        ) {
            (Some(w), Some(h)) => (w, h),
            _ => {
                return Err(UcmError::TooManyPixels {
                    width: self.width.saturating_mul(factor),
                    height: self.height.saturating_mul(factor),
                });
            }
        };
        let f = f64::from(factor);
        let (intrinsics, region) = self.scaled(|length| length * f);
        let region = region.map_err(|m| UcmError::MaskSizeMismatch {
            mask_width: m.width(),
            mask_height: m.height(),
            width,
            height,
        })?;
        Self::new(intrinsics, self.distortion, width, height, region)
    }

    /// The same camera (same field of view) at `1/factor` of the resolution, for image
    /// pyramids: the image is `⌊width/factor⌋ × ⌊height/factor⌋`, focal lengths and radii
    /// divide by `factor`, pixel centres map to the centres of the `factor × factor`
    /// blocks they average, and a masked pixel is valid when every pixel of its block
    /// is. `factor` 0 is [`UcmError::EmptyImage`], as is an image smaller than a block.
    pub fn downsampled(&self, factor: u32) -> Result<Self, UcmError> {
        let (width, height) = (
            self.width.checked_div(factor).unwrap_or(0),
            self.height.checked_div(factor).unwrap_or(0),
        );
        if width == 0 || height == 0 {
            return Err(UcmError::EmptyImage { width, height });
        }
        let f = f64::from(factor);
        let (intrinsics, region) = self.scaled(|length| length / f);
        let region = match region {
            Ok(region) => region,
            Err(m) => {
                let (w, k) = (self.width as usize, factor as usize);
                let flags = m.flags();
                let valid = (0..height as usize)
                    .flat_map(|y| (0..width as usize).map(move |x| (x, y)))
                    .map(|(x, y)| {
                        (0..k).all(|dy| (0..k).all(|dx| flags[(y * k + dy) * w + x * k + dx]))
                    })
                    .collect();
                ValidRegion::Mask(crate::Mask::new(width, height, valid)?)
            }
        };
        Self::new(intrinsics, self.distortion, width, height, region)
    }

    /// The intrinsics and the analytic valid region of the same field of view with
    /// pixel lengths mapped by `length` (pixel centres such that blocks of pixels and
    /// their centres correspond); an explicit mask is returned as the error, for the
    /// callers to resample or refuse.
    fn scaled(
        &self,
        length: impl Fn(f64) -> f64,
    ) -> (Intrinsics, Result<ValidRegion, &crate::Mask>) {
        let centre = |c: f64| length(c + 0.5) - 0.5;
        let mut intrinsics = self.intrinsics;
        intrinsics.alpha_u = length(intrinsics.alpha_u);
        intrinsics.alpha_v = length(intrinsics.alpha_v);
        intrinsics.skew = length(intrinsics.skew);
        intrinsics.u0 = centre(intrinsics.u0);
        intrinsics.v0 = centre(intrinsics.v0);
        let region = match &self.region {
            ValidRegion::Full => Ok(ValidRegion::Full),
            ValidRegion::Annulus(a) => Ok(ValidRegion::Annulus(crate::Annulus {
                center_px: [centre(a.center_px[0]), centre(a.center_px[1])],
                inner_radius_px: length(a.inner_radius_px),
                outer_radius_px: length(a.outer_radius_px),
            })),
            ValidRegion::Mask(m) => Err(m),
        };
        (intrinsics, region)
    }

    /// The model's parameters.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// Mei's distortion, if any.
    pub fn distortion(&self) -> Option<&Distortion> {
        self.distortion.as_ref()
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of pixels, `width × height`.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The valid region as configured.
    pub fn region(&self) -> &ValidRegion {
        &self.region
    }

    /// Validity of every pixel centre, row-major (`index = row × width + column`).
    pub fn valid_pixels(&self) -> &[bool] {
        &self.valid
    }

    /// Number of valid pixels.
    pub fn valid_pixel_count(&self) -> usize {
        self.valid_count
    }

    /// Row-major index of the pixel containing `(u, v)` (pixel `(i, j)` covers
    /// `[i − ½, i + ½) × [j − ½, j + ½)`), or `None` outside the image.
    #[inline(always)]
    pub fn pixel_index<T: Real>(&self, pixel: [T; 2]) -> Option<usize> {
        let (u, v) = (pixel[0].to_f64() + 0.5, pixel[1].to_f64() + 0.5);
        if u >= 0.0 && v >= 0.0 && u < f64::from(self.width) && v < f64::from(self.height) {
            Some(v as usize * self.width as usize + u as usize)
        } else {
            None
        }
    }

    /// Projection onto the (unbounded) image plane, pixels, with the model's domain
    /// checks but no image or region check.
    #[inline(always)]
    pub fn project_unbounded<T: Real>(&self, point_in_camera: [T; 3]) -> Result<[T; 2], OutOfView> {
        let p = T::camera_params(self);
        let [x, y] = model::project_normalized(p.xi, point_in_camera)?;
        if !p.before_fold(x, y) {
            return Err(OutOfView::DistortionFold);
        }
        let [xd, yd] = p.distort(x, y);
        Ok(p.pixel_of(xd, yd))
    }

    /// [`Camera::project_unbounded`] of `rotation · p + translation` (glam's `Mat3 * Vec3`,
    /// then the translation added) for each point `p` of `points`, in `f32`, written to
    /// `pixels` (as many as the shorter of the two), `[NaN, NaN]` where it has no pixel:
    /// the same bits. Without lens distortion the loop has no branch, so that it
    /// vectorises where it is inlined into code compiled for a wide instruction set
    /// (a warp of a whole image); with it, the scalar projection point by point.
    #[inline(always)]
    pub fn project_transformed_unbounded(
        &self,
        rotation: &glam::Mat3,
        translation: glam::Vec3,
        points: &[[f32; 3]],
        pixels: &mut [[f32; 2]],
    ) {
        let params = &self.params_f32;
        if params.distorted {
            for (p, out) in points.iter().zip(pixels.iter_mut()) {
                let q = *rotation * glam::Vec3::from_array(*p) + translation;
                *out = self
                    .project_unbounded(q.to_array())
                    .unwrap_or([f32::NAN; 2]);
            }
            return;
        }
        let xi = params.xi;
        let beyond_one = xi > 1.0;
        // Blocks of points, their coordinates transposed into arrays so that the
        // arithmetic runs lane by lane (the last block padded with NaN points).
        const LANES: usize = 64;
        // The transform's and the model's numbers as locals (loads the vectoriser can
        // hoist out of the loop).
        let (r, t) = (*rotation, translation);
        let params = *params;
        for (points, pixels) in points.chunks(LANES).zip(pixels.chunks_mut(LANES)) {
            let mut p = [[f32::NAN; LANES]; 3];
            for (i, point) in points.iter().enumerate() {
                for (c, &v) in point.iter().enumerate() {
                    p[c][i] = v;
                }
            }
            let mut out = [[f32::NAN; LANES]; 2];
            for i in 0..LANES {
                let [px, py, pz] = [p[0][i], p[1][i], p[2][i]];
                // glam's `Mat3 * Vec3` (column by column), then the translation.
                let x = r.x_axis.x * px + r.y_axis.x * py + r.z_axis.x * pz + t.x;
                let y = r.x_axis.y * px + r.y_axis.y * py + r.z_axis.y * pz + t.y;
                let z = r.x_axis.z * px + r.y_axis.z * py + r.z_axis.z * pz + t.z;
                // `model::project_normalized`'s operations and tests, without a branch.
                let rho = (x * x + y * y + z * z).sqrt();
                let d = z + xi * rho;
                // (`rho < ∞` as `is_finite`: `rho` is a square root, never below 0.)
                let seen = (rho > 0.0)
                    & (rho < f32::INFINITY)
                    & (d > 0.0)
                    & (!beyond_one | (xi * z + rho > 0.0));
                let [u, v] = params.pixel_of(x / d, y / d);
                out[0][i] = if seen { u } else { f32::NAN };
                out[1][i] = if seen { v } else { f32::NAN };
            }
            for (i, (pixel, _)) in pixels.iter_mut().zip(points).enumerate() {
                *pixel = [out[0][i], out[1][i]];
            }
        }
    }

    /// Projection of a point of the camera frame to its pixel `(u, v)`, with the reason
    /// when it is not seen: behind the viewpoint, outside the ξ > 1 domain, outside the
    /// image, outside the valid region.
    #[inline(always)]
    pub fn project<T: Real>(&self, point_in_camera: [T; 3]) -> Result<[T; 2], OutOfView> {
        let pixel = self.project_unbounded(point_in_camera)?;
        match self.pixel_index(pixel) {
            None => Err(OutOfView::OutsideImage),
            Some(i) if !self.valid[i] => Err(OutOfView::OutsideRegion),
            Some(_) => Ok(pixel),
        }
    }

    /// Undistorted normalised coordinates `(x, y)` of a pixel.
    #[inline]
    pub fn normalized_from_pixel<T: Real>(&self, pixel: [T; 2]) -> Result<[T; 2], OutOfView> {
        if !(pixel[0].is_finite() && pixel[1].is_finite()) {
            return Err(OutOfView::BehindViewpoint);
        }
        let p = T::camera_params(self);
        let [xd, yd] = p.distorted_of_pixel(pixel[0], pixel[1]);
        p.undistort(xd, yd).ok_or(OutOfView::DistortionFold)
    }

    /// Unprojection of a pixel onto the unit sphere (the direction of its ray, in the
    /// camera frame). No image or region check: any sub-pixel position is accepted.
    #[inline]
    pub fn unproject<T: Real>(&self, pixel: [T; 2]) -> Result<[T; 3], OutOfView> {
        let [x, y] = self.normalized_from_pixel(pixel)?;
        model::lift_to_sphere(T::camera_params(self).xi, x, y)
    }

    /// `∂(u, v)/∂X`: the 2×3 Jacobian (row-major) of the pixel with respect to the point
    /// in the camera frame, distortion included.
    #[inline]
    pub fn projection_jacobian<T: Real>(
        &self,
        point_in_camera: [T; 3],
    ) -> Result<[[T; 3]; 2], OutOfView> {
        let p = T::camera_params(self);
        let [x, y] = model::project_normalized(p.xi, point_in_camera)?;
        if !p.before_fold(x, y) {
            return Err(OutOfView::DistortionFold);
        }
        let jn = model::normalized_jacobian(p.xi, point_in_camera);
        let k = p.pixel_jacobian(x, y);
        Ok(mat2x2_mul_2xn(k, jn))
    }

    /// Interaction matrix of the image of a 3D point: `∂(u, v)/∂v` (2×6, pixels per unit
    /// twist) for a camera twist `v = (υ, ω)` in the camera frame, from the point.
    #[inline]
    pub fn interaction_matrix<T: Real>(
        &self,
        point_in_camera: [T; 3],
    ) -> Result<[[T; 6]; 2], OutOfView> {
        let j = self.projection_jacobian(point_in_camera)?;
        Ok(model::interaction_from_point_jacobian(j, point_in_camera))
    }

    /// Interaction matrix `∂(u, v)/∂v` of a pixel whose scene point lies at range `ρ`
    /// (distance from the viewpoint, metres): the closed form of the notes, chained with
    /// the distortion and the focal lengths. This is what dense features use, knowing
    /// each pixel's rendered range.
    #[inline]
    pub fn pixel_interaction_matrix<T: Real>(
        &self,
        pixel: [T; 2],
        range: T,
    ) -> Result<[[T; 6]; 2], OutOfView> {
        let p = T::camera_params(self);
        let [x, y] = self.normalized_from_pixel(pixel)?;
        let l =
            model::normalized_interaction(p.xi, x, y, range).ok_or(OutOfView::OutsideXiDomain)?;
        Ok(mat2x2_mul_2xn(p.pixel_jacobian(x, y), l))
    }

    /// Project a slice of points of the camera frame (`f32`, the hot path of a
    /// renderer). `out[i]` receives the pixel or why there is none. The slices must have
    /// the same length.
    pub fn project_batch(
        &self,
        points_in_camera: &[[f32; 3]],
        out: &mut [Result<[f32; 2], OutOfView>],
    ) -> Result<(), UcmError> {
        check_lengths(points_in_camera.len(), out.len())?;
        for (o, &p) in out.iter_mut().zip(points_in_camera) {
            *o = self.project(p);
        }
        Ok(())
    }

    /// Interaction matrices of a slice of points (`f32`); points out of the model's
    /// domain get `None`. The slices must have the same length.
    pub fn interaction_batch(
        &self,
        points_in_camera: &[[f32; 3]],
        out: &mut [Option<[[f32; 6]; 2]>],
    ) -> Result<(), UcmError> {
        check_lengths(points_in_camera.len(), out.len())?;
        for (o, &p) in out.iter_mut().zip(points_in_camera) {
            *o = self.interaction_matrix(p).ok();
        }
        Ok(())
    }
}

pub(crate) fn check_lengths(input: usize, output: usize) -> Result<(), UcmError> {
    if input == output {
        Ok(())
    } else {
        Err(UcmError::LengthMismatch { input, output })
    }
}

#[inline(always)]
pub(crate) fn mat2x2_mul_2xn<T: Real, const N: usize>(
    a: [[T; 2]; 2],
    b: [[T; N]; 2],
) -> [[T; N]; 2] {
    let mut out = [[T::ZERO; N]; 2];
    for r in 0..2 {
        for c in 0..N {
            out[r][c] = a[r][0] * b[0][c] + a[r][1] * b[1][c];
        }
    }
    out
}
