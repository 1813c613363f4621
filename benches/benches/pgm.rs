//! Jacobian kernels of the features, at 320×240 and 640×480, on a rendering of the
//! synthetic city: the PGM transform at λ = 1, 5, 15, 30; G + J_λ + L_G (Convolved and
//! Paper); the brightness feature with L_I; the 7×7 normal equations. Throughput in
//! pixels per second (megapixels/s). `reference/*` is the straightforward
//! implementation of eq. (1), a window sum per sample (radius 4λ), for comparison.

use benches::fixture_camera;
use brightness::{Brightness, normal_equations};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frame::Frame;
use glam::DVec3;
use pgm::{Pgm, PgmJacobian, PgmOptions};
use splat::{RenderOptions, Renderer};
use std::hint::black_box;
use world::city::{City, CityParams, camera_looking_down};

/// Eq. (1) literally: for each sample, the window sum over `|d| ≤ 4λ`.
fn reference_pgm(image: &[f32], width: usize, height: usize, lambda: f32, out: &mut [f32]) {
    let r = (4.0 * lambda).ceil() as isize;
    let inv = 1.0 / (2.0 * lambda * lambda);
    for j in 0..height as isize {
        for i in 0..width as isize {
            let mut sum = 0.0f32;
            for dj in -r..=r {
                let y = j + dj;
                if y < 0 || y >= height as isize {
                    continue;
                }
                for di in -r..=r {
                    let x = i + di;
                    if x < 0 || x >= width as isize {
                        continue;
                    }
                    sum += image[y as usize * width + x as usize]
                        * (-((di * di + dj * dj) as f32) * inv).exp();
                }
            }
            out[j as usize * width + i as usize] = sum;
        }
    }
}

/// The fixture camera `name` and its rendering of the city from `pose`.
fn street_view(city: &City, pose: &ucm::Isometry3, name: &str) -> (ucm::Camera, Frame) {
    let camera = fixture_camera(name);
    let mut renderer = Renderer::new(camera.clone(), RenderOptions::default()).unwrap();
    let mut frame = Frame::for_camera(&camera);
    renderer.render(&city.cloud, pose, &mut frame).unwrap();
    (camera, frame)
}

fn features(c: &mut Criterion) {
    let city = City::generate(&CityParams::default()).unwrap();
    let pose = camera_looking_down(DVec3::new(-20.0, 0.8, 3.0), 0.05).inverse();
    let mut group = c.benchmark_group("features");
    group.sample_size(10);
    for name in ["omni-320x240.toml", "omni-640x480.toml"] {
        let (camera, frame) = street_view(&city, &pose, name);
        let w = camera.width();
        group.throughput(Throughput::Elements(camera.pixel_count() as u64));
        let mut pgm = Pgm::new(&camera, PgmOptions::default()).unwrap();
        for lambda in [1.0f32, 5.0, 15.0, 30.0] {
            group.bench_function(format!("pgm_transform/{w}/lambda{lambda}"), |b| {
                b.iter(|| black_box(pgm.transform(&frame, lambda).unwrap().len()))
            });
        }
        group.bench_function(format!("pgm_g_jlambda_lg_convolved/{w}/lambda15"), |b| {
            b.iter(|| pgm.compute(&frame, 15.0, PgmJacobian::Convolved).unwrap())
        });
        group.bench_function(format!("pgm_g_jlambda_lg_paper/{w}/lambda15"), |b| {
            b.iter(|| {
                pgm.compute(&frame, 15.0, PgmJacobian::Paper { edge_margin: None })
                    .unwrap()
            })
        });
        let mut strided = Pgm::new(
            &camera,
            PgmOptions {
                stride: 4,
                ..PgmOptions::default()
            },
        )
        .unwrap();
        group.bench_function(
            format!("pgm_g_jlambda_lg_convolved_stride4/{w}/lambda15"),
            |b| {
                b.iter(|| {
                    strided
                        .compute(&frame, 15.0, PgmJacobian::Convolved)
                        .unwrap()
                })
            },
        );
        let mut feature = Brightness::new(&camera);
        group.bench_function(format!("brightness_li/{w}"), |b| {
            b.iter(|| feature.compute(&frame).unwrap())
        });

        // Normal equations of the PGM rows [L_G | J_λ] (7 columns).
        pgm.compute(&frame, 15.0, PgmJacobian::Convolved).unwrap();
        let rows: Vec<[f32; 7]> = pgm
            .interaction()
            .iter()
            .zip(pgm.j_lambda())
            .map(|(l, &j)| [l[0], l[1], l[2], l[3], l[4], l[5], j])
            .collect();
        let e: Vec<f32> = pgm.values().iter().map(|v| v * 0.01).collect();
        group.bench_function(format!("normal_equations_7/{w}"), |b| {
            b.iter(|| black_box(normal_equations::<7>(&rows, &e, None)))
        });
        // The reference window sum (λ = 1 and 5; λ = 15 takes seconds per image).
        let image = feature.image().to_vec();
        let mut out = vec![0.0f32; image.len()];
        for lambda in [1.0f32, 5.0] {
            group.bench_function(
                format!("reference_pgm_window_sum/{w}/lambda{lambda}"),
                |b| {
                    b.iter(|| {
                        reference_pgm(
                            &image,
                            w as usize,
                            camera.height() as usize,
                            lambda,
                            &mut out,
                        )
                    })
                },
            );
        }
    }
    group.finish();
}

