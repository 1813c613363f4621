//! [`align_depth`]: where a depth picture fits other depth pictures of the same scene,
//! by geometry alone — point-to-plane ICP with projective association.
//!
//! Each [`Surface`] is a depth picture with its pose: a point and a normal per pixel
//! (normals from the neighbouring pixels; none on depth discontinuities). A query
//! point, placed in the world by the current pose, is paired with the pixel it falls
//! on in *every* target surface that holds a point within the pairing distance and a
//! normal within `max_normal_angle_deg` of its own: all targets vote, so the result is
//! where the query fits the targets together. The residual is the point's distance to
//! the target's tangent plane; Gauss–Newton steps on the pose (perturbed in the query
//! camera's frame), Huber weights, a pairing distance that shrinks from
//! `first_distance_m` to `final_distance_m` halfway through.
//!
//! Colour plays no part, so the alignment checks a dataset's poses independently of
//! the pictures a photometric method compares: a query whose pose fits its neighbours
//! to millimetres but a far frame only after centimetres says the dataset's poses
//! disagree between those frames, whatever the method.

use faer::{Mat, Side};
use glam::{DVec3, Vec3};
use ucm::{Camera, Isometry3};

use crate::error::{check_pose, check_size};
use crate::{DepthImage, RgbdError};

/// A depth picture as a surface: per pixel a point and a unit normal in its camera's
/// frame (`f32`: millimetre-level geometry needs far less than its precision), and where
/// the camera was.
#[derive(Clone, Debug)]
pub struct Surface {
    camera: Camera,
    world_from_depth: Isometry3,
    depth_from_world: Isometry3,
    /// Point of each pixel in the camera's frame; `None` where it has no normal.
    points: Vec<Option<(Vec3, Vec3)>>,
}

impl Surface {
    /// The surface of `depth`, taken by `camera` (its depth is along the optical axis)
    /// at `world_from_depth`. A pixel gets a normal when its four neighbours are
    /// measured and no neighbour's depth differs from its own by more than
    /// `max_depth_jump` times its depth.
    pub fn new(
        depth: &DepthImage,
        camera: &Camera,
        world_from_depth: &Isometry3,
        max_depth_jump: f32,
    ) -> Result<Self, RgbdError> {
        check_size(
            "depth picture",
            "<memory>".into(),
            (depth.width(), depth.height()),
            camera,
        )?;
        check_pose("world_from_depth", world_from_depth)?;
        if !(max_depth_jump > 0.0 && max_depth_jump.is_finite()) {
            return Err(RgbdError::Parameter {
                name: "max_depth_jump",
                message: format!("{max_depth_jump} is not a positive ratio"),
            });
        }
        let (w, h) = (depth.width() as usize, depth.height() as usize);
        let d = &depth.depth_m;
        // `depth_m` is a public field: its length is checked, not assumed.
        if d.len() != w * h {
            return Err(RgbdError::Length {
                what: "depth_m",
                got: d.len(),
                expected: w * h,
            });
        }
        // The point of every measured pixel (depth along the optical axis).
        let point = |x: usize, y: usize| -> Option<Vec3> {
            let z = d[y * w + x];
            if !(z > 0.0 && z.is_finite()) {
                return None;
            }
            let ray = camera.unproject([x as f64, y as f64]).ok()?;
            (ray[2] > 1e-9).then(|| {
                let s = f64::from(z) / ray[2];
                Vec3::new((ray[0] * s) as f32, (ray[1] * s) as f32, z)
            })
        };
        let mut points = vec![None; w * h];
        for y in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                let Some(p) = point(x, y) else { continue };
                let limit = max_depth_jump * p.z;
                let near = |q: Option<Vec3>| q.filter(|q| (q.z - p.z).abs() <= limit);
                let (Some(l), Some(r), Some(t), Some(b)) = (
                    near(point(x - 1, y)),
                    near(point(x + 1, y)),
                    near(point(x, y - 1)),
                    near(point(x, y + 1)),
                ) else {
                    continue;
                };
                let n = (r - l).cross(b - t);
                let length = n.length();
                if !(length > 0.0 && length.is_finite()) {
                    continue;
                }
                // Facing the camera.
                let n = n / length;
                let n = if n.dot(p) > 0.0 { -n } else { n };
                points[y * w + x] = Some((p, n));
            }
        }
        Ok(Self {
            camera: camera.clone(),
            world_from_depth: *world_from_depth,
            depth_from_world: world_from_depth.inverse(),
            points,
        })
    }

    /// Where the camera was.
    pub fn world_from_depth(&self) -> &Isometry3 {
        &self.world_from_depth
    }

    /// Pixels with a point and a normal.
    pub fn point_count(&self) -> usize {
        self.points.iter().flatten().count()
    }

    /// The point and normal (world frame) of the pixel that `point_world` falls on,
    /// if any.
    fn pair(&self, point_world: DVec3) -> Option<(DVec3, DVec3)> {
        let p = self.depth_from_world.transform_point(point_world);
        if !(p.z > 0.0) {
            return None;
        }
        let [u, v] = self.camera.project([p.x, p.y, p.z]).ok()?;
        let (x, y) = (u.round(), v.round());
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x, y) = (x as usize, y as usize);
        let w = self.camera.width() as usize;
        if x >= w || y >= self.camera.height() as usize {
            return None;
        }
        let (q, n) = self.points[y * w + x]?;
        Some((
            self.world_from_depth.transform_point(q.as_dvec3()),
            self.world_from_depth.transform_vector(n.as_dvec3()),
        ))
    }
}

