//! Every analytic Jacobian against central finite differences (f64, relative error
//! < 1e-6), over random points, intrinsics (ξ in [0, 1.5]) and velocities.

use crate::common::*;
use glam::DVec3;
use proptest::prelude::*;
use ucm::{Camera, Intrinsics, Isometry3, PixelGrid, ValidRegion, model};

const H: f64 = 1e-6;

fn rescale_into_domain(p: [f64; 3], xi: f64) -> [f64; 3] {
    let rho = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let theta = (p[2] / rho).acos() * max_off_axis(xi) / 1.4;
    let phi = p[1].atan2(p[0]);
    [
        rho * theta.sin() * phi.cos(),
        rho * theta.sin() * phi.sin(),
        rho * theta.cos(),
    ]
}

/// The pixel motion `∂u/∂v · v` by finite differences of the projection of a fixed
/// world point seen from a camera moved by exp(±h v).
fn pixel_motion_fd(camera: &Camera, p: [f64; 3], v: [f64; 6]) -> [f64; 2] {
    let x = DVec3::from_array(p);
    let at = |s: f64| {
        let moved = Isometry3::exp(v.map(|c| c * s))
            .unwrap()
            .inverse()
            .transform_point(x);
        camera.project_unbounded(moved.to_array()).unwrap()
    };
    let (a, b) = (at(H), at(-H));
    [(a[0] - b[0]) / (2.0 * H), (a[1] - b[1]) / (2.0 * H)]
}

fn apply(l: [[f64; 6]; 2], v: [f64; 6]) -> [f64; 2] {
    [0, 1].map(|r| (0..6).map(|c| l[r][c] * v[c]).sum())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn projection_jacobian_matches_finite_differences(
        camera in prop_oneof![camera_strategy(false), camera_strategy(true)],
        p in point_strategy(1.4),
    ) {
        let p = rescale_into_domain(p, camera.intrinsics().xi);
        // Beyond the fold of a random distortion polynomial there is no projection.
        prop_assume!(camera.project_unbounded(p).is_ok());
        let j = camera.projection_jacobian(p).unwrap();
        for axis in 0..3 {
            let mut a = p;
            let mut b = p;
            a[axis] += H;
            b[axis] -= H;
            let (pa, pb) = (camera.project_unbounded(a).unwrap(), camera.project_unbounded(b).unwrap());
            let numeric = [(pa[0] - pb[0]) / (2.0 * H), (pa[1] - pb[1]) / (2.0 * H)];
            let analytic = [j[0][axis], j[1][axis]];
            let scale = j.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
            let err = ((numeric[0] - analytic[0]).powi(2) + (numeric[1] - analytic[1]).powi(2)).sqrt() / scale;
            prop_assert!(err < 1e-6, "axis {axis}: {numeric:?} vs {analytic:?} (rel {err:e})");
        }
    }

    /// The interaction matrix, from the point and from the pixel and its range (the
    /// notes' closed form), both against the finite difference of the motion.
    #[test]
    fn interaction_matrices_match_finite_differences(
        camera in prop_oneof![camera_strategy(false), camera_strategy(true)],
        p in point_strategy(1.4),
        v in twist_strategy(),
    ) {
        let p = rescale_into_domain(p, camera.intrinsics().xi);
        prop_assume!(camera.project_unbounded(p).is_ok());
        let numeric = pixel_motion_fd(&camera, p, v);
        let from_point = apply(camera.interaction_matrix(p).unwrap(), v);
        let err = rel_err(&from_point, &numeric);
        prop_assert!(err < 1e-6, "from point: {from_point:?} vs {numeric:?} ({err:e})");

        let pixel = camera.project_unbounded(p).unwrap();
        let range = DVec3::from_array(p).length();
        let from_pixel = apply(camera.pixel_interaction_matrix(pixel, range).unwrap(), v);
        let err = rel_err(&from_pixel, &numeric);
        prop_assert!(err < 1e-6, "from pixel: {from_pixel:?} vs {numeric:?} ({err:e})");
    }

    /// The normalised-plane interaction matrix of the notes, alone, against the finite
    /// difference of the normalised projection (no pixels, no distortion).
    #[test]
    fn normalized_interaction_matches_finite_differences(
        xi in 0.0..1.5f64,
        p in point_strategy(1.4),
        v in twist_strategy(),
    ) {
        let p = rescale_into_domain(p, xi);
        let x = DVec3::from_array(p);
        let at = |s: f64| {
            let moved = Isometry3::exp(v.map(|c| c * s)).unwrap().inverse().transform_point(x);
            model::project_normalized(xi, moved.to_array()).unwrap()
        };
        let (a, b) = (at(H), at(-H));
        let numeric = [(a[0] - b[0]) / (2.0 * H), (a[1] - b[1]) / (2.0 * H)];
        let [nx, ny] = model::project_normalized(xi, p).unwrap();
        let l = model::normalized_interaction(xi, nx, ny, x.length()).unwrap();
        let err = rel_err(&apply(l, v), &numeric);
        prop_assert!(err < 1e-6, "{err:e}");
    }

    /// The f32 pixel grid holds the same matrices as the f64 closed form.
    #[test]
    fn pixel_grid_matches_closed_form(xi in 0.0..1.2f64, inv_range in 0.01..2.0f32, k in 0usize..(80 * 60)) {
        let camera = Camera::new(
            Intrinsics { alpha_u: 30.0, alpha_v: 31.0, u0: 39.5, v0: 29.5, xi, skew: 0.2 },
            Some(ucm::Distortion { k1: -0.02, k2: 0.01, p1: 0.001, p2: -0.002, k3: 0.005 }),
            80, 60, ValidRegion::Full,
        ).unwrap();
        let grid = PixelGrid::new(&camera);
        prop_assume!(grid.valid()[k]);
        let pixel = [(k % 80) as f64, (k / 80) as f64];
        let exact = camera.pixel_interaction_matrix(pixel, 1.0 / f64::from(inv_range)).unwrap();
        let fast = grid.factors()[k].interaction(inv_range);
        for r in 0..2 {
            for c in 0..6 {
                prop_assert!((f64::from(fast[r][c]) - exact[r][c]).abs() <= 1e-5 * (1.0 + exact[r][c].abs()));
            }
        }
    }
}

