//! The PGM of the real catadioptric image of `../shared/data` (the paper's Fig. 1).

use bench_conv::real_image::write_pgm_images;
use frame::Image;
use pgm::{Pgm, PgmOptions};
use test_support::data_dir;

/// Mean absolute difference between horizontal neighbours, relative to the mean.
fn roughness(values: &[f32], samples: &[u32], width: usize) -> f64 {
    let mut map = std::collections::HashMap::new();
    for (&k, &v) in samples.iter().zip(values) {
        map.insert(k as usize, f64::from(v));
    }
    let (mut diff, mut n, mut sum) = (0.0, 0usize, 0.0);
    for (&k, &v) in &map {
        sum += v;
        if k % width + 1 < width
            && let Some(&r) = map.get(&(k + 1))
        {
            diff += (r - v).abs();
            n += 1;
        }
    }
    (diff / n as f64) / (sum / map.len() as f64)
}

#[test]
fn pgm_of_the_real_catadioptric_image_smooths_with_lambda() {
    let Some(data) = data_dir() else { return };
    let calib = data.join("catadioptric/omniunwarp-mei.yaml");
    let probe = ucm::Camera::load_mei_yaml(&calib, 1230, 1000, ucm::ValidRegion::Full).unwrap();
    let i = *probe.intrinsics();
    let camera = probe
        .with_region(ucm::ValidRegion::Annulus(ucm::Annulus {
            center_px: [i.u0, i.v0],
            inner_radius_px: 30.0,
            outer_radius_px: 470.0,
        }))
        .unwrap();
    let frame = Image::load(
        data.join("catadioptric/omniunwarp-example.jpg"),
        &camera,
        Some([310, 80, 1230, 1000]),
    )
    .unwrap();
    let hits = frame.valid_count();
    assert!(hits > 600_000, "{hits}");
    let mut pgm = Pgm::new(&camera, PgmOptions::default()).unwrap();
    let mut last = f64::INFINITY;
    for lambda in [1.0f32, 5.0, 15.0] {
        pgm.transform(&frame, lambda).unwrap();
        let r = roughness(pgm.values(), pgm.samples(), 1230);
        assert!(r < last, "λ {lambda}: roughness {r} not below {last}");
        last = r;
    }
    let out = std::env::temp_dir().join(format!("bench-conv-fig1-{}", std::process::id()));
    let files = write_pgm_images(&frame, &camera, &[1.0, 15.0], &out).unwrap();
    assert_eq!(files.len(), 4); // input, two λ, the montage
    for f in &files {
        assert!(f.metadata().unwrap().len() > 1000, "{}", f.display());
    }
    // A crop that does not match the camera is an error.
    assert!(
        Image::load(
            data.join("catadioptric/omniunwarp-example.jpg"),
            &camera,
            Some([0, 0, 100, 100]),
        )
        .is_err()
    );
    std::fs::remove_dir_all(&out).unwrap();
}