/// Settings of [`align_depth`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignOptions {
    /// Gauss–Newton iterations at most.
    pub iterations: u32,
    /// Every `stride`-th pixel of the query, along rows and columns.
    pub stride: u32,
    /// Pairs farther apart are dropped during the first half of the iterations (m).
    /// A rule of thumb: more than the most the starting pose's error moves a query
    /// point, its translation plus its rotation (rad) times the farthest point's range
    /// (5 cm and 3° at 3.5 m: 23 cm; pairing is along the target camera's rays, so a
    /// surface seen at a grazing angle pairs farther still). The default suits starts a
    /// few centimetres and about a degree off, as a dataset's poses are; from farther,
    /// the pose can slide to where the surfaces that hold it are out of reach and
    /// settle there.
    pub first_distance_m: f64,
    /// … and during the second half, and in the reported RMS (m).
    pub final_distance_m: f64,
    /// Residuals beyond this get Huber's weight (m).
    pub huber_m: f64,
    /// Pairs whose normals differ by more are dropped (degrees).
    pub max_normal_angle_deg: f64,
    /// See [`Surface::new`].
    pub max_depth_jump: f32,
}

impl Default for AlignOptions {
    fn default() -> Self {
        Self {
            iterations: 40,
            stride: 2,
            first_distance_m: 0.10,
            final_distance_m: 0.03,
            huber_m: 0.01,
            max_normal_angle_deg: 30.0,
            max_depth_jump: 0.03,
        }
    }
}

impl AlignOptions {
    fn validate(&self) -> Result<(), RgbdError> {
        let bad = |name, message: String| Err(RgbdError::Parameter { name, message });
        if self.iterations == 0 || self.iterations > 10_000 {
            return bad(
                "iterations",
                format!("{} is not in 1..=10000", self.iterations),
            );
        }
        if self.stride == 0 {
            return bad("stride", "must be at least 1".into());
        }
        for (name, value) in [
            ("first_distance_m", self.first_distance_m),
            ("final_distance_m", self.final_distance_m),
            ("huber_m", self.huber_m),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return bad(name, format!("{value} is not a positive length"));
            }
        }
        if !(self.max_normal_angle_deg > 0.0 && self.max_normal_angle_deg <= 180.0) {
            return bad(
                "max_normal_angle_deg",
                format!("{} is not in (0, 180]", self.max_normal_angle_deg),
            );
        }
        Ok(())
    }
}

/// What [`align_depth`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthAlignment {
    /// The refined pose of the query's depth camera.
    pub world_from_depth: Isometry3,
    /// Point-to-plane RMS (m) of the pairs within `final_distance_m` at the given pose…
    pub rms_before_m: f64,
    /// … and at the refined pose.
    pub rms_after_m: f64,
    /// Those pairs at the given pose…
    pub pairs_before: usize,
    /// … and at the refined pose.
    pub pairs_after: usize,
    /// Iterations run.
    pub iterations: u32,
    /// How evenly the pairs at the refined pose constrain the pose: the smallest over
    /// the largest eigenvalue of the normal equations, rotations counted as the motion
    /// they give the query's farthest point. Near 1 every direction is held alike;
    /// near 0 one is barely held (the axis of a corridor), and the pose may have slid
    /// along it.
    pub conditioning: f64,
}

/// Sums of one pass over the query's points.
#[derive(Default)]
struct Normal {
    jtj: [[f64; 6]; 6],
    jte: [f64; 6],
    squares: f64,
    pairs: usize,
}

