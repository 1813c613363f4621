//! What occlusion culling saves on five street poses of the synthetic city, at 320×240
//! on one thread: cells and points skipped, render time (best of 3 × 5 renders) with
//! and without it, and whether the frames are identical.
//! `cargo run --release -p benches --example occlusion`.

use frame::Frame;
use splat::{RenderOptions, Renderer};
use world::city::{City, CityParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let city = City::generate(&CityParams::default())?;
    let camera = benches::fixture_camera("omni-320x240.toml");
    let renderer = |occlusion_culling| {
        let options = RenderOptions {
            parallel: false,
            occlusion_culling,
            ..RenderOptions::default()
        };
        Renderer::new(camera.clone(), options)
    };
    let mut renderers = [renderer(false)?, renderer(true)?];
    let mut frames = [Frame::for_camera(&camera), Frame::for_camera(&camera)];
    for view in &benches::STREET_VIEWS[..5] {
        let pose = benches::camera_from_world(*view);
        let (x, y, z, _) = *view;
        let mut best_ms = [f64::MAX; 2];
        let mut stats = [Default::default(); 2];
        for _ in 0..3 {
            for (k, (renderer, frame)) in renderers.iter_mut().zip(&mut frames).enumerate() {
                let started = std::time::Instant::now();
                for _ in 0..5 {
                    stats[k] = renderer.render(&city.cloud, &pose, frame)?;
                }
                best_ms[k] = best_ms[k].min(started.elapsed().as_secs_f64() * 1e3 / 5.0);
            }
        }
        let [all, culled]: [splat::RenderStats; 2] = stats;
        println!(
            "camera at ({x}, {y}, {z}): {:.0} % of the cells and {:.0} % of the points skipped, \
             {:.1} ms -> {:.1} ms ({:+.0} %), identical frames: {}",
            100.0 * culled.cells_occluded as f64 / all.cells_drawn as f64,
            100.0 * (1.0 - culled.points_drawn as f64 / all.points_drawn as f64),
            best_ms[0],
            best_ms[1],
            100.0 * (best_ms[1] / best_ms[0] - 1.0),
            frames[0].bitwise_eq(&frames[1])
        );
    }
    Ok(())
}
