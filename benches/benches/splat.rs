//! `splat`: rendering the synthetic city (about 1 M and 6 M points) at 320×240 and
//! 640×480 from street level, with and without level of detail, 1 and 2 threads.
//! Throughput in points of the cloud per second.

use benches::fixture_camera;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frame::Frame;
use glam::DVec3;
use splat::{RenderOptions, Renderer};
use world::city::{City, CityParams, camera_looking_down};

fn render(c: &mut Criterion) {
    let mut group = c.benchmark_group("splat");
    group.sample_size(10);
    let pose = camera_looking_down(DVec3::new(-20.0, 0.5, 3.0), 0.1).inverse();
    for (label, spacing_m) in [("1M", 0.12), ("6M", 0.05)] {
        let city = City::generate(&CityParams {
            spacing_m,
            ..CityParams::default()
        })
        .unwrap();
        eprintln!("city {label}: {} points", city.cloud.len());
        group.throughput(Throughput::Elements(city.cloud.len() as u64));
        for camera_name in ["omni-320x240.toml", "omni-640x480.toml"] {
            let camera = fixture_camera(camera_name);
            for (lod_label, lod) in [("lod", Some(0.5)), ("all", None)] {
                for threads in [1, 2] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let options = RenderOptions {
                        lod_spacing_px: lod,
                        ..RenderOptions::default()
                    };
                    let mut renderer = Renderer::new(camera.clone(), options).unwrap();
                    let mut frame = Frame::for_camera(&camera);
                    let name = format!("{label}/{}/{lod_label}/{threads}t", camera.width());
                    group.bench_function(name, |b| {
                        pool.install(|| {
                            b.iter(|| renderer.render(&city.cloud, &pose, &mut frame).unwrap())
                        })
                    });
                }
            }
        }
    }
    group.finish();
}

/// Issue #18's goal for the renderer: at least 100 M drawn points per second on one
/// core at the default level of detail. Throughput in points drawn (after culling and
/// level of detail, `RenderStats::points_drawn`) per second, the default city from the
/// street, one thread.
fn goal_render(c: &mut Criterion) {
    let mut group = c.benchmark_group("goal_render_ge_100M_drawn_points_per_s");
    group.sample_size(20);
    let city = City::generate(&CityParams::default()).unwrap();
    let pose = camera_looking_down(DVec3::new(-20.0, 0.5, 3.0), 0.1).inverse();
    for camera_name in ["omni-320x240.toml", "omni-640x480.toml"] {
        let camera = fixture_camera(camera_name);
        let options = RenderOptions {
            parallel: false,
            ..RenderOptions::default()
        };
        let mut renderer = Renderer::new(camera.clone(), options).unwrap();
        let mut frame = Frame::for_camera(&camera);
        let drawn = renderer
            .render(&city.cloud, &pose, &mut frame)
            .unwrap()
            .points_drawn;
        group.throughput(Throughput::Elements(drawn as u64));
        group.bench_function(format!("default_lod/{}", camera.width()), |b| {
            b.iter(|| renderer.render(&city.cloud, &pose, &mut frame).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, render, goal_render);
criterion_main!(benches);