/// The row `∂r/∂δ` of the point-to-plane residual `r = mᵀ (pose · exp(δ) · p − q)`
/// at δ = 0, where `inverse` is the pose's rotation inverted, `p` the point in the
/// query camera's frame and `m` the target's normal in the world:
/// `mᵀ R [I, −[p]×] = [(Rᵀm)ᵀ, (p × Rᵀm)ᵀ]`.
fn point_to_plane_row(inverse: glam::DQuat, p: DVec3, m: DVec3) -> [f64; 6] {
    let a = inverse * m;
    let b = p.cross(a);
    [a.x, a.y, a.z, b.x, b.y, b.z]
}

/// One pass: every query point (camera frame) paired in every surface at
/// `world_from_depth`; the normal equations of the step `δ` such that the pose becomes
/// `world_from_depth · exp(δ)`.
fn accumulate(
    points: &[(DVec3, DVec3)],
    world_from_depth: &Isometry3,
    surfaces: &[Surface],
    distance_m: f64,
    min_cos: f64,
    huber_m: f64,
) -> Normal {
    let mut sums = Normal::default();
    let rotation = world_from_depth.rotation;
    let inverse = rotation.inverse();
    for &(p, n) in points {
        let world = world_from_depth.transform_point(p);
        let normal_world = rotation * n;
        for surface in surfaces {
            let Some((q, m)) = surface.pair(world) else {
                continue;
            };
            if (world - q).length() > distance_m || m.dot(normal_world) < min_cos {
                continue;
            }
            let r = m.dot(world - q);
            let j = point_to_plane_row(inverse, p, m);
            let weight = if r.abs() <= huber_m {
                1.0
            } else {
                huber_m / r.abs()
            };
            for (row, &ji) in sums.jtj.iter_mut().zip(&j) {
                for (cell, &jk) in row.iter_mut().zip(&j) {
                    *cell += weight * ji * jk;
                }
            }
            for (g, &ji) in sums.jte.iter_mut().zip(&j) {
                *g += weight * ji * r;
            }
            sums.squares += r * r;
            sums.pairs += 1;
        }
    }
    sums
}

/// `δ = −(JᵀWJ)⁻¹ JᵀWr`, or why not: a system whose smallest eigenvalue is below
/// `1e-9` × its largest leaves a direction the surfaces do not constrain (a single
/// plane, say).
fn step(sums: &Normal) -> Result<[f64; 6], RgbdError> {
    let a = Mat::<f64>::from_fn(6, 6, |i, j| sums.jtj[i][j]);
    let eigen = a
        .self_adjoint_eigen(Side::Lower)
        .map_err(|_| RgbdError::Degenerate {
            pairs: sums.pairs,
            ratio: 0.0,
        })?;
    let u = eigen.U();
    let s = eigen.S().column_vector();
    let largest = (0..6).map(|i| s[i]).fold(0.0, f64::max);
    let smallest = (0..6).map(|i| s[i]).fold(f64::INFINITY, f64::min);
    let ratio = smallest / largest;
    if !(largest > 0.0 && ratio > 1e-9) {
        return Err(RgbdError::Degenerate {
            pairs: sums.pairs,
            ratio: if ratio.is_finite() { ratio } else { 0.0 },
        });
    }
    let mut x = [0.0; 6];
    for k in 0..6 {
        let projection: f64 = (0..6).map(|i| u[(i, k)] * sums.jte[i]).sum::<f64>() / s[k];
        for (i, xi) in x.iter_mut().enumerate() {
            *xi -= u[(i, k)] * projection;
        }
    }
    Ok(x)
}

