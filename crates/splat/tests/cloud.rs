//! The packed storage of a cloud: every point decodes to where it was given, to half a
//! step, with its intensity to half of the 16-bit fixed point.

use std::collections::HashMap;

use glam::DVec3;
use splat::PointCloud;

/// 20 000 points on a 1 cm lattice (offset by 3 mm, so that every decoded point
/// rounds back to its lattice node) in a 30 × 30 × 8 m box far from the origin of
/// the world, with random intensities: each decodes within half a step (in every cell
/// size) of its position, and its intensity within half of 1/65 535; every cell's
/// sphere holds its points, the cloud's origin near them or 580 km away (where the
/// centres' `f32` rounding exceeds a millimetre); its bounds are the decoded points'.
/// Cells under a millimetre are refused.
#[test]
fn points_decode_to_half_a_step() {
    let origin = DVec3::new(651_234.5, 6_862_345.25, 40.0);
    let mut rng = splat::rng::SplitMix64::new(11);
    let mut given: HashMap<[i64; 3], (DVec3, f32)> = HashMap::new();
    while given.len() < 20_000 {
        let node = [3000, 3000, 800].map(|n| rng.below(n) as i64);
        let p = DVec3::new(node[0] as f64, node[1] as f64, node[2] as f64) * 0.01 + 0.003;
        given.insert(node, (origin + p, rng.unit() as f32));
    }
    let (positions, intensities): (Vec<DVec3>, Vec<f32>) = given.values().copied().unzip();
    let far = origin - DVec3::new(5e5, 3e5, 0.0);
    for (cloud_origin, cell_size_m) in [(origin, 0.5), (origin, 2.0), (origin, 10.0), (far, 2.0)] {
        let cloud = PointCloud::build(
            cloud_origin,
            &positions,
            &intensities,
            None,
            Some(0.01),
            cell_size_m,
        )
        .unwrap();
        assert_eq!(cloud.len(), given.len());
        let half_step = cloud.step_m() * 0.5 + 1e-9;
        assert!((cloud.step_m() - f64::from(cell_size_m) / 65_535.0).abs() < 1e-15);
        for (i, (p, intensity)) in cloud.decoded().enumerate() {
            let node = ((cloud_origin + p - origin - 0.003) / 0.01)
                .round()
                .to_array()
                .map(|c| c as i64);
            let (want, want_intensity) = given[&node];
            let error = (cloud_origin + p - want).abs().max_element();
            assert!(error <= half_step, "point {i}: {error:e} m off");
            assert!((intensity - want_intensity).abs() <= 0.5 / 65_535.0 + 1e-7);
            assert_eq!(cloud.point(i), Some((p, intensity)));
            assert_eq!(cloud.world_position(i), cloud_origin + p);
        }
        assert_eq!(cloud.point(cloud.len()), None);
        // The bounds (kept from the build) are those of the decoded points.
        let (lo, hi) = cloud.decoded().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), (p, _)| (lo.min(p), hi.max(p)),
        );
        assert_eq!(cloud.bounds(), (cloud_origin + lo, cloud_origin + hi));
        // Every cell's bounding sphere holds its decoded points.
        for cell in cloud.cells() {
            let center = DVec3::from_array(cell.center.map(f64::from));
            for i in cell.start..cell.start + cell.len {
                let (p, _) = cloud.point(i as usize).unwrap();
                assert!((p - center).length() <= f64::from(cell.radius));
            }
        }
    }
    assert!(matches!(
        PointCloud::build(origin, &positions, &intensities, None, Some(0.01), 1e-4),
        Err(splat::SplatError::Parameter {
            name: "cell_size_m",
            ..
        })
    ));
}

