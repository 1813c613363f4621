//! `cloud-io`: what a user waits for before the first localisation (issue #36's goal,
//! this machine's cores): the synthetic city's 5.9 M points, written as LAZ by
//! `cloud_io::write_cloud` (16-bit colours), read back into the renderer's cloud with
//! `cloud_io::read_cloud` — decoded (LAZ chunks on every core) and laid out (cells,
//! packed points). Goal: 2 s. The file is read from the page cache (written just
//! before), as a second run of a user's command would; removed at the end.

use criterion::{Criterion, criterion_group, criterion_main};
use world::city::{City, CityParams};

fn goal_cloud_read(c: &mut Criterion) {
    let city = City::generate(&CityParams::default()).unwrap();
    let path = std::env::temp_dir().join(format!("pgm-bench-city-{}.laz", std::process::id()));
    cloud_io::write_cloud(&city.cloud, &path).unwrap();
    let (cloud, ..) = cloud_io::read_cloud(&path).unwrap();
    assert_eq!(cloud.len(), city.cloud.len(), "the city read back whole");
    println!(
        "{} points, {:.1} MB, {} threads",
        cloud.len(),
        std::fs::metadata(&path).unwrap().len() as f64 / 1e6,
        rayon::current_num_threads()
    );
    let mut group = c.benchmark_group("goal_cloud_read_le_2s");
    group.sample_size(10);
    group.measurement_time(std::time::Duration::from_secs(30));
    group.bench_function("city_laz/read_cloud", |b| {
        b.iter(|| cloud_io::read_cloud(&path).unwrap().0.len());
    });
    group.finish();
    std::fs::remove_file(&path).unwrap();
}

criterion_group!(benches, goal_cloud_read);
criterion_main!(benches);
