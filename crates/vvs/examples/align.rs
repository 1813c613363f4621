//! Align one initial pose to a desired one on the synthetic city and print the run:
//! `cargo run --release -p vvs --example align -- <method> <dx> <dy> <dz> <yaw_deg> [jacobian] [roll_deg] [pitch_deg] [camera]`
//! (offsets in the desired camera's frame, the paper's (t, θw); jacobian: convolved |
//! paper; camera: a file of fixtures/, default omni-320x240.toml).

use glam::DVec3;
use ucm::Isometry3;
use vvs::{Method, PgmJacobian, Servo, VvsConfig};
use world::city::{City, CityParams, camera_looking_down};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let method = match args.first().map(String::as_str) {
        Some("povs") => Method::Povs,
        Some("rule0") => Method::Rule0,
        Some("rule1") => Method::Rule1,
        _ => Method::Rule2,
    };
    let num = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let jacobian = match args.get(5).map(String::as_str) {
        Some("paper") => PgmJacobian::Paper { edge_margin: None },
        _ => PgmJacobian::Convolved,
    };
    let city = City::generate(&CityParams::default())?;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let camera_name = args.get(8).map_or("omni-320x240.toml", String::as_str);
    let camera = ucm::Camera::load_toml(root.join("fixtures").join(camera_name))?;
    let config = VvsConfig {
        jacobian,
        ..VvsConfig::default()
    };
    let mut servo = Servo::new(&city.cloud, &camera, config)?;
    let desired_pose = camera_looking_down(DVec3::new(-20.0, 0.5, 3.0), 0.0);
    let desired = servo.render(&desired_pose)?;
    let offset = Isometry3::from_pose_vector([
        num(1, 1.0),
        num(2, 0.0),
        num(3, 0.0),
        0.0,
        0.0,
        num(4, 0.0).to_radians(),
    ])?;
    let start = desired_pose * offset;
    let t = std::time::Instant::now();
    let outcome = servo.run(method, &desired, start)?;
    let (dt, dr) = outcome.world_from_camera.distance_to(&desired_pose);
    for r in outcome.history.iter().step_by(10) {
        let (et, er) = Isometry3::from_pose_vector(r.pose)?.distance_to(&desired_pose);
        println!(
            "stage {} λ {:6.2} cost {:.3e} err {:.4} m {:.3}° step {:.2e}",
            r.stage,
            r.lambda,
            r.cost,
            et,
            er.to_degrees(),
            r.update_translation_m
        );
    }
    println!(
        "{:?} {:?}: stop {:?}, iterations {:?}, final error {:.4} m {:.4}°, λ {:.2}, {:.1} ms/iteration",
        method,
        jacobian,
        outcome.stop,
        outcome.iterations,
        dt,
        dr.to_degrees(),
        outcome.lambda,
        t.elapsed().as_secs_f64() * 1e3
            / (outcome.iterations[0] + outcome.iterations[1]).max(1) as f64
    );
    Ok(())
}
