//! How far a rendering is from the pixel-integrated image, and what it costs: for a
//! level of detail and splat size, renders seven street views of the synthetic city at
//! 320×240 on one thread and compares them with a reference drawn at 4× the resolution
//! from every point (larger splats allowed) and averaged over 4×4 blocks: the mean
//! intensity error, the pixels hit in one image only, the mean gradient magnitude
//! (pixel-scale texture; the reference's in parentheses) and the RMS error of the
//! PGM `G(λ)` at λ = 1, 5, 15 relative to the RMS variation of the reference's.
//! `cargo run --release -p benches --example lod -- [LOD_SPACING_PX|all] [SPLAT_SCALE]`
//! (defaults: the renderer's, 0.65 px and 1.25).

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
    let camera = benches::fixture_camera("omni-320x240.toml");
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
    let mut pgm = pgm::Pgm::new(
        &camera,
        pgm::PgmOptions {
            parallel: false,
            ..pgm::PgmOptions::default()
        },
    )?;
    println!("lod_spacing_px {lod_spacing_px:?}, splat_scale {splat_scale}");
    println!(
        "pose | points drawn | time (best of 5) | mean |I - I_ref| | pixels hit in one only | \
         mean |grad I| (reference) | relative RMS error of G at lambda = 1, 5, 15"
    );
    let (mut total_points, mut total_ms, mut total_err, mut total_n) = (0, 0.0, 0.0, 0);
    let (mut total_grad, mut total_grad_ref) = (0.0, 0.0);
    let (mut g_err, mut g_var) = ([0.0f64; 3], [0.0f64; 3]);
    for view in benches::STREET_VIEWS {
        let pose = benches::camera_from_world(view);
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
        let (grad, grad_ref) = (mean_gradient(&frame), mean_gradient(&truth));
        let mut g_view = [0.0; 3];
        for (k, lambda) in [1.0f32, 5.0, 15.0].into_iter().enumerate() {
            let reference = pgm.transform(&truth, lambda)?.to_vec();
            let g = pgm.transform(&frame, lambda)?;
            let mean = reference.iter().map(|&v| f64::from(v)).sum::<f64>()
                / reference.len().max(1) as f64;
            let e: f64 = g
                .iter()
                .zip(&reference)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum();
            let v: f64 = reference
                .iter()
                .map(|&b| (f64::from(b) - mean).powi(2))
                .sum();
            g_view[k] = (e / v.max(f64::MIN_POSITIVE)).sqrt();
            g_err[k] += e;
            g_var[k] += v;
        }
        println!(
            "({x}, {y}, {z}) | {} | {best_ms:.1} ms | {:.4} | {mismatched} | {grad:.4} ({grad_ref:.4}) | \
             {:.4}, {:.4}, {:.4}",
            stats.points_drawn,
            err / n.max(1) as f64,
            g_view[0],
            g_view[1],
            g_view[2]
        );
        total_grad += grad;
        total_grad_ref += grad_ref;
        total_points += stats.points_drawn;
        total_ms += best_ms;
        total_err += err;
        total_n += n;
    }
    let relative = |k: usize| (g_err[k] / g_var[k].max(f64::MIN_POSITIVE)).sqrt();
    println!(
        "mean | {} | {:.1} ms | {:.4} | | {:.4} ({:.4}) | {:.4}, {:.4}, {:.4}",
        total_points / 7,
        total_ms / 7.0,
        total_err / total_n.max(1) as f64,
        total_grad / 7.0,
        total_grad_ref / 7.0,
        relative(0),
        relative(1),
        relative(2)
    );
    Ok(())
}

/// Mean magnitude of the central-difference gradient over the pixels hit whose four
/// neighbours are hit too.
fn mean_gradient(frame: &Frame) -> f64 {
    let w = frame.width() as usize;
    let hit = |k: usize| frame.status[k] == PixelStatus::Hit;
    let (mut sum, mut n) = (0.0, 0usize);
    for k in w + 1..frame.intensity.len().saturating_sub(w + 1) {
        if hit(k) && hit(k - 1) && hit(k + 1) && hit(k - w) && hit(k + w) {
            let gx = f64::from(frame.intensity[k + 1] - frame.intensity[k - 1]) * 0.5;
            let gy = f64::from(frame.intensity[k + w] - frame.intensity[k - w]) * 0.5;
            sum += gx.hypot(gy);
            n += 1;
        }
    }
    sum / n.max(1) as f64
}
