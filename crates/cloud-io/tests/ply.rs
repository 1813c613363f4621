//! PLY: files written by other programs, every encoding against the same points, round
//! trips, and files that lie.

use cloud_io::{
    CloudFormat, CloudIoError, ColorScale, Colors, FileInfo, IntensitySource, PlyEncoding, PlyInfo,
    Points, read_cloud, read_points, write_points,
};
use glam::DVec3;

use crate::common::*;

fn ply_info(info: cloud_io::CloudInfo) -> PlyInfo {
    match info.file {
        FileInfo::Ply(ply) => ply,
        other => panic!("not a PLY file: {other:?}"),
    }
}

#[test]
fn files_written_by_other_programs_read_with_their_values() {
    // Open3D: binary little-endian, double coordinates, uchar colour.
    let (points, info) = read_points(fixture("open3d_pcd_double_rgb.ply")).unwrap();
    assert_eq!(info.format, CloudFormat::Ply);
    let ply = ply_info(info);
    assert_eq!(ply.encoding, PlyEncoding::BinaryLittleEndian);
    assert_eq!(ply.vertex_count, 4032);
    assert!(ply.comments.iter().any(|c| c.contains("Open3D")));
    assert_eq!(points.len(), 4032);
    let colors = points.colors.as_ref().unwrap();
    assert_eq!(colors.scale, ColorScale::EightBit);
    assert_eq!(
        points.positions_m[0],
        DVec3::new(
            -0.372_137_278_318_405_15,
            0.200_000_002_980_232_24,
            1.700_000_047_683_715_8
        )
    );
    assert_eq!(colors.values[0], [252, 253, 253]);
    assert_eq!(
        points.positions_m[4031],
        DVec3::new(
            -0.850_000_023_841_857_9,
            -0.150_000_005_960_464_48,
            2.568_140_506_744_384_8
        )
    );
    assert_eq!(colors.values[4031], [254, 254, 254]);
    let (cloud, _, source) = read_cloud(fixture("open3d_pcd_double_rgb.ply")).unwrap();
    assert_eq!(cloud.len(), 4032);
    assert_eq!(source, IntensitySource::Color(ColorScale::EightBit));

    // CloudCompare: binary little-endian floats, no colour: constant intensity.
    let (points, _) = read_points(fixture("cloudcompare_bin_xyz.ply")).unwrap();
    assert_eq!(
        points.positions_m,
        [
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0)
        ]
    );
    assert!(points.colors.is_none() && points.intensities.is_none());
    let (_, _, source) = read_cloud(fixture("cloudcompare_bin_xyz.ply")).unwrap();
    assert_eq!(source, IntensitySource::Constant);

    // Blender: ASCII, extra properties (s, t) between the coordinates and the colour,
    // and a face element after the vertices.
    let (points, info) = read_points(fixture("blender_ascii_rgb.ply")).unwrap();
    assert_eq!(ply_info(info).encoding, PlyEncoding::Ascii);
    assert_eq!(
        points.positions_m,
        [
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(1.0, -1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(-1.0, 1.0, 0.0)
        ]
    );
    assert_eq!(
        points.colors.unwrap().values,
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]]
    );

    // MeshLab: RGBA colour (alpha skipped) and 1610 faces after the vertices.
    let (points, _) = read_points(fixture("meshlab_bin_rgba_mesh.ply")).unwrap();
    assert_eq!(points.len(), 845);
    assert_eq!(
        points.positions_m[0],
        DVec3::new(
            f64::from(-52.825_6_f32),
            f64::from(-49.530_9_f32),
            f64::from(-68.130_3_f32)
        )
    );
    assert_eq!(points.colors.unwrap().values[0], [192, 192, 192]);

    // hapPLY: binary big-endian doubles, faces after the vertices.
    let (points, info) = read_points(fixture("happly_big_endian_mesh.ply")).unwrap();
    assert_eq!(ply_info(info).encoding, PlyEncoding::BinaryBigEndian);
    assert_eq!(points.len(), 50);
    assert_eq!(
        points.positions_m[0],
        DVec3::new(-3.562_626, -0.627_972, 0.613_591)
    );
    assert_eq!(
        points.positions_m[49],
        DVec3::new(6.068_807, 0.985_759, 0.056_527)
    );
}

