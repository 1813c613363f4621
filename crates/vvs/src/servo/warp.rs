//! Beyond the paper ([`crate::VvsConfig::rerender_px`]): between two renderings, the
//! picture warped into the last one through its ranges, so that an iteration compares
//! without rendering (the inverse compositional scheme of Baker and Matthews, 2004,
//! with the rendering as the template).
//!
//! A rendering at `world_from_reference` sees, at pixel `k`, the point `X_k = ρ_k d_k`
//! of its camera frame (`d_k` the pixel's ray, `ρ_k` its range). A camera at
//! `world_from_camera` sees that point at `π(camera_from_reference X_k)`: the picture
//! sampled there (bilinearly) is what the picture shows at pixel `k` of the rendering
//! if the pose is right. With the estimate at `world_from_reference · Δ` and the picture
//! taken at `world_from_reference · D`, the warped picture looks like the rendering's
//! camera moved by `D Δ⁻¹`; the law's `v` (from the rendering's `L_G`, computed once)
//! estimates that motion, so the pose becomes `world_from_reference · exp(v) · Δ`
//! ([`compose`]). Approximations: the surface is taken at the rendering's ranges (no
//! occlusion), the picture is interpolated bilinearly, and the Jacobian is the last
//! rendering's (its normalisation over that rendering's support too).

use frame::{AnyImage, Frame, Image, PixelStatus};
use glam::{Mat3, Vec3};
use ucm::{Camera, Isometry3};

use super::stage::motion_px;

/// What an iteration between renderings compares against: the rendering's pose, λ
/// and the scale of its image motion, fixed when it was rendered.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Reference {
    /// The pose the level's frame was rendered at.
    pub(crate) world_from_reference: Isometry3,
    /// λ when the rendering's `L_G` and `J_λ` were computed.
    pub(crate) lambda: f32,
    /// `1/ρ̄`, the mean inverse range of the rendering's hits (m⁻¹).
    pub(crate) mean_inverse_range: f64,
    /// How many pixels of the picture hold an intensity (the coverage's denominator).
    pub(crate) observed: usize,
    /// Whether the level's points hold the rendering's ([`lift`]: done by the first
    /// iteration that warps, as most renderings are followed by another).
    pub(crate) lifted: bool,
}

impl Reference {
    /// How far `world_from_camera` moves the image of the rendering, in pixels of
    /// `camera` (`α (‖t‖ / ρ̄ + ‖ω‖)`, as the test in pixels measures an update).
    pub(crate) fn image_motion_px(&self, camera: &Camera, world_from_camera: &Isometry3) -> f64 {
        let [tx, ty, tz, wx, wy, wz] =
            (self.world_from_reference.inverse() * *world_from_camera).log();
        let t = (tx * tx + ty * ty + tz * tz).sqrt();
        let w = (wx * wx + wy * wy + wz * wz).sqrt();
        motion_px(camera, self.mean_inverse_range, t, w)
    }
}

/// The pose after the update `v` of an iteration that compared in the rendering taken
/// at `world_from_reference`: `world_from_reference · exp(v) · reference_from_camera`.
pub(crate) fn compose(
    world_from_reference: &Isometry3,
    update: Isometry3,
    world_from_camera: &Isometry3,
) -> Isometry3 {
    *world_from_reference * update * (world_from_reference.inverse() * *world_from_camera)
}

/// Every pixel's ray (the unit vector of the camera frame it sees along), NaN where the
/// model has none: what [`lift`] scales, computed once for a level.
pub(crate) fn rays(camera: &Camera, rays: &mut Vec<[f32; 3]>) {
    let w = camera.width() as usize;
    rays.clear();
    rays.extend((0..camera.pixel_count()).map(|k| {
        camera
            .unproject([(k % w) as f32, (k / w) as f32])
            .unwrap_or([f32::NAN; 3])
    }));
}

