//! E57: files written by other programs, scans merged with their poses, round trips,
//! corrupt files.

use cloud_io::{
    CloudFormat, CloudIoError, ColorScale, Colors, E57Info, FileInfo, IntensitySource, Points,
    read_cloud, read_points, write_points,
};
use glam::DVec3;

use crate::common::*;

fn e57_read(name: &str) -> (Points, E57Info) {
    let (points, info) = read_points(fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(info.format, CloudFormat::E57);
    assert_eq!(info.points, points.len() as u64);
    match info.file {
        FileInfo::E57(e57) => (points, e57),
        other => panic!("{name}: {other:?}"),
    }
}

#[test]
fn files_written_by_other_programs_read_with_their_values() {
    // The E57 reference implementation: scaled integer coordinates, no colour or
    // intensity.
    let (points, info) = e57_read("bunnyInt19.e57");
    assert_eq!(points.len(), 30_571);
    assert_eq!(info.scan_point_counts, [30_571]);
    assert!(points.colors.is_none() && points.intensities.is_none());
    let first = points.positions_m[0];
    assert!(
        (first - DVec3::new(-0.07063, 0.04015, 0.001226))
            .abs()
            .max_element()
            < 1e-6
    );
    let (_, _, source) = read_cloud(fixture("bunnyInt19.e57")).unwrap();
    assert_eq!(source, IntensitySource::Constant);

    // Float cartesian coordinates and 8-bit colour.
    let (points, _) = e57_read("tinyCartesianFloatRgb.e57");
    assert_eq!(points.len(), 2090);
    let colors = points.colors.as_ref().unwrap();
    assert_eq!(colors.scale, ColorScale::EightBit);
    assert_eq!(colors.values[0], [219, 218, 222]);
    assert_eq!(
        points.positions_m[0],
        DVec3::new(
            f64::from(-8.673_63_f32),
            f64::from(4.575_418_5_f32),
            f64::from(295.549_47_f32)
        )
    );
    let (cloud, _, source) = read_cloud(fixture("tinyCartesianFloatRgb.e57")).unwrap();
    assert_eq!(source, IntensitySource::Color(ColorScale::EightBit));
    assert_eq!(cloud.len(), 2090);

    // Spherical coordinates: the 180 points with a range become cartesian (the first at
    // range 1, azimuth 0, elevation 0), the 180 directions without one are left out.
    let (points, info) = e57_read("tiny_spherical.e57");
    assert_eq!(info.spherical_scans, 1);
    assert_eq!(info.scan_point_counts, [360]);
    assert_eq!(info.invalid_points, 180);
    assert_eq!(points.len(), 180);
    assert_eq!(points.positions_m[0], DVec3::new(1.0, 0.0, 0.0));
    for p in &points.positions_m {
        assert!((p.length() - 1.0).abs() < 1e-9, "{p}");
    }

    // A structured scan (row and column indices).
    let (points, info) = e57_read("read_error.e57");
    assert_eq!(info.structured_scans, 1);
    assert_eq!(points.len(), 2651);

    // Integer intensity without colour: the intensity attribute.
    let (points, _) = e57_read("integer_intensity.e57");
    assert_eq!(
        points.positions_m,
        [DVec3::new(1.1, 2.2, 3.3), DVec3::new(4.4, 5.5, 6.6)]
    );
    assert_eq!(points.intensities.as_deref(), Some(&[0.0, 1.0][..]));
    let (_, _, source) = read_cloud(fixture("integer_intensity.e57")).unwrap();
    assert_eq!(source, IntensitySource::IntensityAttribute);

    // Invalid-state flags (stored as floats, as PDAL does): only the valid point.
    let (points, info) = e57_read("cartesian_invalid_state_single.e57");
    assert_eq!(points.positions_m, [DVec3::new(-1.0, -2.0, -3.0)]);
    assert_eq!(info.invalid_points, 2);
}

#[test]
fn empty_and_corrupt_files_are_errors() {
    assert!(matches!(
        read_cloud(fixture("empty_pc.e57")),
        Err(CloudIoError::NoPoint { .. })
    ));
    let message = read_points(fixture("corrupt_crc.e57"))
        .unwrap_err()
        .to_string();
    assert!(message.contains("checksum"), "{message}");
    // A copy cut short: an error, not a panic.
    let dir = temp_dir("e57-cut");
    let bytes = std::fs::read(fixture("tinyCartesianFloatRgb.e57")).unwrap();
    for keep in [bytes.len() / 2, 2000, 100, 8] {
        let path = dir.join("cut.e57");
        std::fs::write(&path, &bytes[..keep]).unwrap();
        assert!(read_points(&path).is_err(), "{keep} bytes");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two scans, each with its own pose, one with 16-bit colour and one with intensity
/// only: merged in the file's frame, the scan without colour grey at its intensity.
#[test]
fn scans_are_merged_with_their_poses() {
    let dir = temp_dir("e57-scans");
    let path = dir.join("two.e57");
    let mut writer = e57::E57Writer::from_file(&path, "file").unwrap();
    let color_u16 = |name| e57::Record {
        name,
        data_type: e57::RecordDataType::U16,
    };
    let mut scan = writer
        .add_pointcloud(
            "coloured",
            vec![
                e57::Record::CARTESIAN_X_F64,
                e57::Record::CARTESIAN_Y_F64,
                e57::Record::CARTESIAN_Z_F64,
                color_u16(e57::RecordName::ColorRed),
                color_u16(e57::RecordName::ColorGreen),
                color_u16(e57::RecordName::ColorBlue),
            ],
        )
        .unwrap();
    // Translated by (10, 20, 30).
    scan.set_transform(Some(e57::Transform {
        rotation: e57::Quaternion::default(),
        translation: e57::Translation {
            x: 10.0,
            y: 20.0,
            z: 30.0,
        },
    }));
    let d = e57::RecordValue::Double;
    let i = e57::RecordValue::Integer;
    scan.add_point(vec![d(1.0), d(0.0), d(0.0), i(65_535), i(0), i(1000)])
        .unwrap();
    scan.finalize().unwrap();
    let mut scan = writer
        .add_pointcloud(
            "grey",
            vec![
                e57::Record::CARTESIAN_X_F64,
                e57::Record::CARTESIAN_Y_F64,
                e57::Record::CARTESIAN_Z_F64,
                e57::Record::INTENSITY_UNIT_F32,
            ],
        )
        .unwrap();
    // Turned by 90° about z: x becomes y.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    scan.set_transform(Some(e57::Transform {
        rotation: e57::Quaternion {
            w: h,
            x: 0.0,
            y: 0.0,
            z: h,
        },
        translation: e57::Translation {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        },
    }));
    scan.add_point(vec![d(2.0), d(0.0), d(0.0), e57::RecordValue::Single(0.5)])
        .unwrap();
    scan.finalize().unwrap();
    writer.finalize().unwrap();
    drop(writer);

    let (points, info) = read_points(&path).unwrap();
    let FileInfo::E57(e57) = info.file else {
        panic!()
    };
    assert_eq!(e57.scans, 2);
    assert_eq!(points.positions_m[0], DVec3::new(11.0, 20.0, 30.0));
    assert!((points.positions_m[1] - DVec3::new(0.0, 2.0, 0.0)).length() < 1e-12);
    let colors = points.colors.unwrap();
    assert_eq!(colors.scale, ColorScale::SixteenBit);
    assert_eq!(colors.values, [[65_535, 0, 1000], [32_768; 3]]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn writing_keeps_coordinates_colours_and_intensities() {
    let dir = temp_dir("e57-round");
    for scale in [ColorScale::EightBit, ColorScale::SixteenBit] {
        let top = scale.max_value();
        let points = Points {
            positions_m: vec![
                DVec3::new(651_000.123_456_789_1, 4_860_000.987_654_321, 120.5),
                DVec3::new(-1e-12, 1e6, 0.1),
            ],
            colors: Some(Colors {
                values: vec![[top, 0, 1], [2, top / 3, top - 1]],
                scale,
            }),
            intensities: Some(vec![0.25, 3.5]),
        };
        let path = dir.join("r.e57");
        write_points(&points, &path).unwrap();
        let (back, _) = read_points(&path).unwrap();
        assert_eq!(back.positions_m, points.positions_m);
        assert_eq!(back.colors, points.colors);
        // Intensities come back normalised by the largest (the written limits).
        let intensities = back.intensities.unwrap();
        assert!((intensities[0] - 0.25 / 3.5).abs() < 1e-6 && (intensities[1] - 1.0).abs() < 1e-6);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
