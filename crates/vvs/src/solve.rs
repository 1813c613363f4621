//! The Gauss–Newton step of the control law from the normal equations, with faer.

use faer::{Mat, Side};

/// `x = (JᵀJ)⁺ Jᵀe`, the least-squares solution `J⁺ e` (minimum norm where `J` is rank
/// deficient), with optional Levenberg–Marquardt damping `η` (`JᵀJ + η diag(JᵀJ)`).
/// The pseudo-inverse drops eigenvalues below `1e-12` × the largest (`J⁺`'s singular
/// values below `1e-6` × the largest). Returns `None` when the system is not finite or
/// has no usable direction.
pub fn solve<const N: usize>(
    jtj: &[[f64; N]; N],
    jte: &[f64; N],
    damping: Option<f64>,
) -> Option<[f64; N]> {
    if jtj
        .iter()
        .flatten()
        .chain(jte.iter())
        .any(|v| !v.is_finite())
    {
        return None;
    }
    let eta = damping.unwrap_or(0.0);
    let a = Mat::<f64>::from_fn(N, N, |i, j| {
        if i == j {
            jtj[i][j] * (1.0 + eta)
        } else {
            jtj[i][j]
        }
    });
    let eigen = a.self_adjoint_eigen(Side::Lower).ok()?;
    let u = eigen.U();
    let s = eigen.S().column_vector();
    let largest = (0..N).map(|i| s[i].abs()).fold(0.0, f64::max);
    if !(largest > 0.0) {
        return None;
    }
    let mut x = [0.0; N];
    for k in 0..N {
        if s[k] <= 1e-12 * largest {
            continue;
        }
        // x += u_k (u_kᵀ Jᵀe) / s_k
        let proj: f64 = (0..N).map(|i| u[(i, k)] * jte[i]).sum::<f64>() / s[k];
        for i in 0..N {
            x[i] += u[(i, k)] * proj;
        }
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}