/// The same vertices in the three encodings, after an element with a list property
/// that the reader must skip, with `ushort` colour, `double` coordinates, an unused
/// property and an intensity.
fn hand_written(encoding: PlyEncoding) -> (Vec<u8>, Points) {
    let positions_m = vec![
        DVec3::new(651_000.123_456_789, 4_860_000.987_654_321, 120.5),
        DVec3::new(651_000.5 - 1e-9, 4_860_002.5, -3.25),
        DVec3::new(651_000.1, 4_860_000.2, 0.3),
    ];
    let colors: Vec<[u16; 3]> = vec![[65_535, 0, 257], [1, 2, 3], [40_000, 50_000, 60_000]];
    let intensities = vec![0.25f32, 1.0, 17.5];
    let format = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
    };
    let mut bytes = format!(
        "ply\r\nformat {format} 1.0\ncomment hand written\nelement camera 2\n\
         property list uchar int ids\nproperty float f\nelement vertex 3\n\
         property double x\nproperty double y\nproperty double z\nproperty short unused\n\
         property ushort red\nproperty ushort green\nproperty ushort blue\n\
         property float scalar_intensity\nelement face 1\nproperty list uchar int vertex_indices\n\
         end_header\n"
    )
    .into_bytes();
    let big = encoding == PlyEncoding::BinaryBigEndian;
    macro_rules! put {
        ($v:expr) => {
            if big {
                bytes.extend_from_slice(&$v.to_be_bytes())
            } else {
                bytes.extend_from_slice(&$v.to_le_bytes())
            }
        };
    }
    match encoding {
        PlyEncoding::Ascii => {
            bytes.extend_from_slice(b"2 7 8 0.5\n0 -1.5\n");
            for i in 0..3 {
                let p = positions_m[i];
                let c = colors[i];
                bytes.extend_from_slice(
                    format!(
                        "{:?} {:?} {:?}  -7 {} {} {}\t{:?}\n",
                        p.x, p.y, p.z, c[0], c[1], c[2], intensities[i]
                    )
                    .as_bytes(),
                );
            }
            bytes.extend_from_slice(b"3 0 1 2\n");
        }
        _ => {
            for (ids, f) in [(&[7i32, 8][..], 0.5f32), (&[][..], -1.5)] {
                bytes.push(ids.len() as u8);
                for id in ids {
                    put!(*id);
                }
                put!(f);
            }
            for i in 0..3 {
                let p = positions_m[i];
                put!(p.x);
                put!(p.y);
                put!(p.z);
                put!(-7i16);
                for c in colors[i] {
                    put!(c);
                }
                put!(intensities[i]);
            }
            bytes.push(3);
            for k in 0..3i32 {
                put!(k);
            }
        }
    }
    let points = Points {
        positions_m,
        colors: Some(Colors {
            values: colors,
            scale: ColorScale::SixteenBit,
        }),
        intensities: Some(intensities),
    };
    (bytes, points)
}

