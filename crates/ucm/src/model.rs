//! The unified central model on the normalised plane: projection, lifting to the unit
//! sphere, Jacobians and the interaction matrix. Pure functions of `ξ`, generic over
//! `f32`/`f64`; [`crate::Camera`] adds the pixel mapping, the distortion and the
//! valid region.

use crate::Real;

/// Why a point or pixel has no image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OutOfView {
    /// `Z + ξρ ≤ 0` (behind the pinhole for ξ = 0), or the point is the viewpoint itself,
    /// or a coordinate is not finite.
    BehindViewpoint,
    /// `ξ > 1` and the point lies beyond the part of the sphere where the projection is
    /// one-to-one (`ξ Z/ρ ≤ −1`), or a pixel's lifting has no real solution.
    OutsideXiDomain,
    /// The projection falls outside the image.
    OutsideImage,
    /// The projection falls in the image but outside the valid region (mask).
    OutsideRegion,
    /// Beyond the radius where Mei's distortion polynomial stops being one-to-one
    /// (it is then extrapolated far outside the calibrated field), or its inversion did
    /// not converge.
    DistortionFold,
}

/// Projection onto the normalised plane: `(X/(Z + ξρ), Y/(Z + ξρ))`, with the model's
/// domain checks.
#[inline(always)]
pub fn project_normalized<T: Real>(xi: T, point_in_camera: [T; 3]) -> Result<[T; 2], OutOfView> {
    let [x, y, z] = point_in_camera;
    let rho = (x * x + y * y + z * z).sqrt();
    if !(rho > T::ZERO) || !rho.is_finite() {
        return Err(OutOfView::BehindViewpoint);
    }
    let d = z + xi * rho;
    if !(d > T::ZERO) {
        return Err(OutOfView::BehindViewpoint);
    }
    if xi > T::ONE && !(xi * z + rho > T::ZERO) {
        return Err(OutOfView::OutsideXiDomain);
    }
    Ok([x / d, y / d])
}

/// `γ = √(1 + (1 − ξ²)(x² + y²))`, or `None` outside the ξ > 1 domain.
#[inline(always)]
pub fn gamma<T: Real>(xi: T, x: T, y: T) -> Option<T> {
    let g2 = T::ONE + (T::ONE - xi * xi) * (x * x + y * y);
    (g2 >= T::ZERO).then(|| g2.sqrt())
}

/// Lifting of a normalised point onto the unit sphere:
/// `η = (ξ + γ)/(1 + r²)`, `Xs = (ηx, ηy, η − ξ)`.
#[inline(always)]
pub fn lift_to_sphere<T: Real>(xi: T, x: T, y: T) -> Result<[T; 3], OutOfView> {
    let g = gamma(xi, x, y).ok_or(OutOfView::OutsideXiDomain)?;
    let eta = (xi + g) / (T::ONE + x * x + y * y);
    Ok([eta * x, eta * y, eta - xi])
}

/// `∂(x, y)/∂X`, the 2×3 Jacobian of the normalised projection with respect to the
/// point (row-major). The point must be in the model's domain.
#[inline(always)]
pub fn normalized_jacobian<T: Real>(xi: T, point_in_camera: [T; 3]) -> [[T; 3]; 2] {
    let [px, py, pz] = point_in_camera;
    let rho = (px * px + py * py + pz * pz).sqrt();
    let inv_d = T::ONE / (pz + xi * rho);
    let x = px * inv_d;
    let y = py * inv_d;
    // ∂D/∂X = (ξX/ρ, ξY/ρ, 1 + ξZ/ρ)
    let k = xi / rho;
    let dd = [k * px, k * py, T::ONE + k * pz];
    [
        [
            inv_d * (T::ONE - x * dd[0]),
            -inv_d * x * dd[1],
            -inv_d * x * dd[2],
        ],
        [
            -inv_d * y * dd[0],
            inv_d * (T::ONE - y * dd[1]),
            -inv_d * y * dd[2],
        ],
    ]
}

/// A 2×3 block of an interaction matrix (rows `x`/`u` then `y`/`v`).
pub type Block<T> = [[T; 3]; 2];

/// Interaction matrix of a normalised image point, split as
/// `L = [T/ρ | R]`: returns `(T, R)`, the translational block multiplied by the range
/// `ρ` and the rotational block (both 2×3, rows `x` then `y`). This is the formula of
/// `../shared/notes/math.md` (the paper's printed eq. 6 is wrong):
///
/// ```text
/// Lx = [ −(1 + x²(1 − ξ(γ+ξ)) + y²) / (ρ(γ+ξ)),  ξxy/ρ,  γx/ρ,  xy,  −((1+x²)γ − ξy²)/(γ+ξ),  y ]
/// Ly = [ ξxy/ρ,  −(1 + y²(1 − ξ(γ+ξ)) + x²) / (ρ(γ+ξ)),  γy/ρ,  ((1+y²)γ − ξx²)/(γ+ξ),  −xy,  −x ]
/// ```
///
/// `None` outside the ξ > 1 domain.
#[inline(always)]
pub fn normalized_interaction_parts<T: Real>(xi: T, x: T, y: T) -> Option<(Block<T>, Block<T>)> {
    let g = gamma(xi, x, y)?;
    let gx = g + xi;
    let inv_gx = T::ONE / gx;
    let xx = x * x;
    let yy = y * y;
    let xy = x * y;
    let one = T::ONE;
    let t = [
        [-(one + xx * (one - xi * gx) + yy) * inv_gx, xi * xy, g * x],
        [xi * xy, -(one + yy * (one - xi * gx) + xx) * inv_gx, g * y],
    ];
    let r = [
        [xy, -((one + xx) * g - xi * yy) * inv_gx, y],
        [((one + yy) * g - xi * xx) * inv_gx, -xy, -x],
    ];
    Some((t, r))
}

/// The full 2×6 interaction matrix of a normalised point at range `ρ`:
/// `∂(x, y)/∂v` for a camera twist `v = (υ, ω)`.
#[inline]
pub fn normalized_interaction<T: Real>(xi: T, x: T, y: T, range: T) -> Option<[[T; 6]; 2]> {
    let (t, r) = normalized_interaction_parts(xi, x, y)?;
    let inv = T::ONE / range;
    Some([
        [
            t[0][0] * inv,
            t[0][1] * inv,
            t[0][2] * inv,
            r[0][0],
            r[0][1],
            r[0][2],
        ],
        [
            t[1][0] * inv,
            t[1][1] * inv,
            t[1][2] * inv,
            r[1][0],
            r[1][1],
            r[1][2],
        ],
    ])
}

/// Chain a 2×3 Jacobian with respect to a point with the motion of that point under a
/// camera twist, `Ẋ = −υ − ω × X = [−I | [X]×] v`: returns the 2×6 interaction matrix.
#[inline(always)]
pub fn interaction_from_point_jacobian<T: Real>(
    jacobian: [[T; 3]; 2],
    point_in_camera: [T; 3],
) -> [[T; 6]; 2] {
    let [x, y, z] = point_in_camera;
    let mut out = [[T::ZERO; 6]; 2];
    for (row, j) in out.iter_mut().zip(jacobian) {
        row[0] = -j[0];
        row[1] = -j[1];
        row[2] = -j[2];
        // j · [X]×, [X]× = [[0, −z, y], [z, 0, −x], [−y, x, 0]]
        row[3] = j[1] * z - j[2] * y;
        row[4] = j[2] * x - j[0] * z;
        row[5] = j[0] * y - j[1] * x;
    }
    out
}