/// Each hit of `frame` as the point of its camera frame it sees (`ρ d`, metres, `d` its
/// pixel's ray of [`rays`]), NaN where `frame` sees no point or its range is unknown.
pub(crate) fn lift(frame: &Frame, rays: &[[f32; 3]], points: &mut [[f32; 3]]) {
    for (((p, &status), &range_m), d) in points
        .iter_mut()
        .zip(&frame.status)
        .zip(&frame.range_m)
        .zip(rays)
    {
        // Without a branch (a NaN range makes the point NaN), so that the loop streams.
        let seen = (status == PixelStatus::Hit) & (range_m > 0.0) & (range_m < f32::INFINITY);
        let range_m = if seen { range_m } else { f32::NAN };
        *p = d.map(|c| c * range_m);
    }
}

/// `picture` seen from the rendering whose points are `points`: pixel `k` of `out`
/// takes the picture bilinearly at `π(camera_from_reference X_k)`, valid where `X_k` is
/// known, projects inside the picture and its four neighbours lie in the camera's valid
/// region and hold an intensity. Compiled for the widest instruction set found at run
/// time: the points are projected a block at a time
/// ([`Camera::project_transformed_unbounded`], vectorised; the same bits), then sampled.
pub(crate) fn warp(
    camera: &Camera,
    points: &[[f32; 3]],
    camera_from_reference: &Isometry3,
    picture: &impl AnyImage,
    out: &mut Image,
) {
    let (w, h) = (picture.width() as usize, picture.height() as usize);
    if w < 2 || h < 2 {
        out.valid.fill(false);
        return;
    }
    isa::arch().dispatch(Warp {
        camera,
        points,
        rotation: Mat3::from_quat(camera_from_reference.rotation.as_quat()),
        translation: camera_from_reference.translation.as_vec3(),
        picture,
        out,
    });
}

/// Points projected at once before they are sampled (a block's pixels stay in the
/// first level of cache).
const WARP_BLOCK: usize = 64;

/// [`warp`]'s arguments, as a `pulp` kernel (only what is inlined into `with_simd` is
/// compiled for its instruction set).
struct Warp<'a, P> {
    camera: &'a Camera,
    points: &'a [[f32; 3]],
    rotation: Mat3,
    translation: Vec3,
    picture: &'a P,
    out: &'a mut Image,
}

