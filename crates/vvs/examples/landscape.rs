//! The PGM cost along one axis of the desired camera's frame, for several λ:
//! `cargo run --release -p vvs --example landscape -- <axis 0-5> <max offset> [λ...]`.
//! Prints `offset cost(λ1) cost(λ2) …` (mean squared residual, normalised by its value
//! at the largest offset), to see the width of the basin of the global minimum.

use glam::DVec3;
use pgm::{Pgm, PgmOptions};
use ucm::Isometry3;
use vvs::{Servo, VvsConfig};
use world::city::{City, CityParams, camera_looking_down};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let axis: usize = args.first().and_then(|s| s.parse().ok()).unwrap_or(0);
    let max: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10.0);
    let lambdas: Vec<f32> = if args.len() > 2 {
        args[2..].iter().filter_map(|s| s.parse().ok()).collect()
    } else {
        vec![5.0, 15.0, 30.0]
    };
    let city = City::generate(&CityParams::default())?;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let camera = ucm::Camera::load_toml(root.join("fixtures/omni-320x240.toml"))?;
    let mut servo = Servo::new(&city.cloud, &camera, VvsConfig::default())?;
    let mut pgm = Pgm::new(&camera, PgmOptions::default())?;
    let desired_pose = camera_looking_down(DVec3::new(-42.0, 0.5, 3.0), 0.0);
    let desired = servo.render(&desired_pose)?;
    let references: Vec<Vec<f32>> = lambdas
        .iter()
        .map(|&l| pgm.transform(&desired, l).map(|g| g.to_vec()))
        .collect::<Result<_, _>>()?;
    let steps = 40;
    println!(
        "offset_along_axis_{axis} {}",
        lambdas
            .iter()
            .map(|l| format!("cost_lambda{l}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    for k in 0..=steps {
        let s = -max + 2.0 * max * k as f64 / steps as f64;
        let mut r = [0.0; 6];
        r[axis] = if axis < 3 { s } else { s.to_radians() };
        let frame = servo.render(&(desired_pose * Isometry3::from_pose_vector(r)?))?;
        let costs: Vec<String> = lambdas
            .iter()
            .zip(&references)
            .map(|(&l, g_star)| {
                let g = pgm.transform(&frame, l).unwrap();
                let c: f64 = g
                    .iter()
                    .zip(g_star)
                    .map(|(a, b)| f64::from(a - b).powi(2))
                    .sum::<f64>()
                    / g.len() as f64;
                format!("{c:.4e}")
            })
            .collect();
        println!("{s:+.2} {}", costs.join(" "));
    }
    Ok(())
}