#[test]
fn every_encoding_reads_the_same_points_and_writing_keeps_them_exactly() {
    let dir = temp_dir("ply-encodings");
    for encoding in [
        PlyEncoding::Ascii,
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let (bytes, expected) = hand_written(encoding);
        // A name that says nothing: the format comes from the content.
        let path = dir.join(format!("{encoding:?}.cloud"));
        std::fs::write(&path, &bytes).unwrap();
        let (points, info) = read_points(&path).unwrap();
        assert_eq!(points, expected, "{encoding:?}");
        let ply = ply_info(info);
        assert_eq!(ply.encoding, encoding);
        assert_eq!(ply.comments, ["comment hand written"]);
        // Written back (binary little-endian) and read again: the same, bit for bit.
        let out = dir.join(format!("{encoding:?}-back.ply"));
        write_points(&points, &out).unwrap();
        assert_eq!(read_points(&out).unwrap().0, expected);
        // The renderer's cloud: 16-bit colours brought to 8 bits.
        let (cloud, _, source) = read_cloud(&path).unwrap();
        assert_eq!(source, IntensitySource::Color(ColorScale::SixteenBit));
        let mut rgb = cloud.colors().unwrap().to_vec();
        rgb.sort();
        assert_eq!(rgb, [[0, 0, 0], [156, 195, 233], [255, 0, 1]]);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn grey_and_intensity_without_colour() {
    let dir = temp_dir("ply-grey");
    let path = dir.join("g.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar grey\nend_header\n0 0 0 10\n1 0 0 200\n",
    )
    .unwrap();
    let (points, _) = read_points(&path).unwrap();
    let colors = points.colors.unwrap();
    assert_eq!(colors.scale, ColorScale::EightBit);
    assert_eq!(colors.values, [[10; 3], [200; 3]]);
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
         property float z\nproperty float intensity\nend_header\n0 0 0 10\n1 0 0 40\n",
    )
    .unwrap();
    let (cloud, _, source) = read_cloud(&path).unwrap();
    assert_eq!(source, IntensitySource::IntensityAttribute);
    // A grey property after the colour does not replace it.
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
         property uchar grey\nend_header\n0 0 0 10 20 30 99\n",
    )
    .unwrap();
    assert_eq!(
        read_points(&path).unwrap().0.colors.unwrap().values,
        [[10, 20, 30]]
    );
    let mut intensities: Vec<f32> = cloud.decoded().map(|(_, i)| i).collect();
    intensities.sort_by(f32::total_cmp);
    assert!((intensities[0] - 0.25).abs() < 1e-4 && (intensities[1] - 1.0).abs() < 1e-4);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `bytes` with the first `from` replaced by `to` (a header line).
fn replace(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    let at = bytes
        .windows(from.len())
        .position(|w| w == from.as_bytes())
        .unwrap();
    [&bytes[..at], to.as_bytes(), &bytes[at + from.len()..]].concat()
}

/// Headers that lie (counts beyond the file, up to 2⁶⁴ − 1), truncated bodies, and
/// malformed headers and values: typed errors, nothing allocated from a count.
#[test]
fn files_that_lie_or_break_the_format_are_errors() {
    let dir = temp_dir("ply-lies");
    let path = dir.join("l.ply");
    let (valid, _) = hand_written(PlyEncoding::BinaryLittleEndian);
    for count in ["4", "100000000", "18446744073709551615"] {
        let lying = replace(
            &valid,
            "element vertex 3",
            &format!("element vertex {count}"),
        );
        std::fs::write(&path, &lying).unwrap();
        match read_points(&path) {
            Err(CloudIoError::Truncated {
                announced, found, ..
            }) => {
                assert_eq!(announced.unwrap().to_string(), count);
                assert!(found.starts_with("3 vertices"), "{found}");
            }
            other => panic!("{count}: {other:?}"),
        }
    }
    // An element before the vertices that announces more records than the file holds.
    let lying = replace(&valid, "element camera 2", "element camera 4000000000");
    std::fs::write(&path, &lying).unwrap();
    assert!(matches!(
        read_points(&path),
        Err(CloudIoError::Truncated { .. })
    ));
    // An ASCII file cut in its vertices.
    let (ascii, _) = hand_written(PlyEncoding::Ascii);
    let cut = &ascii[..ascii.len() - 40];
    std::fs::write(&path, cut).unwrap();
    let message = read_points(&path).unwrap_err().to_string();
    assert!(
        message.contains("2 vertices before its text ends"),
        "{message}"
    );
    let huge = replace(
        &ascii,
        "element vertex 3",
        "element vertex 18446744073709551615",
    );
    std::fs::write(&path, &huge).unwrap();
    assert!(matches!(
        read_points(&path),
        Err(CloudIoError::Truncated { .. })
    ));

    let header = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n";
    let cases: [(&str, &str); 9] = [
        (
            "ply\nformat ascii 1.0\nelement vertex 1\n",
            "the file ends before `end_header`",
        ),
        ("ply\nelement vertex 0\nend_header\n", "no `format` line"),
        ("ply\nformat ascii 2.0\nend_header\n", "only version 1.0"),
        (
            "ply\nformat ascii 1.0\nelement face 0\nend_header\n",
            "no `vertex` element",
        ),
        (&format!("{header}end_header\n1 2\n"), "lacks x, y or z"),
        (
            &format!("{header}property float z\nproperty float x\nend_header\n"),
            "names `x` twice",
        ),
        (
            &format!("{header}property float z\nproperty float7 w\nend_header\n"),
            "an unknown type",
        ),
        (
            &format!("{header}property float z\nproperty uchar red\nend_header\n1 2 3 4\n"),
            "some colour channels only",
        ),
        (
            &format!("{header}property float z\nproperty uchar q\nend_header\n1 2 3 300\n"),
            "`300` is not a U8",
        ),
    ];
    for (text, expected) in cases {
        std::fs::write(&path, text).unwrap();
        let message = read_points(&path).unwrap_err().to_string();
        assert!(message.contains(expected), "{text:?}: {message}");
    }
    // No `end_header` within a megabyte: refused without reading the rest.
    let mut endless = b"ply\nformat ascii 1.0\n".to_vec();
    endless.extend(std::iter::repeat_n(b'a', 1 << 21));
    std::fs::write(&path, &endless).unwrap();
    let message = read_points(&path).unwrap_err().to_string();
    assert!(message.contains("no `end_header`"), "{message}");
    // An element of no property announcing 2⁶⁴ − 1 records before the vertices: skipped
    // at once, in both encodings.
    for format in ["ascii", "binary_little_endian"] {
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement nothing 18446744073709551615\n\
             element vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
             end_header\n"
        )
        .into_bytes();
        if format == "ascii" {
            bytes.extend_from_slice(b"1 2 3\n");
        } else {
            for v in [1f32, 2.0, 3.0] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        std::fs::write(&path, &bytes).unwrap();
        let (points, _) = read_points(&path).unwrap();
        assert_eq!(points.positions_m, [DVec3::new(1.0, 2.0, 3.0)], "{format}");
    }
    // Three thousand unused double properties (a 24 KB record) and one vertex: read,
    // with a buffer of one record, not of a chunk of them.
    let mut header = String::from(
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
         property float y\nproperty float z\n",
    );
    for k in 0..3000 {
        header += &format!("property double extra{k}\n");
    }
    header += "end_header\n";
    let mut bytes = header.into_bytes();
    for v in [4f32, 5.0, 6.0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes.extend(std::iter::repeat_n(0u8, 3000 * 8));
    std::fs::write(&path, &bytes).unwrap();
    let (points, info) = read_points(&path).unwrap();
    assert_eq!(points.positions_m, [DVec3::new(4.0, 5.0, 6.0)]);
    assert_eq!(ply_info(info).properties[3], "double extra0");
    // A vertex count of zero: no point.
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
         property float z\nend_header\n",
    )
    .unwrap();
    assert!(matches!(
        read_cloud(&path),
        Err(CloudIoError::NoPoint { .. })
    ));
    std::fs::remove_dir_all(&dir).unwrap();
}