/// Refine the pose `world_from_depth` of the depth picture `depth` (taken by `camera`)
/// against `surfaces`. Errors: a picture of another size than its camera, a non-finite
/// pose, settings out of range, no pair at the given pose ([`RgbdError::NoOverlap`]),
/// surfaces that leave a direction free ([`RgbdError::Degenerate`]).
pub fn align_depth(
    depth: &DepthImage,
    camera: &Camera,
    world_from_depth: &Isometry3,
    surfaces: &[Surface],
    options: &AlignOptions,
) -> Result<DepthAlignment, RgbdError> {
    options.validate()?;
    let query = Surface::new(depth, camera, world_from_depth, options.max_depth_jump)?;
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let stride = options.stride as usize;
    let points: Vec<(DVec3, DVec3)> = (0..h)
        .step_by(stride)
        .flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x))
        .filter_map(|k| query.points[k].map(|(p, n)| (p.as_dvec3(), n.as_dvec3())))
        .collect();
    let range_m = points.iter().map(|(p, _)| p.length()).fold(0.0, f64::max);
    let min_cos = options.max_normal_angle_deg.to_radians().cos();
    let pass = |pose: &Isometry3, distance_m: f64| {
        accumulate(
            &points,
            pose,
            surfaces,
            distance_m,
            min_cos,
            options.huber_m,
        )
    };
    let before = pass(world_from_depth, options.final_distance_m);
    let mut pose = *world_from_depth;
    let mut iterations = 0;
    for iteration in 0..options.iterations {
        let distance_m = if iteration < options.iterations / 2 {
            options.first_distance_m
        } else {
            options.final_distance_m
        };
        let sums = pass(&pose, distance_m);
        if sums.pairs == 0 {
            return Err(RgbdError::NoOverlap {
                points: points.len(),
                surfaces: surfaces.len(),
            });
        }
        let mut delta = step(&sums)?;
        // A step moves no query point by more than half the pairing distance (a
        // weakly paired first pass would otherwise throw the pose away).
        let moved = DVec3::new(delta[0], delta[1], delta[2]).length();
        let turned = DVec3::new(delta[3], delta[4], delta[5]).length();
        let reach = moved + turned * range_m;
        if reach > 0.5 * distance_m {
            let scale = 0.5 * distance_m / reach;
            delta.iter_mut().for_each(|d| *d *= scale);
        }
        pose = pose * Isometry3::exp(delta)?;
        iterations = iteration + 1;
        if iteration >= options.iterations / 2 && moved < 1e-7 && turned < 1e-8 {
            break;
        }
    }
    let after = pass(&pose, options.final_distance_m);
    let conditioning = conditioning(&after, range_m);
    let rms = |n: &Normal| {
        if n.pairs == 0 {
            f64::NAN
        } else {
            (n.squares / n.pairs as f64).sqrt()
        }
    };
    Ok(DepthAlignment {
        world_from_depth: pose,
        rms_before_m: rms(&before),
        rms_after_m: rms(&after),
        pairs_before: before.pairs,
        pairs_after: after.pairs,
        iterations,
        conditioning,
    })
}

/// Smallest over largest eigenvalue of the normal equations with the rotation's
/// columns scaled by `range_m` (0 when they cannot be computed).
fn conditioning(sums: &Normal, range_m: f64) -> f64 {
    let scale = |i: usize| if i < 3 { 1.0 } else { 1.0 / range_m.max(1e-9) };
    let a = Mat::<f64>::from_fn(6, 6, |i, j| sums.jtj[i][j] * scale(i) * scale(j));
    let Ok(eigen) = a.self_adjoint_eigen(Side::Lower) else {
        return 0.0;
    };
    let s = eigen.S().column_vector();
    let largest = (0..6).map(|i| s[i]).fold(0.0, f64::max);
    let smallest = (0..6).map(|i| s[i]).fold(f64::INFINITY, f64::min);
    let ratio = smallest / largest;
    if ratio.is_finite() {
        ratio.max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use proptest::prelude::*;
    use ucm::Isometry3;

    use super::point_to_plane_row;

    proptest! {
        /// The residual's row against central differences of `r(δ)` along each of the
        /// six directions, over random poses, points, normals and target points.
        #[test]
        fn the_point_to_plane_row_matches_finite_differences(
            pose in prop::array::uniform6(-2.0f64..2.0),
            p in prop::array::uniform3(-3.0f64..3.0),
            n in prop::array::uniform3(-1.0f64..1.0),
            q in prop::array::uniform3(-3.0f64..3.0),
        ) {
            let pose = Isometry3::from_pose_vector(pose).unwrap();
            let (p, q) = (DVec3::from(p), DVec3::from(q));
            prop_assume!(DVec3::from(n).length() > 0.1);
            let m = DVec3::from(n).normalize();
            let residual = |delta: [f64; 6]| {
                let moved = pose * Isometry3::exp(delta).unwrap();
                m.dot(moved.transform_point(p) - q)
            };
            let row = point_to_plane_row(pose.rotation.inverse(), p, m);
            let h = 1e-6;
            for (k, &analytic) in row.iter().enumerate() {
                let mut plus = [0.0; 6];
                let mut minus = [0.0; 6];
                plus[k] = h;
                minus[k] = -h;
                let numeric = (residual(plus) - residual(minus)) / (2.0 * h);
                prop_assert!(
                    (numeric - analytic).abs() < 1e-6 * (1.0 + analytic.abs()),
                    "direction {}: {} against {}", k, numeric, analytic
                );
            }
        }
    }
}
