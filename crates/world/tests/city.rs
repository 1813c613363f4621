//! The city: deterministic, validated, textured, and its ablation switches.

use frame::{Frame, PixelStatus};
use glam::DVec3;
use splat::{RenderOptions, Renderer};
use test_support::{data_dir, workspace_root as root};
use world::{City, CityParams, camera_looking_down};

fn fixture(name: &str) -> ucm::Camera {
    ucm::Camera::load_toml(root().join("fixtures").join(name)).unwrap()
}

#[test]
fn city_is_deterministic_and_validated() {
    let params = CityParams {
        arm_length_m: 15.0,
        spacing_m: 0.2,
        ..CityParams::default()
    };
    let a = City::generate(&params).unwrap();
    let b = City::generate(&params).unwrap();
    assert_eq!(a.cloud.points(), b.cloud.points());
    assert_eq!(a.cloud.colors(), b.cloud.colors());
    let c = City::generate(&CityParams {
        seed: 2,
        ..params.clone()
    })
    .unwrap();
    assert_ne!(a.cloud.points(), c.cloud.points());
    // Another sampling of the same surfaces: other points, (nearly) the same image;
    // another seed: another city.
    let resampled = City::generate(&CityParams {
        sampling_seed: Some(7),
        ..params.clone()
    })
    .unwrap();
    assert_ne!(a.cloud.points(), resampled.cloud.points());
    let camera = fixture("omni-320x240.toml");
    let pose = camera_looking_down(DVec3::new(-8.0, 0.5, 3.0), 0.0);
    let image = |city: &City| {
        let mut frame = Frame::for_camera(&camera);
        Renderer::new(camera.clone(), RenderOptions::default())
            .unwrap()
            .render(&city.cloud, &pose.inverse(), &mut frame)
            .unwrap();
        frame
    };
    let mean_abs_diff = |x: &Frame, y: &Frame| {
        let pairs: Vec<(f32, f32)> = (0..x.intensity.len())
            .filter(|&i| x.status[i] == PixelStatus::Hit && y.status[i] == PixelStatus::Hit)
            .map(|i| (x.intensity[i], y.intensity[i]))
            .collect();
        pairs.iter().map(|(p, q)| (p - q).abs()).sum::<f32>() / pairs.len() as f32
    };
    let (base, same, other) = (image(&a), image(&resampled), image(&c));
    let (d_same, d_other) = (mean_abs_diff(&base, &same), mean_abs_diff(&base, &other));
    eprintln!("mean |ΔI|: resampled {d_same:.4}, other seed {d_other:.4}");
    assert!(
        d_same > 0.0 && d_same < 0.5 * d_other,
        "{d_same} vs {d_other}"
    );
    for bad in [
        CityParams {
            spacing_m: 0.0,
            ..params.clone()
        },
        CityParams {
            spacing_m: f64::NAN,
            ..params.clone()
        },
        CityParams {
            street_width_m: 2.0,
            ..params.clone()
        },
        CityParams {
            texture_dir: Some("/nonexistent/textures".into()),
            ..params.clone()
        },
        // The old documented minimum: 590 million points, refused at once.
        CityParams {
            spacing_m: 0.005,
            ..CityParams::default()
        },
        // Arms of 500 m every 2 cm: about 310 million points.
        CityParams {
            spacing_m: 0.02,
            arm_length_m: 500.0,
            ..CityParams::default()
        },
    ] {
        let started = std::time::Instant::now();
        let message = City::generate(&bad).unwrap_err().to_string();
        assert!(
            started.elapsed().as_secs_f64() < 1.0,
            "{bad:?}: refused late"
        );
        eprintln!("{message}");
    }
    // Range errors say the range.
    let message = City::generate(&CityParams {
        street_width_m: 2.0,
        ..params.clone()
    })
    .unwrap_err()
    .to_string();
    assert!(message.contains("[4, 60] m"), "{message}");
}

/// Photographic textures from a folder change the city's appearance, not its geometry.
#[test]
fn image_textures_modulate_the_city() {
    let Some(data) = data_dir() else { return };
    let params = CityParams {
        arm_length_m: 15.0,
        spacing_m: 0.2,
        ..CityParams::default()
    };
    let plain = City::generate(&params).unwrap();
    let textured = City::generate(&CityParams {
        texture_dir: Some(data.join("textures")),
        ..params
    })
    .unwrap();
    assert_eq!(plain.cloud.len(), textured.cloud.len());
    let differ = plain
        .cloud
        .points()
        .iter()
        .zip(textured.cloud.points())
        .filter(|(a, b)| a.intensity != b.intensity)
        .count();
    assert!(differ > plain.cloud.len() / 4, "{differ}");
}

/// The ablation switches: without clutter the city loses points and keeps every facade
/// and ground point; without facade detail every building is a plain wall (fewer
/// distinct colours), and the ground is untouched.
#[test]
fn city_ablation_switches_remove_what_they_say() {
    let params = CityParams {
        arm_length_m: 15.0,
        spacing_m: 0.2,
        ..CityParams::default()
    };
    let full = City::generate(&params).unwrap();
    let bare = City::generate(&CityParams {
        clutter: false,
        ..params.clone()
    })
    .unwrap();
    assert!(bare.cloud.len() < full.cloud.len());
    // Clutter is drawn last: the rest of the city is the same point for point.
    let kept = |city: &City| {
        let mut points: Vec<[u64; 3]> = city
            .cloud
            .decoded()
            .map(|(p, _)| p.to_array().map(f64::to_bits))
            .collect();
        points.sort_unstable();
        points
    };
    let (full_points, bare_points) = (kept(&full), kept(&bare));
    assert!(
        bare_points
            .iter()
            .all(|p| full_points.binary_search(p).is_ok())
    );
    let plain = City::generate(&CityParams {
        facade_detail: false,
        ..params.clone()
    })
    .unwrap();
    let colours = |city: &City| {
        let mut c: Vec<[u8; 3]> = city.cloud.colors().unwrap().to_vec();
        c.sort_unstable();
        c.dedup();
        c.len()
    };
    assert!(
        colours(&plain) < colours(&full) / 2,
        "{} vs {}",
        colours(&plain),
        colours(&full)
    );
}
