//! Parameters of the unified central model and of Mei's lens distortion.

use serde::{Deserialize, Serialize};

use crate::{Real, UcmError};

/// Generalised focal lengths, principal point, skew and mirror parameter of the UCM.
///
/// A point `(X, Y, Z)` in the camera frame, `ρ = ‖X‖`, projects to the normalised plane
/// at `x = X/(Z + ξρ)`, `y = Y/(Z + ξρ)`, then (after optional distortion) to the pixel
/// `u = αu·x + s·y + u0`, `v = αv·y + v0`. Pixel `(i, j)` is the unit square centred on
/// `u = i, v = j`: the centre of a `W×H` image is `((W−1)/2, (H−1)/2)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// `αu`, horizontal generalised focal length, pixels (> 0).
    pub alpha_u: f64,
    /// `αv`, vertical generalised focal length, pixels (> 0).
    pub alpha_v: f64,
    /// `u0`, column of the principal point, pixels.
    pub u0: f64,
    /// `v0`, row of the principal point, pixels.
    pub v0: f64,
    /// `ξ`, mirror parameter (0: pinhole, 1: parabolic mirror; > 1 occurs for some
    /// real calibrations).
    pub xi: f64,
    /// `s`, skew in pixels (0 for the paper's model; real calibrations may have it).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub skew: f64,
}

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// Mei's radial–tangential distortion of the normalised plane:
/// `x_d = x(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²)`,
/// `y_d = y(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y`.
/// Mei's model has no `k3` (0, left out of files when 0); the plumb-bob model of
/// OpenCV's and ROS's pinhole calibrations (TUM RGB-D's Kinects) has it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Distortion {
    /// First radial coefficient.
    pub k1: f64,
    /// Second radial coefficient.
    pub k2: f64,
    /// First tangential coefficient.
    pub p1: f64,
    /// Second tangential coefficient.
    pub p2: f64,
    /// Third radial coefficient (0 in Mei's model).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k3: f64,
}

impl Intrinsics {
    /// Check every invariant: finite values, `αu, αv > 0`, `ξ ≥ 0`.
    pub fn validate(&self) -> Result<(), UcmError> {
        for (name, value) in [
            ("alpha_u", self.alpha_u),
            ("alpha_v", self.alpha_v),
            ("u0", self.u0),
            ("v0", self.v0),
            ("xi", self.xi),
            ("skew", self.skew),
        ] {
            if !value.is_finite() {
                return Err(UcmError::NonFinite { name, value });
            }
        }
        for (name, value) in [("alpha_u", self.alpha_u), ("alpha_v", self.alpha_v)] {
            if value <= 0.0 {
                return Err(UcmError::NonPositiveFocal { name, value });
            }
        }
        if self.xi < 0.0 {
            return Err(UcmError::NegativeXi(self.xi));
        }
        Ok(())
    }
}

impl Distortion {
    /// Check that every coefficient is finite.
    pub fn validate(&self) -> Result<(), UcmError> {
        for (name, value) in [
            ("k1", self.k1),
            ("k2", self.k2),
            ("p1", self.p1),
            ("p2", self.p2),
            ("k3", self.k3),
        ] {
            if !value.is_finite() {
                return Err(UcmError::NonFinite { name, value });
            }
        }
        Ok(())
    }

    /// Whether every coefficient is zero.
    pub fn is_identity(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.k3 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0
    }
}

/// All parameters of a camera converted once to `T`, so that hot loops in `f32` do not
/// convert. Opaque: read the parameters from [`Intrinsics`] and [`Distortion`].
#[derive(Clone, Copy, Debug)]
pub struct Params<T> {
    pub(crate) alpha_u: T,
    pub(crate) alpha_v: T,
    pub(crate) u0: T,
    pub(crate) v0: T,
    pub(crate) xi: T,
    pub(crate) skew: T,
    pub(crate) k1: T,
    pub(crate) k2: T,
    pub(crate) k3: T,
    pub(crate) p1: T,
    pub(crate) p2: T,
    pub(crate) distorted: bool,
    /// `r²` of the first fold of the radial polynomial (`d(r·radial)/dr = 0`), or +∞.
    pub(crate) fold_r2: T,
}