impl<P: AnyImage> pulp::WithSimd for Warp<'_, P> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Warp {
            camera,
            points,
            rotation,
            translation,
            picture,
            out,
        } = self;
        let (w, h) = (picture.width() as usize, picture.height() as usize);
        let intensity = picture.intensity();
        let region = camera.valid_pixels();
        let usable = |c: usize| region[c] && picture.is_observed(c);
        let mut pixels = [[0.0f32; 2]; WARP_BLOCK];
        let blocks = out
            .intensity
            .chunks_mut(WARP_BLOCK)
            .zip(out.valid.chunks_mut(WARP_BLOCK))
            .zip(points.chunks(WARP_BLOCK));
        for ((out, valid), points) in blocks {
            camera.project_transformed_unbounded(&rotation, translation, points, &mut pixels);
            let pixels = &pixels[..points.len()];
            for ((o, valid), &[u, v]) in out.iter_mut().zip(valid).zip(pixels) {
                *o = 0.0;
                *valid = false;
                // The four pixels around (u, v): pixel (i, j) is centred at (i, j)
                // (non-negative coordinates truncate to their floor; NaN fails).
                if !(u >= 0.0 && v >= 0.0 && u < (w - 1) as f32 && v < (h - 1) as f32) {
                    continue;
                }
                let (x0, y0) = (u as usize, v as usize);
                let (fx, fy) = (u - x0 as f32, v - y0 as f32);
                let k = y0 * w + x0;
                if !(usable(k) && usable(k + 1) && usable(k + w) && usable(k + w + 1)) {
                    continue;
                }
                let (a, b, c, d) = (
                    intensity[k],
                    intensity[k + 1],
                    intensity[k + w],
                    intensity[k + w + 1],
                );
                *o = (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy;
                *valid = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use splat::PointCloud;

    use super::*;

    /// A textured plane of 1.5 cm points, 6 m by 6 m, and the fixture camera (which
    /// sees 50° to 120° off its axis).
    fn plane() -> (PointCloud, Camera) {
        let (_, camera) = crate::servo::test_plane();
        let positions: Vec<DVec3> = (0..400 * 400)
            .map(|k| DVec3::new(f64::from(k % 400) * 0.015, f64::from(k / 400) * 0.015, 0.0))
            .collect();
        let intensities: Vec<f32> = positions
            .iter()
            .map(|p| (0.5 + 0.4 * (p.x * 5.0).sin() * (p.y * 3.0).cos()) as f32)
            .collect();
        let cloud = PointCloud::from_points(DVec3::ZERO, &positions, &intensities, None, None)
            .expect("a valid cloud");
        (cloud, camera)
    }

    /// `cloud` rendered by `camera` at `world_from_camera`, and its pixels lifted to
    /// points of the camera's frame.
    fn rendered_and_lifted(
        cloud: &PointCloud,
        camera: &Camera,
        world_from_camera: &Isometry3,
    ) -> (Frame, Vec<[f32; 3]>) {
        let mut renderer =
            splat::Renderer::new(camera.clone(), splat::RenderOptions::default()).unwrap();
        let mut frame = Frame::for_camera(camera);
        renderer
            .render(cloud, &world_from_camera.inverse(), &mut frame)
            .unwrap();
        let (mut rays_of_pixels, mut points) = (Vec::new(), vec![[0.0; 3]; camera.pixel_count()]);
        rays(camera, &mut rays_of_pixels);
        lift(&frame, &rays_of_pixels, &mut points);
        (frame, points)
    }

    /// The warp is its definition, point by point (`project_unbounded`, then the
    /// bilinear sample where the four neighbours are usable), to the bit: with the
    /// fixture camera and with the same camera given a lens distortion, after a motion.
    #[test]
    fn the_warp_is_its_definition_point_by_point() {
        let (cloud, fixture) = plane();
        let distorted = Camera::new(
            *fixture.intrinsics(),
            Some(ucm::Distortion {
                k1: -0.05,
                k2: 0.01,
                p1: 0.001,
                p2: -0.001,
                k3: 0.0,
            }),
            fixture.width(),
            fixture.height(),
            ucm::ValidRegion::Full,
        )
        .unwrap();
        let pose = Isometry3::from_pose_vector([3.0, 3.0, -0.4, 0.0, 0.0, 0.0]).unwrap();
        let motion = Isometry3::from_pose_vector([0.05, -0.03, 0.02, 0.01, -0.02, 0.015]).unwrap();
        for camera in [fixture, distorted] {
            let (frame, points) = rendered_and_lifted(&cloud, &camera, &pose);
            let picture = Image::from_frame(&frame);
            let mut out = Image::new(camera.width(), camera.height());
            warp(&camera, &points, &motion, &picture, &mut out);
            let rotation = Mat3::from_quat(motion.rotation.as_quat());
            let translation = motion.translation.as_vec3();
            let (w, h) = (camera.width() as usize, camera.height() as usize);
            let usable = |c: usize| camera.valid_pixels()[c] && picture.valid[c];
            let mut compared = 0;
            for (k, p) in points.iter().enumerate() {
                let q = rotation * Vec3::from_array(*p) + translation;
                let expected = camera
                    .project_unbounded(q.to_array())
                    .ok()
                    .and_then(|[u, v]| {
                        if !(u >= 0.0 && v >= 0.0 && u < (w - 1) as f32 && v < (h - 1) as f32) {
                            return None;
                        }
                        let (x0, y0) = (u as usize, v as usize);
                        let (fx, fy) = (u - x0 as f32, v - y0 as f32);
                        let i = y0 * w + x0;
                        let c = [i, i + 1, i + w, i + w + 1];
                        c.iter().all(|&c| usable(c)).then(|| {
                            let [a, b, c, d] = c.map(|c| picture.intensity[c]);
                            (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
                        })
                    });
                let got = out.valid[k].then_some(out.intensity[k]);
                assert_eq!(
                    got.map(f32::to_bits),
                    expected.map(f32::to_bits),
                    "pixel {k}"
                );
                compared += usize::from(got.is_some());
            }
            assert!(compared > 5000, "{compared} pixels compared");
        }
    }

    /// At the reference itself the warp gives the picture back at every hit whose
    /// neighbours are observed (a point of pixel `k` projects back onto `k`).
    #[test]
    fn the_warp_at_the_reference_is_the_picture() {
        let (cloud, camera) = plane();
        let pose = Isometry3::from_pose_vector([3.0, 3.0, -0.4, 0.0, 0.0, 0.0]).unwrap();
        let (frame, points) = rendered_and_lifted(&cloud, &camera, &pose);
        let picture = Image::from_frame(&frame);
        let mut out = Image::new(camera.width(), camera.height());
        warp(&camera, &points, &Isometry3::IDENTITY, &picture, &mut out);
        let mut compared = 0;
        for k in 0..camera.pixel_count() {
            if out.valid[k] {
                compared += 1;
                assert!(
                    (out.intensity[k] - picture.intensity[k]).abs() < 1e-3,
                    "pixel {k}: {} against {}",
                    out.intensity[k],
                    picture.intensity[k]
                );
            }
        }
        assert!(compared > 5000, "{compared} pixels compared");
    }

    /// A picture taken elsewhere, warped into the rendering, shows what the rendering
    /// shows (and unwarped, it does not): the warp goes from the rendering to the
    /// picture's camera, and [`compose`] undoes a motion of the rendering's camera.
    #[test]
    fn a_picture_warped_into_the_rendering_matches_it() {
        let (cloud, camera) = plane();
        let world_from_reference =
            Isometry3::from_pose_vector([3.0, 3.0, -0.4, 0.0, 0.0, 0.0]).unwrap();
        let world_from_camera = world_from_reference
            * Isometry3::from_pose_vector([0.05, -0.03, 0.02, 0.01, -0.02, 0.015]).unwrap();
        let (reference, points) = rendered_and_lifted(&cloud, &camera, &world_from_reference);
        let (frame, _) = rendered_and_lifted(&cloud, &camera, &world_from_camera);
        let picture = Image::from_frame(&frame);
        let mut out = Image::new(camera.width(), camera.height());
        let mean_difference = |out: &Image| {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for k in 0..camera.pixel_count() {
                if out.valid[k] {
                    sum += f64::from((out.intensity[k] - reference.intensity[k]).abs());
                    n += 1;
                }
            }
            (sum / n.max(1) as f64, n)
        };
        warp(
            &camera,
            &points,
            &(world_from_camera.inverse() * world_from_reference),
            &picture,
            &mut out,
        );
        let (warped, n) = mean_difference(&out);
        warp(&camera, &points, &Isometry3::IDENTITY, &picture, &mut out);
        let (unwarped, _) = mean_difference(&out);
        // The inverse motion: the wrong way round.
        warp(
            &camera,
            &points,
            &(world_from_reference.inverse() * world_from_camera),
            &picture,
            &mut out,
        );
        let (inverse, _) = mean_difference(&out);
        assert!(n > 5000, "{n} pixels compared");
        assert!(
            warped < 0.25 * unwarped && warped < 0.25 * inverse,
            "warped {warped}, unwarped {unwarped}, the inverse motion {inverse}"
        );
        // The composition: the picture taken at `world_from_reference · D`, warped by an
        // estimate `world_from_reference · Δ`, looks like the rendering's camera moved by
        // `D Δ⁻¹`; that update composed gives the picture's pose.
        let d = world_from_reference.inverse() * world_from_camera;
        let delta = Isometry3::exp([0.02, 0.01, -0.03, 0.005, 0.01, -0.02]).unwrap();
        let estimate = world_from_reference * delta;
        let back = compose(&world_from_reference, d * delta.inverse(), &estimate);
        let (t, r) = back.distance_to(&world_from_camera);
        assert!(t < 1e-9 && r < 1e-9, "{t} m, {r} rad");
    }
}