/// ξ = 0: the classic pinhole interaction matrix `[−1/Z, 0, x/Z, xy, −(1+x²), y]`.
#[test]
fn xi_zero_gives_the_classic_interaction_matrix() {
    for p in [
        [0.3, -0.2, 2.0],
        [-1.0, 0.5, 4.0],
        [0.0, 0.0, 1.0],
        [2.0, 1.0, 1.5],
    ] {
        let (x, y, z) = (p[0] / p[2], p[1] / p[2], p[2]);
        let classic = [
            [-1.0 / z, 0.0, x / z, x * y, -(1.0 + x * x), y],
            [0.0, -1.0 / z, y / z, 1.0 + y * y, -x * y, -x],
        ];
        let rho: f64 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
        let l = model::normalized_interaction(0.0, x, y, rho.sqrt()).unwrap();
        // The notes' form has 1/ρ with γ = 1: (1 + x² + y²)/ρ = 1/Z · ρ/Z … equal to 1/Z·(1+…)
        // only through ρ = Z √(1 + x² + y²); compare numerically.
        for r in 0..2 {
            for c in 0..6 {
                assert!(
                    (l[r][c] - classic[r][c]).abs() < 1e-12,
                    "{p:?} [{r}][{c}]: {} vs {}",
                    l[r][c],
                    classic[r][c]
                );
            }
        }
    }
}

#[test]
fn photometric_row_is_minus_gradient_times_interaction() {
    let camera = fixture_320();
    let grid = PixelGrid::new(&camera);
    let k = grid.valid().iter().position(|&v| v).unwrap();
    let f = grid.factors()[k];
    let l = f.interaction(0.25);
    let g = [0.7f32, -1.3];
    let row = f.photometric(g, 0.25);
    for c in 0..6 {
        let expected = -(g[0] * l[0][c] + g[1] * l[1][c]);
        assert!((row[c] - expected).abs() < 1e-6);
    }
}