/// Smallest `s = r² > 0` where `d(r (1 + k1 r² + k2 r⁴ + k3 r⁶))/dr
/// = 1 + 3 k1 s + 5 k2 s² + 7 k3 s³` vanishes: beyond it the radial distortion is not
/// one-to-one. The roots of the quadratic when `k3 = 0`; otherwise the first sign change
/// on a geometric grid of `s` (1e-6 to 1e6, 64 points an octave), bisected.
fn first_fold_r2(k1: f64, k2: f64, k3: f64) -> f64 {
    if k3 != 0.0 {
        let slope = |s: f64| 1.0 + s * (3.0 * k1 + s * (5.0 * k2 + s * 7.0 * k3));
        let step = 2f64.powf(1.0 / 64.0);
        let (mut lo, mut hi) = (0.0, 1e-6);
        while hi < 1e6 {
            if slope(hi) <= 0.0 {
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if slope(mid) > 0.0 { lo = mid } else { hi = mid }
                }
                return lo;
            }
            lo = hi;
            hi *= step;
        }
        return f64::INFINITY;
    }
    let (a, b, c) = (5.0 * k2, 3.0 * k1, 1.0);
    let roots: [f64; 2] = if a == 0.0 {
        [if b < 0.0 { -c / b } else { f64::INFINITY }, f64::INFINITY]
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            [f64::INFINITY; 2]
        } else {
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            [q / a, if q != 0.0 { c / q } else { f64::INFINITY }]
        }
    };
    roots
        .into_iter()
        .filter(|&s| s > 0.0)
        .fold(f64::INFINITY, f64::min)
}

impl<T: Real> Params<T> {
    pub(crate) fn new(intrinsics: &Intrinsics, distortion: Option<&Distortion>) -> Self {
        let d = distortion.copied().unwrap_or_default();
        Self {
            alpha_u: T::from_f64(intrinsics.alpha_u),
            alpha_v: T::from_f64(intrinsics.alpha_v),
            u0: T::from_f64(intrinsics.u0),
            v0: T::from_f64(intrinsics.v0),
            xi: T::from_f64(intrinsics.xi),
            skew: T::from_f64(intrinsics.skew),
            k1: T::from_f64(d.k1),
            k2: T::from_f64(d.k2),
            k3: T::from_f64(d.k3),
            p1: T::from_f64(d.p1),
            p2: T::from_f64(d.p2),
            distorted: !d.is_identity(),
            fold_r2: T::from_f64(first_fold_r2(d.k1, d.k2, d.k3)),
        }
    }

    /// Whether an undistorted normalised point lies where the distortion is
    /// one-to-one: inside the first fold of its radial polynomial, with a positive
    /// Jacobian determinant (the tangential terms shift the fold slightly). Always true
    /// without distortion.
    #[inline(always)]
    pub(crate) fn before_fold(&self, x: T, y: T) -> bool {
        if !self.distorted {
            return true;
        }
        if !(x * x + y * y < self.fold_r2) {
            return false;
        }
        let [[a, b], [c, d]] = self.distortion_jacobian(x, y);
        a * d - b * c > T::ZERO
    }

    /// Distorted normalised coordinates.
    #[inline(always)]
    pub(crate) fn distort(&self, x: T, y: T) -> [T; 2] {
        if !self.distorted {
            return [x, y];
        }
        let r2 = x * x + y * y;
        let radial = T::ONE + r2 * (self.k1 + r2 * (self.k2 + self.k3 * r2));
        let two = T::TWO;
        [
            x * radial + two * self.p1 * x * y + self.p2 * (r2 + two * x * x),
            y * radial + self.p1 * (r2 + two * y * y) + two * self.p2 * x * y,
        ]
    }

    /// `∂(x_d, y_d)/∂(x, y)`, row-major.
    #[inline(always)]
    pub(crate) fn distortion_jacobian(&self, x: T, y: T) -> [[T; 2]; 2] {
        if !self.distorted {
            return [[T::ONE, T::ZERO], [T::ZERO, T::ONE]];
        }
        let two = T::TWO;
        let six = T::from_f64(6.0);
        let r2 = x * x + y * y;
        let radial = T::ONE + r2 * (self.k1 + r2 * (self.k2 + self.k3 * r2));
        // ∂radial/∂x = dradial·x
        let dradial = two * self.k1 + r2 * (T::from_f64(4.0) * self.k2 + six * self.k3 * r2);
        let cross = dradial * x * y + two * self.p1 * x + two * self.p2 * y;
        [
            [
                radial + dradial * x * x + two * self.p1 * y + six * self.p2 * x,
                cross,
            ],
            [
                cross,
                radial + dradial * y * y + six * self.p1 * y + two * self.p2 * x,
            ],
        ]
    }

