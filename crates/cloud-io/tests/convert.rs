//! Conversion between the four formats: coordinates and colours kept exactly.

use cloud_io::{CloudFormat, ColorScale, Colors, FileInfo, LasGrid, Points, convert, read_points};
use glam::DVec3;

use crate::common::*;

/// Points on a LAS millimetre grid, 16-bit colour.
fn on_grid() -> Points {
    let n = 500;
    Points {
        positions_m: (0..n)
            .map(|i| {
                DVec3::new(
                    651_000.0 + f64::from(i) * 0.013,
                    4_860_000.0 + f64::from(i % 37) * 0.291,
                    120.0 + f64::from(i % 11) * 0.007,
                )
            })
            .collect(),
        colors: Some(Colors {
            values: (0..n as u32)
                .map(|i| [(i * 131 % 65_536) as u16, (i * 7) as u16, 65_535 - i as u16])
                .collect(),
            scale: ColorScale::SixteenBit,
        }),
        intensities: Some((0..n).map(|i| f32::from(i as u16 % 300)).collect()),
    }
}

#[test]
fn las_laz_ply_e57_and_back_keep_coordinates_and_16_bit_colour() {
    let dir = temp_dir("convert");
    let grid = LasGrid {
        scale_m: DVec3::splat(1e-3),
        offset_m: DVec3::new(651_000.0, 4_860_000.0, 100.0),
    };
    let start = dir.join("a.las");
    cloud_io::write_points_on_grid(&on_grid(), &start, Some(grid)).unwrap();
    let (original, _) = read_points(&start).unwrap();
    // Every coordinate a whole number of millimetres from the offset, as LAS stores it.
    for p in &original.positions_m {
        let steps = (*p - grid.offset_m) / grid.scale_m;
        assert!((steps - steps.round()).abs().max_element() < 1e-6);
    }
    assert_eq!(original.colors, on_grid().colors);
    let chain = ["b.ply", "c.e57", "d.laz", "e.ply", "f.las"];
    let mut from = start.clone();
    let mut previous = original.clone();
    for name in chain {
        let to = dir.join(name);
        let info = convert(&from, &to).unwrap();
        let (points, back) = read_points(&to).unwrap();
        assert_eq!(back.format, CloudFormat::of_output(&to).unwrap());
        assert_eq!(info.points, 500);
        assert_eq!(points.colors, original.colors, "{name}");
        match back.file {
            // Written as LAS on the source's grid (a LAS source) or on 0.1 mm (a PLY or
            // E57 source): the same millimetre coordinates, to rounding.
            FileInfo::Las(_) => {
                for (a, b) in points.positions_m.iter().zip(&original.positions_m) {
                    assert!((*a - *b).abs().max_element() < 1e-9, "{name}: {a} vs {b}");
                }
            }
            // PLY and E57 keep their source's f64 coordinates bit for bit.
            _ => assert_eq!(points.positions_m, previous.positions_m, "{name}"),
        }
        from = to;
        previous = points;
    }
    // LAS to LAZ keeps the grid.
    let laz = dir.join("g.laz");
    convert(&start, &laz).unwrap();
    let (points, info) = read_points(&laz).unwrap();
    assert_eq!(points.positions_m, original.positions_m);
    assert_eq!(las_info(info).grid, grid);
    // A real PLY to E57 and back: bit for bit.
    let e57 = dir.join("o3d.e57");
    convert(fixture("open3d_pcd_double_rgb.ply"), &e57).unwrap();
    let ply = dir.join("o3d.ply");
    convert(&e57, &ply).unwrap();
    assert_eq!(
        read_points(&ply).unwrap().0,
        read_points(fixture("open3d_pcd_double_rgb.ply")).unwrap().0
    );
    // A real E57 to LAZ: within the 0.1 mm grid.
    let laz = dir.join("bunny.laz");
    convert(fixture("bunnyInt19.e57"), &laz).unwrap();
    let (a, _) = read_points(fixture("bunnyInt19.e57")).unwrap();
    let (b, _) = read_points(&laz).unwrap();
    assert_eq!(a.len(), b.len());
    for (p, q) in a.positions_m.iter().zip(&b.positions_m) {
        assert!(
            (*p - *q).abs().max_element() <= 0.5e-4 + 1e-12,
            "{p} vs {q}"
        );
    }
    // A PLY of coordinates alone written as LAS reads back without colour (point
    // format 0), not black: the renderer's constant intensity.
    let las = dir.join("xyz.las");
    convert(fixture("cloudcompare_bin_xyz.ply"), &las).unwrap();
    let (points, info) = read_points(&las).unwrap();
    assert!(points.colors.is_none());
    assert_eq!(las_info(info).point_format, 0);
    let (_, _, source) = cloud_io::read_cloud(&las).unwrap();
    assert_eq!(source, cloud_io::IntensitySource::Constant);
    // An unknown input and a wrong output name are errors, and nothing is written.
    assert!(convert(dir.join("missing.ply"), dir.join("x.las")).is_err());
    assert!(convert(&start, dir.join("x.txt")).is_err());
    assert!(!dir.join("x.txt").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
