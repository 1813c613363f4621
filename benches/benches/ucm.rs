//! `ucm` kernels: batch projection, point interaction matrices, and whole-image
//! interaction matrices from a precomputed pixel grid. Throughput in points (pixels)
//! per second.

use benches::{fixture_camera, points_around_camera};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use ucm::{OutOfView, PixelGrid};

fn batch(c: &mut Criterion) {
    let camera = fixture_camera("omni-640x480.toml");
    let n = 1 << 20;
    let points = points_around_camera(n, 7);
    let mut group = c.benchmark_group("ucm");
    group.throughput(Throughput::Elements(n as u64));
    group.sample_size(20);

    let mut pixels: Vec<Result<[f32; 2], OutOfView>> = vec![Err(OutOfView::OutsideImage); n];
    group.bench_function("project_batch/1M points", |b| {
        b.iter(|| {
            camera
                .project_batch(black_box(&points), &mut pixels)
                .unwrap()
        })
    });

    let mut matrices = vec![None; n];
    group.bench_function("interaction_batch/1M points", |b| {
        b.iter(|| {
            camera
                .interaction_batch(black_box(&points), &mut matrices)
                .unwrap()
        })
    });

    for name in ["omni-320x240.toml", "omni-640x480.toml"] {
        let camera = fixture_camera(name);
        let grid = PixelGrid::new(&camera);
        let pixels = camera.pixel_count();
        let inverse_range: Vec<f32> = (0..pixels).map(|i| 0.05 + (i % 97) as f32 * 0.01).collect();
        let mut out = vec![[[0.0f32; 6]; 2]; pixels];
        group.throughput(Throughput::Elements(pixels as u64));
        group.bench_function(format!("interaction_image/{}", camera.width()), |b| {
            b.iter(|| {
                grid.interaction_image(black_box(&inverse_range), &mut out)
                    .unwrap()
            })
        });
        group.bench_function(format!("pixel_grid_new/{}", camera.width()), |b| {
            b.iter(|| PixelGrid::new(black_box(&camera)))
        });
    }
    group.finish();
}

criterion_group!(benches, batch);
criterion_main!(benches);
