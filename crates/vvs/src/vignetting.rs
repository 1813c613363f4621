//! Beyond the paper: a radial vignetting model estimated with the pose
//! ([`crate::VvsConfig::vignetting`]).
//!
//! A real catadioptric camera darkens towards the rim of its mirror; the rendering of a
//! cloud does not. Global centring and normalisation (§4) remove a gain and an offset,
//! not a radial ramp, and the wide PGM of step 1 matches the ramp rather than the
//! scene (`docs/RESULTS.md`, tracking). With this model the *rendered* picture is
//! multiplied by
//!
//! `V_c(u) = 1 + c₁ ρ(u)² + c₂ ρ(u)⁴`,
//!
//! `ρ` the distance of pixel `u` from the valid region's centre over its outer radius
//! (the image's half-diagonal without an annulus), and `c = (c₁, c₂)` are two more
//! unknowns of the same least squares as the pose (and λ). The feature is linear in
//! the picture, so the columns of `c` are the feature of `ρ^{2k} I` (centred and scaled
//! like the picture when the brightness is normalised, the dependence of the mean and
//! the norm on `c` neglected as for the pose); they are checked against finite
//! differences in `tests/vignetting.rs`.

use frame::{Frame, Image, PixelStatus};
use ucm::{Camera, ValidRegion};

/// Largest `|c_k|` the estimate may reach (`V_c` stays positive over the region while
/// `|c₁| + |c₂| < 1`; the bound only stops a runaway).
pub const MAX_COEFFICIENT: f64 = 0.9;

/// The radial basis of one camera: `ρ²` of every pixel.
#[derive(Clone, Debug)]
pub struct RadialVignetting {
    width: u32,
    height: u32,
    rho2: Vec<f32>,
}

impl RadialVignetting {
    /// The basis of `camera`.
    pub fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let (centre, radius) = match camera.region() {
            ValidRegion::Annulus(a) => (a.center_px, a.outer_radius_px.max(1.0)),
            _ => {
                let c = [(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0];
                (c, (c[0] * c[0] + c[1] * c[1]).sqrt().max(1.0))
            }
        };
        let rho2 = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                (((x - centre[0]).powi(2) + (y - centre[1]).powi(2)) / (radius * radius)) as f32
            })
            .collect();
        Self {
            width: camera.width(),
            height: camera.height(),
            rho2,
        }
    }

    /// `V_c` at pixel `k`.
    #[inline]
    fn factor(&self, c: [f64; 2], k: usize) -> f32 {
        let r2 = f64::from(self.rho2[k]);
        (1.0 + c[0] * r2 + c[1] * r2 * r2) as f32
    }

    /// `out` = `frame` with its observed intensities multiplied by `V_c` (ranges and
    /// statuses copied). Both must have the camera's size.
    pub fn apply(&self, c: [f64; 2], frame: &Frame, out: &mut Frame) {
        debug_assert!(frame.width() == self.width && frame.height() == self.height);
        out.clone_from(frame);
        for (k, (v, s)) in out.intensity.iter_mut().zip(&frame.status).enumerate() {
            if *s != PixelStatus::Masked {
                *v *= self.factor(c, k);
            }
        }
    }

    /// The derivative with respect to `c_k` (`k` = 0 or 1) of the picture the feature
    /// transforms, for the rendering `frame` (uncorrected): `ρ^{2(k+1)} I` on the
    /// pixels the feature `observed` (the others invalid), written into `out`. When the
    /// brightness is normalised, `normalization` gives the scale `1/‖I' − mean‖` of the
    /// corrected picture `I'` and the normalised picture `n` itself (row-major, as
    /// `brightness::Brightness::image`): the derivative of `n` is then exact,
    /// `s (d − mean d) − n ⟨n, s (d − mean d)⟩` over the observed `samples` (a radial
    /// ramp is nearly collinear with the picture, so the norm's dependence cannot be
    /// neglected here).
    pub fn derivative(
        &self,
        k: usize,
        frame: &Frame,
        samples: &[u32],
        observed: &[bool],
        normalization: Option<(f32, &[f32])>,
        out: &mut Image,
    ) {
        debug_assert!(out.width() == self.width && out.height() == self.height);
        for (i, (o, v)) in out.intensity.iter_mut().zip(&mut out.valid).enumerate() {
            let observed = observed[i];
            *v = observed;
            *o = if observed {
                let r2 = self.rho2[i];
                frame.intensity[i] * if k == 0 { r2 } else { r2 * r2 }
            } else {
                0.0
            };
        }
        if let Some((scale, normalized)) = normalization {
            let seen = || samples.iter().filter(|&&s| observed[s as usize]);
            let m = seen().count().max(1) as f64;
            let mean = seen()
                .map(|&s| f64::from(out.intensity[s as usize]))
                .sum::<f64>()
                / m;
            let scale = f64::from(scale);
            let along: f64 = seen()
                .map(|&s| {
                    let s = s as usize;
                    f64::from(normalized[s]) * (f64::from(out.intensity[s]) - mean) * scale
                })
                .sum();
            for &s in seen() {
                let s = s as usize;
                let centred = (f64::from(out.intensity[s]) - mean) * scale;
                out.intensity[s] = (centred - f64::from(normalized[s]) * along) as f32;
            }
        }
    }
}
