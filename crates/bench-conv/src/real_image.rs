//! The PGM of a real catadioptric image at several λ (the paper's Fig. 1), so that
//! users see the transform on a real picture.

use std::path::{Path, PathBuf};

use anyhow::Context;
use frame::Image;
use pgm::{Pgm, PgmOptions};
use ucm::Camera;

/// Write `input.png`, `pgm-lambda<λ>.png` (each scaled to its own maximum, masked
/// pixels black) and `fig1.png` (all of them side by side, at most 320 pixels wide each)
/// under `out`; returns the written files.
pub fn write_pgm_images(
    image: &Image,
    camera: &Camera,
    lambdas: &[f32],
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut written = Vec::new();
    let input = out.join("input.png");
    image.save_png(&input)?;
    written.push(input);
    let mut pgm = Pgm::new(camera, PgmOptions::default())?;
    for &lambda in lambdas {
        pgm.transform(image, lambda)?;
        let g = pgm.values();
        let max = g.iter().copied().fold(f32::MIN_POSITIVE, f32::max);
        let mut shown = image.clone();
        for (&k, &v) in pgm.samples().iter().zip(g) {
            shown.intensity[k as usize] = v / max;
        }
        let path = out.join(format!("pgm-lambda{lambda}.png"));
        shown.save_png(&path)?;
        written.push(path);
    }
    // The panels side by side.
    let scale = (320.0 / camera.width() as f32).min(1.0);
    let (w, h) = (
        ((camera.width() as f32 * scale) as u32).max(1),
        ((camera.height() as f32 * scale) as u32).max(1),
    );
    let mut montage = image::GrayImage::new(w * written.len() as u32, h);
    for (i, path) in written.iter().enumerate() {
        let panel = image::open(path)
            .with_context(|| format!("reading {}", path.display()))?
            .into_luma8();
        let small = image::imageops::resize(&panel, w, h, image::imageops::FilterType::Triangle);
        image::imageops::overlay(&mut montage, &small, i64::from(i as u32 * w), 0);
    }
    let path = out.join("fig1.png");
    montage
        .save(&path)
        .with_context(|| format!("writing {}", path.display()))?;
    written.push(path);
    Ok(written)
}
