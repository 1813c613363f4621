//! Read cloud files and say what they hold and how long each step took: the file
//! decoded into points, then the points laid out for the renderer.
//!
//! ```sh
//! cargo run --release -p cloud-io --example read -- city.las city.laz city.ply city.e57
//! ```
//!
//! Peak memory: run one file at a time under `/usr/bin/time -v`.

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        return Err("usage: read FILE...".into());
    }
    for path in paths {
        let bytes = std::fs::metadata(&path)?.len();
        let started = Instant::now();
        let (points, info) = cloud_io::read_points(&path)?;
        let read_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let (cloud, source) = points.to_cloud(path.as_ref())?;
        let layout_s = started.elapsed().as_secs_f64();
        println!(
            "{path}: {} {:.1} MB, {} points, {:?}; decoded in {read_s:.2} s, laid out for \
             the renderer ({} points) in {layout_s:.2} s",
            info.format,
            bytes as f64 / 1e6,
            info.points,
            source,
            cloud.len(),
        );
    }
    Ok(())
}
