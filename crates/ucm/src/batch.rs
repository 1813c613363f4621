//! The fixed pixel grid of a camera, with every pixel's interaction-matrix factors
//! precomputed: the hot path of dense features (`brightness`, `pgm`).
//!
//! For a pixel `u` with undistorted normalised coordinates `(x, y)`, the interaction
//! matrix `∂u/∂v` is `[T(u)/ρ | R(u)]`: only the translational block depends on the
//! rendered range `ρ`. [`PixelGrid`] stores `T` and `R` (computed in `f64`, stored in
//! `f32`), so that a whole image of interaction matrices costs a multiply per entry.

use crate::camera::{check_lengths, mat2x2_mul_2xn};
use crate::model::normalized_interaction_parts;
use crate::{Camera, UcmError};

/// The two blocks of a pixel's interaction matrix (rows `u` then `v`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct PixelJacobian {
    /// Translational block multiplied by the range: `ρ ∂u/∂υ` (pixels·m per m/s).
    pub translation: [[f32; 3]; 2],
    /// Rotational block `∂u/∂ω` (pixels per rad/s).
    pub rotation: [[f32; 3]; 2],
}

impl PixelJacobian {
    /// The 2×6 interaction matrix at inverse range `1/ρ` (0 for a point at infinity).
    #[inline(always)]
    pub fn interaction(&self, inverse_range: f32) -> [[f32; 6]; 2] {
        let t = &self.translation;
        let r = &self.rotation;
        [
            [
                t[0][0] * inverse_range,
                t[0][1] * inverse_range,
                t[0][2] * inverse_range,
                r[0][0],
                r[0][1],
                r[0][2],
            ],
            [
                t[1][0] * inverse_range,
                t[1][1] * inverse_range,
                t[1][2] * inverse_range,
                r[1][0],
                r[1][1],
                r[1][2],
            ],
        ]
    }

    /// The photometric interaction row `−∇Iᵀ ∂u/∂v` of a pixel with image gradient
    /// `(∂I/∂u, ∂I/∂v)` at inverse range `1/ρ` (brightness constancy).
    #[inline(always)]
    pub fn photometric(&self, gradient: [f32; 2], inverse_range: f32) -> [f32; 6] {
        let [gu, gv] = gradient;
        let t = &self.translation;
        let r = &self.rotation;
        let s = -inverse_range;
        [
            s * (gu * t[0][0] + gv * t[1][0]),
            s * (gu * t[0][1] + gv * t[1][1]),
            s * (gu * t[0][2] + gv * t[1][2]),
            -(gu * r[0][0] + gv * r[1][0]),
            -(gu * r[0][1] + gv * r[1][1]),
            -(gu * r[0][2] + gv * r[1][2]),
        ]
    }
}

/// Every pixel's [`PixelJacobian`] for a camera, row-major.
#[derive(Clone, Debug)]
pub struct PixelGrid {
    width: u32,
    height: u32,
    factors: Vec<PixelJacobian>,
    valid: Vec<bool>,
}

impl PixelGrid {
    /// Precompute the grid of a camera. Pixels of the camera's valid region where the
    /// model cannot be inverted (undistortion fails, outside the ξ > 1 domain) are
    /// marked invalid here.
    pub fn new(camera: &Camera) -> Self {
        let (width, height) = (camera.width(), camera.height());
        let xi = camera.intrinsics().xi;
        let n = camera.pixel_count();
        let mut factors = vec![PixelJacobian::default(); n];
        let mut valid = camera.valid_pixels().to_vec();
        for j in 0..height {
            for i in 0..width {
                let index = (j * width + i) as usize;
                if !valid[index] {
                    continue;
                }
                let pixel = [f64::from(i), f64::from(j)];
                let Ok([x, y]) = camera.normalized_from_pixel(pixel) else {
                    valid[index] = false;
                    continue;
                };
                let Some((t, r)) = normalized_interaction_parts(xi, x, y) else {
                    valid[index] = false;
                    continue;
                };
                let k = camera.params_f64.pixel_jacobian(x, y);
                let t = mat2x2_mul_2xn(k, t);
                let r = mat2x2_mul_2xn(k, r);
                let to32 = |m: [[f64; 3]; 2]| m.map(|row| row.map(|v| v as f32));
                factors[index] = PixelJacobian {
                    translation: to32(t),
                    rotation: to32(r),
                };
            }
        }
        Self {
            width,
            height,
            factors,
            valid,
        }
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major factors (meaningless where [`PixelGrid::valid`] is false).
    pub fn factors(&self) -> &[PixelJacobian] {
        &self.factors
    }

    /// Row-major validity: the camera's region minus pixels the model cannot invert.
    pub fn valid(&self) -> &[bool] {
        &self.valid
    }

    /// The interaction matrices of the whole image, given every pixel's inverse range
    /// (`1/ρ`, row-major). Invalid pixels get zeros. Slices must have the image's size.
    pub fn interaction_image(
        &self,
        inverse_range: &[f32],
        out: &mut [[[f32; 6]; 2]],
    ) -> Result<(), UcmError> {
        check_lengths(self.factors.len(), inverse_range.len())?;
        check_lengths(self.factors.len(), out.len())?;
        for (((o, f), &inv), &ok) in out
            .iter_mut()
            .zip(&self.factors)
            .zip(inverse_range)
            .zip(&self.valid)
        {
            *o = if ok {
                f.interaction(inv)
            } else {
                [[0.0; 6]; 2]
            };
        }
        Ok(())
    }
}
