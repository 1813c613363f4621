//! The acquired images: the sequence rendered at its true poses and degraded as a real
//! camera would ([`world::sequence::Acquisition`]).

use anyhow::bail;
use frame::{Frame, Image};
use splat::{PointCloud, RenderOptions, Renderer};
use ucm::{Camera, Isometry3};
use world::sequence::{Acquisition, Trajectory};

/// The acquired images of every frame in `needed` (others left empty), rendered at
/// the true poses and degraded ([`Acquisition::acquire`]).
pub fn acquire(
    cloud: &PointCloud,
    camera: &Camera,
    poses: &[Isometry3],
    trajectory: &Trajectory,
    acquisition: &Acquisition,
    needed: &[bool],
) -> anyhow::Result<Vec<Option<Image>>> {
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default())?;
    let mut frames = Vec::with_capacity(poses.len());
    for (k, pose) in poses.iter().enumerate() {
        if !needed[k] {
            frames.push(None);
            continue;
        }
        let mut frame = Frame::for_camera(camera);
        let stats = renderer.render(cloud, &pose.inverse(), &mut frame)?;
        if stats.pixels_hit == 0 {
            bail!("frame {k}: the camera sees no point of the cloud at its true pose");
        }
        frames.push(Some(acquisition.acquire(
            &frame,
            camera,
            k,
            trajectory.time_s(k),
        )?));
    }
    Ok(frames)
}