/// The generator's values taken by index (as the cloud's shuffle takes them on several
/// threads) are its sequence.
#[test]
fn the_generators_values_by_index_are_its_sequence() {
    for seed in [0, 17, 0x5EED_CE11, u64::MAX] {
        let mut rng = splat::rng::SplitMix64::new(seed);
        for index in 0..1000 {
            assert_eq!(
                splat::rng::SplitMix64::nth_value(seed, index),
                rng.next_u64()
            );
        }
    }
}

/// A thinned cloud keeps each cell's first `⌈len / k⌉` points, where they were (to half
/// a step of either layout), with their intensities and colours, in cells of the new
/// size, spaced `√k` times wider (one in one, in the same cells: every point, in the
/// same cells, shuffled again; one in more than any cell holds: one a cell).
/// Keeping none, or cells of no size, is refused.
#[test]
fn a_thinned_cloud_keeps_each_cells_first_points() {
    let mut rng = splat::rng::SplitMix64::new(5);
    let n = 30_000;
    let positions: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.unit() * 40.0, rng.unit() * 12.0, rng.unit() * 6.0))
        .collect();
    let intensities: Vec<f32> = (0..n).map(|_| rng.unit() as f32).collect();
    let colors: Vec<[u8; 3]> = (0..n).map(|i| [i as u8, (i >> 8) as u8, 7]).collect();
    let origin = DVec3::new(-1.0, -2.0, 0.0);
    let cloud = PointCloud::build(
        origin,
        &positions,
        &intensities,
        Some(colors),
        Some(0.05),
        2.0,
    )
    .unwrap();
    let same = cloud.thinned(1, 2.0).unwrap();
    assert_eq!(
        (same.len(), same.cells().len()),
        (cloud.len(), cloud.cells().len())
    );
    assert_eq!(same.spacing_m(), cloud.spacing_m());

    let thinned = cloud.thinned(8, 4.0).unwrap();
    let expected: Vec<usize> = cloud
        .cells()
        .iter()
        .flat_map(|c| c.start as usize..(c.start + c.len.div_ceil(8)) as usize)
        .collect();
    assert_eq!(thinned.len(), expected.len());
    assert!((thinned.spacing_m() - 0.05 * 8f32.sqrt()).abs() < 1e-6);
    assert!((thinned.step_m() - 4.0 / 65_535.0).abs() < 1e-15);
    assert!(thinned.cells().len() < cloud.cells().len());
    // Every kept point once, at its place (to the two layouts' half steps), with its
    // intensity.
    let tolerance = cloud.step_m() * 0.5 + thinned.step_m() * 0.5 + 1e-9;
    let mut wanted: Vec<_> = expected
        .iter()
        .map(|&i| {
            let (p, v) = cloud.point(i).unwrap();
            (p, v, cloud.colors().unwrap()[i])
        })
        .collect();
    let mut got: Vec<_> = (0..thinned.len())
        .map(|i| {
            let (p, v) = thinned.point(i).unwrap();
            (p, v, thinned.colors().unwrap()[i])
        })
        .collect();
    // Each point's colour tells it apart (its index in the input, in two bytes).
    wanted.sort_by_key(|w| w.2);
    got.sort_by_key(|g| g.2);
    for (w, g) in wanted.iter().zip(&got) {
        assert!((w.0 - g.0).abs().max_element() <= tolerance, "{w:?} {g:?}");
        assert_eq!((w.1.to_bits(), w.2), (g.1.to_bits(), g.2));
    }

    // Without colours; every cell down to one point, in the same cells.
    let grey = PointCloud::build(origin, &positions, &intensities, None, Some(0.05), 2.0).unwrap();
    let one_each = grey.thinned(u32::MAX, 2.0).unwrap();
    assert_eq!(one_each.len(), grey.cells().len());
    assert_eq!(one_each.cells().len(), grey.cells().len());
    assert!(one_each.colors().is_none());

    assert!(cloud.thinned(0, 2.0).is_err());
    assert!(cloud.thinned(2, 0.0).is_err());
    assert!(cloud.thinned(2, f32::NAN).is_err());
}
