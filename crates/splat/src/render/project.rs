//! The projection of a point into its [`Splat`]: the scalar reference
//! ([`project_point`], also the path of cameras with lens distortion) and the block
//! kernel of the baseline instruction set ([`project_block`]), which gives the same
//! bits several points at a time.

use glam::Vec3;
use ucm::Camera;

use crate::PackedPoint;

#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
use super::splat::NOT_DRAWN;
use super::splat::{Splat, band_limit};
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::sse2;
use super::view::View;

/// `floor(x)` for `|x| < 2²²`, exactly, with float and integer operations that
/// vectorise (no libm call: `floor` is not an instruction on baseline x86-64, and a
/// saturating `as i32` is not vectorised). Adding 1.5·2²³ rounds `x` to the nearest
/// integer into the low mantissa bits; one step down where that rounded up.
#[inline(always)]
pub(super) fn floor_small(x: f32) -> i32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 · 2^23
    let nearest = (x + MAGIC).to_bits() as i32 - MAGIC.to_bits() as i32;
    nearest - i32::from(nearest as f32 > x)
}

/// `x` limited to `[lo, hi]`, NaN sent to `lo` (`f32::clamp` keeps NaN, which a
/// saturating conversion would then have to handle).
#[inline(always)]
#[allow(clippy::manual_clamp)]
pub(super) fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    x.max(lo).min(hi)
}

/// The first pixel (column or row) of a splat of odd `width` centred on the pixel
/// that holds the coordinate `x`: `round(x) − (width − 1)/2` (halves up; `x` is limited
/// to the range of pixel coordinates first).
#[inline(always)]
fn first_px(x: f32, width: i32) -> i32 {
    // Limit first: the projection of points near the domain's edge can be huge.
    floor_small(limit(x, -30_000.0, 30_000.0) + 0.5) - ((width - 1) >> 1)
}

/// The splat of one point, or `None` if it is not seen (behind the viewpoint, outside
/// the model's domain, or entirely outside the image). The reference for
/// [`project_block`], and the path of cameras with lens distortion.
#[inline(always)]
pub(super) fn project_point(
    p: &PackedPoint,
    footprint: f32,
    view: &View,
    camera: &Camera,
) -> Option<Splat> {
    let [x, y, z] = p.steps.map(f32::from);
    project_steps(Vec3::new(x, y, z), p.intensity, footprint, view, camera)
}

/// [`project_point`] of a point at `steps` (as floats: exact below 2²⁴) from the
/// corner of the view's cell.
#[inline(always)]
pub(super) fn project_steps(
    steps: Vec3,
    intensity: u16,
    footprint: f32,
    view: &View,
    camera: &Camera,
) -> Option<Splat> {
    let pc = view.point_rotation * steps + view.point_translation;
    let rho = pc.length();
    let dd = pc.z + view.xi * rho;
    if !(dd > 0.0) || (view.xi > 1.0 && !(view.xi * pc.z + rho > 0.0)) {
        return None;
    }
    let inv_d = 1.0 / dd;
    let [u, v] = if view.undistorted {
        let (x, y) = (pc.x * inv_d, pc.y * inv_d);
        [
            view.alpha_u * x + view.skew * y + view.u0,
            view.alpha_v * y + view.v0,
        ]
    } else {
        camera.project_unbounded(pc.to_array()).ok()?
    };
    // Footprint in pixels: spacing · α/D · max((ρ + ξZ)/D, 1).
    let size = footprint * inv_d * ((rho + view.xi * pc.z) * inv_d).max(1.0);
    let width = splat_width(size, view.max_width);
    let iu = first_px(u, width) - view.origin[0];
    let iv = first_px(v, width) - view.origin[1];
    if iu + width <= 0 || iv + width <= 0 || iu >= view.width || iv >= view.height {
        return None;
    }
    Some(Splat::new(
        [iu, iv, view.width],
        width,
        i32::from(intensity),
        rho,
        band_limit(rho, view),
    ))
}