/// Issue #18's goal for the features: G + J_λ + L_G (Convolved) in at most 2 ms at
/// 320×240 and 6 ms at 640×480 on one core, nearly independent of λ in [1, 40]. One
/// thread (`parallel: false`), the default filters (recursive from λ = 3; `L_G`'s
/// vertical pass keeping one row in ⌊0.2 λ⌋, interpolated), and for comparison at
/// λ = 15 every row kept, and the exact truncated kernels.
fn goal_features(c: &mut Criterion) {
    let city = City::generate(&CityParams::default()).unwrap();
    let pose = camera_looking_down(DVec3::new(-20.0, 0.8, 3.0), 0.05).inverse();
    let mut group = c.benchmark_group("goal_features_le_2ms_320_le_6ms_640");
    group.sample_size(20);
    for (name, bound_ms) in [("omni-320x240.toml", 2), ("omni-640x480.toml", 6)] {
        let (camera, frame) = street_view(&city, &pose, name);
        let w = camera.width();
        group.throughput(Throughput::Elements(camera.pixel_count() as u64));
        let one_thread = PgmOptions {
            parallel: false,
            ..PgmOptions::default()
        };
        let mut pgm = Pgm::new(&camera, one_thread).unwrap();
        for lambda in [1.0f32, 3.0, 5.0, 15.0, 40.0] {
            group.bench_function(
                format!("g_jlambda_lg_convolved/{w}/lambda{lambda}/bound_{bound_ms}ms"),
                |b| b.iter(|| pgm.compute(&frame, lambda, PgmJacobian::Convolved).unwrap()),
            );
        }
        let every_row = PgmOptions {
            interaction_row_step_lambdas: 0.0,
            ..one_thread
        };
        let mut every = Pgm::new(&camera, every_row).unwrap();
        group.bench_function(format!("every_row/{w}/lambda15"), |b| {
            b.iter(|| every.compute(&frame, 15.0, PgmJacobian::Convolved).unwrap())
        });
        let mut exact = Pgm::new(
            &camera,
            PgmOptions {
                recursive_from_lambda: f32::INFINITY,
                ..one_thread
            },
        )
        .unwrap();
        group.bench_function(format!("exact_kernels/{w}/lambda15"), |b| {
            b.iter(|| exact.compute(&frame, 15.0, PgmJacobian::Convolved).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, features, goal_features);
criterion_main!(benches);
