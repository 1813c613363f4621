//! How far a rendering is from the pixel-integrated image, and what it costs: for a
//! level of detail and splat size, renders seven street views of the synthetic city at
//! 320×240 on one thread and compares them with a reference drawn at 4× the resolution
//! from every point (larger splats allowed) and averaged over 4×4 blocks.
//! `cargo run --release -p splat --example lod -- [LOD_SPACING_PX|all] [SPLAT_SCALE]`
//! (defaults: the renderer's, 0.65 px and 1.25; from the workspace root).

mod common;

use frame::{Frame, PixelStatus};
use splat::{RenderOptions, Renderer};
use world::city::{City, CityParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let defaults = RenderOptions::default();
    let lod_spacing_px = match args.next().as_deref() {
        None => defaults.lod_spacing_px,
        Some("all") => None,
        Some(s) => Some(s.parse()?),
    };
    let splat_scale = args
        .next()
        .map_or(Ok(defaults.splat_scale), |s| s.parse())?;
    let options = RenderOptions {
        lod_spacing_px,
        splat_scale,
        parallel: false,
        ..defaults
    };

    let city = City::generate(&CityParams::default())?;
    let camera = ucm::Camera::load_toml("fixtures/omni-320x240.toml")?;
    let fine = camera.rescaled(4)?;
    let mut reference = Renderer::new(
        fine.clone(),
        RenderOptions {
            lod_spacing_px: None,
            max_splat_radius_px: 40,
            // Fixed, whatever the defaults: the reference of every row in RESULTS.md.
            splat_scale: 1.5,
            ..defaults
        },
    )?;
    let mut renderer = Renderer::new(camera.clone(), options)?;
    let (mut fine_frame, mut frame) = (Frame::for_camera(&fine), Frame::for_camera(&camera));
    println!("lod_spacing_px {lod_spacing_px:?}, splat_scale {splat_scale}");
    println!("pose | points drawn | time (best of 5) | mean |I - I_ref| | pixels hit in one only");
    let (mut total_points, mut total_ms, mut total_err, mut total_n) = (0, 0.0, 0.0, 0);
    for view in common::STREET_VIEWS {
        let pose = common::camera_from_world(view);
        let (x, y, z, _) = view;
        reference.render(&city.cloud, &pose, &mut fine_frame)?;
        let truth = fine_frame.downsampled(4, &camera)?;
        let mut best_ms = f64::MAX;
        let mut stats = Default::default();
        for _ in 0..5 {
            let started = std::time::Instant::now();
            stats = renderer.render(&city.cloud, &pose, &mut frame)?;
            best_ms = best_ms.min(started.elapsed().as_secs_f64() * 1e3);
        }
        let (mut err, mut n, mut mismatched) = (0.0f64, 0usize, 0usize);
        for k in 0..frame.intensity.len() {
            match (truth.status[k], frame.status[k]) {
                (PixelStatus::Hit, PixelStatus::Hit) => {
                    err += f64::from((frame.intensity[k] - truth.intensity[k]).abs());
                    n += 1;
                }
                (PixelStatus::Hit, _) | (_, PixelStatus::Hit) => mismatched += 1,
                _ => {}
            }
        }
        println!(
            "({x}, {y}, {z}) | {} | {best_ms:.1} ms | {:.4} | {mismatched}",
            stats.points_drawn,
            err / n.max(1) as f64
        );
        total_points += stats.points_drawn;
        total_ms += best_ms;
        total_err += err;
        total_n += n;
    }
    println!(
        "mean | {} | {:.1} ms | {:.4} |",
        total_points / 7,
        total_ms / 7.0,
        total_err / total_n.max(1) as f64
    );
    Ok(())
}