/// Width of the square splat of a footprint of `size` pixels: the odd width
/// `2 ⌈(size − 1)/2⌉ + 1`, at most `max_width` (no libm call, no branch). Odd, so that
/// a splat grows by a ring of pixels around the one holding the projection. (`⌈size⌉`,
/// even widths included, was tried: closer to a pixel-integrated reference, but
/// a rendering less smooth in the pose — the whole-pipeline finite differences of the
/// PGM's Jacobian along the optical axis fell from 0.87 to 0.84 in cosine — and every
/// run of the convergence protocols it changed ended worse; `docs/RESULTS.md`.)
#[inline(always)]
fn splat_width(size: f32, max_width: i32) -> i32 {
    let h = limit((size - 1.0) * 0.5, 0.0, 1000.0);
    let t = floor_small(h);
    2 * (t + i32::from((t as f32) < h)).min((max_width - 1) >> 1) + 1
}

/// Points projected at a time by [`project_block`].
pub(super) const BLOCK: usize = 64;
/// Points projected at a time at the end of a cell (fewer wasted on padding: level of
/// detail leaves most cells with a count that is not a multiple of [`BLOCK`]).
pub(super) const TAIL: usize = 8;

#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
/// The splats of `N` points, one array per field: what [`project_block`] computes
/// several points at a time before packing them into [`Splat`]s.
struct Lanes<const N: usize> {
    iu: [i32; N],
    iv: [i32; N],
    /// [`NOT_DRAWN`] where the point is not seen.
    width: [i32; N],
    range: [f32; N],
    limit: [f32; N],
    intensity: [i32; N],
}

#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
impl<const N: usize> Lanes<N> {
    /// The splat of point `k`.
    fn splat(&self, k: usize, view: &View) -> Splat {
        Splat::new(
            [self.iu[k], self.iv[k], view.width],
            self.width[k],
            self.intensity[k],
            self.range[k],
            self.limit[k],
        )
    }

    fn new() -> Self {
        Self {
            iu: [0; N],
            iv: [0; N],
            width: [0; N],
            range: [0.0; N],
            limit: [0.0; N],
            intensity: [0; N],
        }
    }
}

/// [`project_point`] of `N` points of a camera without lens distortion, with the
/// same operations in the same order (so bit for bit the same splats), several points
/// per instruction: explicit SSE2 on x86-64 ([`sse2::project_splats`]), elsewhere
/// branch-free code that the compiler vectorises ([`project_lanes_portable`]); the
/// [`Baseline`](super::projector::Baseline) projector (wider ones:
/// [`Avx512`](super::projector::Avx512), [`Avx2`](super::projector::Avx2)). Unseen
/// points get the width [`NOT_DRAWN`](super::splat::NOT_DRAWN) (their other fields are
/// then meaningless).
#[inline(always)]
pub(super) fn project_block<const N: usize>(
    points: &[PackedPoint; N],
    footprint: f32,
    view: &View,
    out: &mut [Splat; N],
) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    sse2::project_splats(points, footprint, view, out);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    {
        let mut lanes = Lanes::<N>::new();
        project_lanes_portable(points, footprint, view, &mut lanes);
        for (k, out) in out.iter_mut().enumerate() {
            *out = lanes.splat(k, view);
        }
    }
}

/// The lanes of [`project_block`] without explicit vector instructions: branch-free,
/// so that the compiler computes several points per instruction where it can.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
#[inline(always)]
fn project_lanes_portable<const N: usize>(
    points: &[PackedPoint; N],
    footprint: f32,
    view: &View,
    out: &mut Lanes<N>,
) {
    let r = view.point_rotation;
    let t = view.point_translation;
    for k in 0..N {
        let [x, y, z] = points[k].steps.map(f32::from);
        // `Mat3 * Vec3 + Vec3` as glam computes it.
        let pcx = r.x_axis.x * x + r.y_axis.x * y + r.z_axis.x * z + t.x;
        let pcy = r.x_axis.y * x + r.y_axis.y * y + r.z_axis.y * z + t.y;
        let pcz = r.x_axis.z * x + r.y_axis.z * y + r.z_axis.z * z + t.z;
        let rho = (pcx * pcx + pcy * pcy + pcz * pcz).sqrt();
        let dd = pcz + view.xi * rho;
        let in_domain = (dd > 0.0) & ((view.xi <= 1.0) | (view.xi * pcz + rho > 0.0));
        let inv_d = 1.0 / dd;
        let u = view.alpha_u * (pcx * inv_d) + view.skew * (pcy * inv_d) + view.u0;
        let v = view.alpha_v * (pcy * inv_d) + view.v0;
        let size = footprint * inv_d * ((rho + view.xi * pcz) * inv_d).max(1.0);
        let n = splat_width(size, view.max_width);
        let (pu, pv) = (
            first_px(u, n) - view.origin[0],
            first_px(v, n) - view.origin[1],
        );
        let in_image = (pu + n > 0) & (pv + n > 0) & (pu < view.width) & (pv < view.height);
        out.iu[k] = pu;
        out.iv[k] = pv;
        out.width[k] = if in_domain & in_image {
            n
        } else {
            i32::from(NOT_DRAWN)
        };
        out.range[k] = rho;
        out.limit[k] = band_limit(rho, view);
        out.intensity[k] = i32::from(points[k].intensity);
    }
}