    /// Inverse of [`Params::distort`] by Newton's method; `None` if it does not converge
    /// (far outside the calibrated field, where the polynomial folds).
    pub(crate) fn undistort(&self, xd: T, yd: T) -> Option<[T; 2]> {
        if !self.distorted {
            return Some([xd, yd]);
        }
        let tolerance = T::from_f64(64.0) * T::EPSILON * (T::ONE + xd.abs() + yd.abs());
        // Newton's method inside the region before the fold, where the distortion is
        // one to one: start from the distorted point, pulled towards the centre until it
        // lies there (a distortion that expands near its fold puts the distorted point
        // beyond it), and halve every step that would leave the region.
        let half = T::from_f64(0.5);
        let (mut x, mut y) = (xd, yd);
        let mut pulls = 0;
        while !self.before_fold(x, y) {
            if pulls == 80 {
                return None;
            }
            (x, y) = (x * half, y * half);
            pulls += 1;
        }
        // Each step is halved until it stays in that region and lowers the residual:
        // full Newton steps can cycle where the distortion bends strongly (a radial
        // polynomial near its inflection), and a decreasing residual cannot.
        let residual = |[fx, fy]: [T; 2]| {
            let (ex, ey) = (fx - xd, fy - yd);
            ex * ex + ey * ey
        };
        let mut f = self.distort(x, y);
        'newton: for _ in 0..60 {
            let (ex, ey) = (f[0] - xd, f[1] - yd);
            if ex.abs() <= tolerance && ey.abs() <= tolerance {
                return Some([x, y]);
            }
            let [[a, b], [c, d]] = self.distortion_jacobian(x, y);
            let det = a * d - b * c;
            if !(det > T::ZERO) || !det.is_finite() {
                return None;
            }
            let (dx, dy) = ((d * ex - b * ey) / det, (a * ey - c * ex) / det);
            let now = residual(f);
            let mut step = T::ONE;
            let mut halvings = 0;
            loop {
                let (cx, cy) = (x - step * dx, y - step * dy);
                if self.before_fold(cx, cy) {
                    let fc = self.distort(cx, cy);
                    if residual(fc) < now {
                        (x, y, f) = (cx, cy, fc);
                        break;
                    }
                }
                if halvings == 60 {
                    // No step lowers the residual: at its rounding floor (judged below).
                    break 'newton;
                }
                step *= half;
                halvings += 1;
            }
        }
        // `f` is the distortion of the last point.
        let [fx, fy] = f;
        let loose = T::from_f64(1e3) * tolerance;
        ((fx - xd).abs() <= loose && (fy - yd).abs() <= loose && self.before_fold(x, y))
            .then_some([x, y])
    }

    /// Pixel of a distorted normalised point.
    #[inline(always)]
    pub(crate) fn pixel_of(&self, xd: T, yd: T) -> [T; 2] {
        [
            self.alpha_u * xd + self.skew * yd + self.u0,
            self.alpha_v * yd + self.v0,
        ]
    }

    /// Distorted normalised point of a pixel.
    #[inline(always)]
    pub(crate) fn distorted_of_pixel(&self, u: T, v: T) -> [T; 2] {
        let yd = (v - self.v0) / self.alpha_v;
        [(u - self.u0 - self.skew * yd) / self.alpha_u, yd]
    }

    /// `∂(u, v)/∂(x, y)` of the undistorted normalised point: `K₂ · J_d`.
    #[inline(always)]
    pub(crate) fn pixel_jacobian(&self, x: T, y: T) -> [[T; 2]; 2] {
        let [[a, b], [c, d]] = self.distortion_jacobian(x, y);
        [
            [
                self.alpha_u * a + self.skew * c,
                self.alpha_u * b + self.skew * d,
            ],
            [self.alpha_v * c, self.alpha_v * d],
        ]
    }
}
