//! Helpers of the pipeline tests: the city, renders, finite differences of the
//! render → feature pipeline.

use frame::Frame;
use glam::DVec3;
use splat::{RenderOptions, Renderer};
use ucm::Isometry3;
use world::city::camera_looking_down;

use crate::common::city;

/// A street-level pose in the city, 3 m above the road.
pub fn street_pose() -> Isometry3 {
    camera_looking_down(DVec3::new(-20.0, 0.8, 3.0), 0.05)
}

pub fn render(camera: &ucm::Camera, world_from_camera: &Isometry3) -> Frame {
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
    let mut frame = Frame::for_camera(camera);
    renderer
        .render(&city().cloud, &world_from_camera.inverse(), &mut frame)
        .unwrap();
    frame
}

/// Cosine similarity and relative error of two vectors.
pub fn compare(analytic: &[f64], numeric: &[f64]) -> (f64, f64) {
    let dot: f64 = analytic.iter().zip(numeric).map(|(a, b)| a * b).sum();
    let na = analytic.iter().map(|a| a * a).sum::<f64>().sqrt();
    let nb = numeric.iter().map(|b| b * b).sum::<f64>().sqrt();
    let diff = analytic
        .iter()
        .zip(numeric)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    (dot / (na * nb).max(1e-300), diff / nb.max(1e-300))
}

/// `(F(exp(ε v)) − F(exp(−ε v))) / 2ε` of a per-sample feature `F` of the rendering at
/// the pose moved by the twist `v` (camera frame).
pub fn pipeline_difference(
    camera: &ucm::Camera,
    world_from_camera: &Isometry3,
    v: [f64; 6],
    eps: f64,
    mut feature: impl FnMut(&Frame) -> Vec<f32>,
) -> Vec<f64> {
    let at = |s: f64| *world_from_camera * Isometry3::exp(v.map(|c| c * s)).unwrap();
    let plus = feature(&render(camera, &at(eps)));
    let minus = feature(&render(camera, &at(-eps)));
    plus.iter()
        .zip(&minus)
        .map(|(a, b)| (f64::from(*a) - f64::from(*b)) / (2.0 * eps))
        .collect()
}