#[cfg(test)]
mod tests {
    //! The vectorised per-point kernels against their scalar references.

    use glam::{DMat3, DVec3, Vec3};
    use proptest::prelude::*;

    use super::*;
    #[cfg(target_arch = "x86_64")]
    use crate::render::projector::{Avx2, Avx512};
    use crate::render::projector::{Baseline, Project};
    use crate::render::tests::{regions, test_setup};

    /// The splats of `points` by every projector this processor runs, in pass 1's
    /// own instruction set (its first [`BLOCK`] as a block, the rest, 37 points, as a
    /// cell's last ones), each checked to agree with the baseline projector; returns
    /// the baseline's. The AVX-512 and AVX2 projectors are checked where the processor
    /// has them.
    fn with_every_projector(
        points: &[PackedPoint; BLOCK],
        footprint: f32,
        view: &View,
    ) -> Vec<Splat> {
        struct Run<'a, P> {
            points: &'a [PackedPoint; BLOCK],
            footprint: f32,
            view: &'a View,
            projector: P,
        }
        impl<P: Project> pulp::WithSimd for Run<'_, P> {
            type Output = Vec<Splat>;
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _: S) -> Vec<Splat> {
                let mut out = vec![Splat::default(); BLOCK + 37];
                let (block, rest) = out.split_at_mut(BLOCK);
                let block: &mut [Splat; BLOCK] = block.try_into().unwrap();
                self.projector
                    .lanes(self.points, self.footprint, self.view, block);
                self.projector
                    .rest(&self.points[..37], self.footprint, self.view, rest);
                out
            }
        }
        let baseline = pulp::Simd::vectorize(
            pulp::Scalar,
            Run {
                points,
                footprint,
                view,
                projector: Baseline,
            },
        );
        let same = |a: &[Splat], b: &[Splat]| {
            a.iter()
                .zip(b)
                .all(|(a, b)| a.drawn() == b.drawn() && (!a.drawn() || a == b))
        };
        assert!(
            same(&baseline[BLOCK..], &baseline[..37]),
            "a cell's last points differ from the same points in a block"
        );
        #[cfg(target_arch = "x86_64")]
        {
            let check = |wide: Vec<Splat>, name: &str| {
                assert!(
                    same(&wide, &baseline),
                    "{name} and baseline projectors differ"
                );
            };
            if let Some(simd) = pulp::x86::V4::try_new() {
                let projector = Avx512(simd);
                check(
                    pulp::Simd::vectorize(
                        simd,
                        Run {
                            points,
                            footprint,
                            view,
                            projector,
                        },
                    ),
                    "AVX-512",
                );
            }
            if let Some(simd) = pulp::x86::V3::try_new() {
                let projector = Avx2(simd);
                check(
                    pulp::Simd::vectorize(
                        simd,
                        Run {
                            points,
                            footprint,
                            view,
                            projector,
                        },
                    ),
                    "AVX2",
                );
            }
        }
        baseline
    }

    proptest! {
        /// `floor_small` is `floor` over its whole domain, halves and negative values
        /// included.
        #[test]
        fn floor_small_is_floor(x in -4_000_000.0f32..4_000_000.0, halves in -60_000i32..60_000) {
            prop_assert_eq!(floor_small(x), x.floor() as i32);
            let half = halves as f32 * 0.5;
            prop_assert_eq!(floor_small(half), half.floor() as i32);
            prop_assert_eq!(floor_small(-x.abs() * 1e-6), (-x.abs() * 1e-6).floor() as i32);
        }

        /// A block of points (of [`BLOCK`], and its first [`TAIL`] as a tail block)
        /// projects to exactly the splats of the scalar kernel: steps of 1 µm to
        /// 10 cm, cells' corners near the viewpoint, metres and kilometres away, points
        /// behind the viewpoint, beyond the model's domain (ξ > 1), off the image, or
        /// at the viewpoint itself included.
        #[test]
        fn project_block_equals_project_point(
            seed in any::<u64>(),
            axis_angle in prop::array::uniform3(-3.2f64..3.2),
            translation in prop::array::uniform3(-5.0f64..5.0),
            alpha_u in 20.0f32..400.0,
            aspect in 0.8f32..1.25,
            skew in -3.0f32..3.0,
            xi in 0.0f32..2.5,
            spacing_m in 0.001f32..0.5,
            splat_scale in 0.5f32..3.0,
            max_radius in 0u32..12,
            region in regions(),
            step_exponent in -6i32..=-1,
            corner_scale in prop::sample::select(vec![0.0f64, 0.3, 3.0, 30.0, 3000.0]),
        ) {
            let (camera, options) = test_setup(alpha_u, aspect, skew, xi, splat_scale, max_radius);
            let axis = DVec3::from_array(axis_angle);
            let view = View::new(
                &camera,
                &options,
                region,
                DMat3::from_axis_angle(axis.normalize_or(DVec3::Z), axis.length()),
                DVec3::from_array(translation),
                10f64.powi(step_exponent),
            );
            let mut rng = crate::rng::SplitMix64::new(seed);
            let corner = [0.0; 3].map(|_: f64| (rng.unit() * 2.0 - 1.0) * corner_scale);
            let mut points = [PackedPoint::default(); BLOCK];
            for (k, p) in points.iter_mut().enumerate() {
                // Near the corner, and across the whole cell.
                let range = [16, 1024, 65_536][k % 3];
                p.steps = [0; 3].map(|_: u16| rng.below(range) as u16);
                p.intensity = rng.below(65_536) as u16;
            }
            // Without a corner scale, the cell's corner at the viewpoint and the first
            // point on it.
            let at_viewpoint = corner_scale == 0.0;
            if at_viewpoint {
                points[0].steps = [0; 3];
            }
            let view = view.in_cell(if at_viewpoint { Vec3::ZERO } else { view.corner(corner) });
            let footprint = spacing_m * view.alpha * splat_scale;
            let mut block = [Splat::default(); BLOCK];
            project_block(&points, footprint, &view, &mut block);
            let mut tail = [Splat::default(); TAIL];
            let first: &[PackedPoint; TAIL] = points[..TAIL].try_into().unwrap();
            project_block(first, footprint, &view, &mut tail);
            for (t, b) in tail.iter().zip(&block) {
                prop_assert_eq!(t, b);
            }
            for (p, got) in points.iter().zip(&block) {
                match project_point(p, footprint, &view, &camera) {
                    Some(want) => prop_assert_eq!(*got, want, "point {:?}", p),
                    None => prop_assert!(!got.drawn(), "point {:?}", p),
                }
            }
            // Every projector, by whole blocks and by a cell's last points.
            for (k, got) in with_every_projector(&points, footprint, &view)[..BLOCK].iter().enumerate() {
                prop_assert_eq!(got.drawn(), block[k].drawn(), "point {:?}", points[k]);
                if got.drawn() {
                    prop_assert_eq!(*got, block[k], "point {:?}", points[k]);
                }
            }
            // The portable kernel (the one of other architectures) too.
            let mut lanes = Lanes::<BLOCK>::new();
            project_lanes_portable(&points, footprint, &view, &mut lanes);
            for (k, got) in block.iter().enumerate() {
                let portable = lanes.splat(k, &view);
                prop_assert_eq!(portable.drawn(), got.drawn());
                if got.drawn() {
                    prop_assert_eq!(portable, *got);
                }
            }
        }
    }
}
