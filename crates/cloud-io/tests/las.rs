//! LAS/LAZ: every shared file against its header, colour depth, round trips, errors.

use cloud_io::{CloudFormat, CloudIoError, ColorScale, IntensitySource, write_cloud};
use glam::DVec3;
use splat::{PointCloud, SplatError};

use crate::common::*;

#[test]
fn every_shared_cloud_reads_with_its_header_counts_and_colour_range() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("clouds");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_lowercase();
        if ext != "las" && ext != "laz" {
            continue;
        }
        let (cloud, info, source) =
            read_las(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(
            cloud.len() as u64,
            info.header_point_count,
            "{}",
            path.display()
        );
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        // Positions within the header's bounds (millimetre tolerance of f32 offsets).
        let (lo, hi) = cloud.bounds();
        assert!(
            (lo - info.bounds.0).abs().max_element() < 0.01,
            "{name}: {lo} vs {}",
            info.bounds.0
        );
        assert!(
            (hi - info.bounds.1).abs().max_element() < 0.01,
            "{name}: {hi} vs {}",
            info.bounds.1
        );
        match name.as_str() {
            "autzen_trim.las" | "autzen_trim_7.las" => {
                assert_eq!(cloud.len(), 110_000);
                assert_eq!(source, IntensitySource::Color(ColorScale::EightBit));
                assert!(info.max_color_value.unwrap() <= 255);
            }
            "sample_c.las" => {
                assert_eq!(cloud.len(), 14_408);
                assert_eq!(source, IntensitySource::Color(ColorScale::SixteenBit));
                assert!(info.max_color_value.unwrap() > 255);
            }
            "lone-star.laz" => {
                assert_eq!(cloud.len(), 518_862);
                assert_eq!(info.point_format, 1);
                assert!(cloud.colors().is_none());
            }
            _ => {}
        }
        // Colour clouds use the whole 8-bit range after scaling, not a sliver of it.
        if let Some(colors) = cloud.colors() {
            let max = colors.iter().flatten().copied().max().unwrap();
            assert!(max > 128, "{name}: max colour {max}");
        }
        let max_i = cloud.decoded().map(|(_, i)| i).fold(0.0f32, f32::max);
        assert!(max_i > 0.3 && max_i <= 1.0, "{name}: {max_i}");
        seen += 1;
    }
    assert!(seen >= 5, "{seen} clouds in {}", dir.display());
}

#[test]
fn las_and_laz_round_trip() {
    let dir = temp_dir("roundtrip");
    let positions: Vec<DVec3> = (0..2000)
        .map(|i| {
            DVec3::new(
                651_000.0 + f64::from(i) * 0.013,
                4_860_000.0 + f64::from(i % 37) * 0.29,
                120.0 + f64::from(i % 11),
            )
        })
        .collect();
    let colors: Vec<[u8; 3]> = (0..2000)
        .map(|i| [(i % 256) as u8, (i * 7 % 256) as u8, (255 - i % 256) as u8])
        .collect();
    let intensities: Vec<f32> = colors.iter().map(|&c| splat::luminance(c)).collect();
    let cloud = PointCloud::from_points(
        DVec3::new(651_000.0, 4_860_000.0, 100.0),
        &positions,
        &intensities,
        Some(colors),
        None,
    )
    .unwrap();
    for name in ["c.las", "c.laz"] {
        let path = dir.join(name);
        write_cloud(&cloud, &path).unwrap();
        let (back, _, source) = read_las(&path).unwrap();
        assert_eq!(back.len(), cloud.len());
        // Written as 16-bit full range, read back as such.
        assert_eq!(source, IntensitySource::Color(ColorScale::SixteenBit));
        // Same set of points (the order follows the cells): compare sorted.
        let key = |c: &PointCloud| {
            let mut v: Vec<(i64, i64, i64, [u8; 3])> = (0..c.len())
                .map(|i| {
                    let p = c.world_position(i);
                    (
                        (p.x * 1000.0).round() as i64,
                        (p.y * 1000.0).round() as i64,
                        (p.z * 1000.0).round() as i64,
                        c.colors().unwrap()[i],
                    )
                })
                .collect();
            v.sort();
            v
        };
        let (a, b) = (key(&cloud), key(&back));
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x.0 - y.0).abs() <= 1 && (x.1 - y.1).abs() <= 1 && (x.2 - y.2).abs() <= 1,
                "{x:?} vs {y:?}"
            );
            assert_eq!(x.3, y.3);
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn corrupt_truncated_and_missing_files_are_errors() {
    let dir = temp_dir("corrupt");
    assert!(matches!(
        read_las(dir.join("missing.las")),
        Err(CloudIoError::Io { .. })
    ));
    let junk = dir.join("junk.las");
    std::fs::write(&junk, b"this is not a LAS file at all, just some bytes").unwrap();
    assert!(matches!(
        read_las(&junk),
        Err(CloudIoError::UnknownFormat { .. })
    ));
    std::fs::write(&junk, b"LASF and then nothing that a header needs").unwrap();
    assert!(matches!(read_las(&junk), Err(CloudIoError::Las { .. })));

    // A real file cut in the middle of its points.
    let positions: Vec<DVec3> = (0..5000)
        .map(|i| DVec3::new(f64::from(i) * 0.01, 0.0, 0.0))
        .collect();
    let cloud =
        PointCloud::from_points(DVec3::ZERO, &positions, &vec![0.5; 5000], None, Some(0.01))
            .unwrap();
    for name in ["t.las", "t.laz"] {
        let path = dir.join(name);
        write_cloud(&cloud, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let result = std::panic::catch_unwind(|| read_las(&path));
        let result = result.unwrap_or_else(|_| panic!("{name}: reading a truncated file panicked"));
        let message = result
            .expect_err("a truncated file was accepted")
            .to_string();
        assert!(message.contains("truncated"), "{name}: {message}");
        // Only the header: no point.
        std::fs::write(&path, &bytes[..300.min(bytes.len())]).unwrap();
        assert!(read_las(&path).is_err());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Header fields that lie: a point count far beyond the file (0xFFFFFFFF, or
/// 100 000 000 in a file of a few kilobytes) is refused from the file's size, before
/// anything is allocated, with both counts in the message; header bounds of ±1e300
/// do not move the cloud (its origin comes from the data).
#[test]
fn lying_headers_are_refused_or_ignored() {
    let dir = temp_dir("lying");
    let positions: Vec<DVec3> = (0..500)
        .map(|i| DVec3::new(f64::from(i) * 0.01, f64::from(i % 7), 2.0))
        .collect();
    let cloud = PointCloud::from_points(DVec3::ZERO, &positions, &vec![0.5; 500], None, Some(0.01))
        .unwrap();
    let path = dir.join("h.las");
    write_cloud(&cloud, &path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // LAS 1.2: the legacy point count at bytes 107..111, bounds at 179..227.
    for count in [u32::MAX, 100_000_000, 501] {
        let mut lying = bytes.clone();
        lying[107..111].copy_from_slice(&count.to_le_bytes());
        std::fs::write(&path, &lying).unwrap();
        match read_las(&path) {
            Err(CloudIoError::Truncated {
                announced, found, ..
            }) => {
                assert_eq!(announced, Some(u64::from(count)));
                assert!(found.starts_with("500 points"), "{found}");
            }
            other => panic!("count {count}: {other:?}"),
        }
        let message = read_las(&path).unwrap_err().to_string();
        assert!(message.contains(&count.to_string()), "{message}");
    }
    let mut lying = bytes.clone();
    for (k, v) in [1e300f64, -1e300, 1e300, -1e300, 1e300, -1e300]
        .iter()
        .enumerate()
    {
        lying[179 + 8 * k..187 + 8 * k].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&path, &lying).unwrap();
    let (back, info, _) = read_las(&path).unwrap();
    assert_eq!(info.bounds.1.x, 1e300);
    assert_eq!(back.len(), 500);
    let (lo, hi) = back.bounds();
    assert!(lo.is_finite() && hi.is_finite() && (hi - lo).max_element() < 10.0);
    // Points farther from the origin than f32 positions can hold are refused.
    let far = [DVec3::ZERO, DVec3::new(2e6, 0.0, 0.0)];
    assert!(matches!(
        PointCloud::from_points(DVec3::ZERO, &far, &[0.5, 0.5], None, Some(0.1)),
        Err(SplatError::Parameter {
            name: "positions",
            ..
        })
    ));
    // Output paths: a known extension in an existing folder only.
    assert_eq!(
        CloudFormat::of_output(&dir.join("c.LAZ")).unwrap(),
        CloudFormat::Laz
    );
    assert!(CloudFormat::of_output(&dir.join("c.txt")).is_err());
    assert!(CloudFormat::of_output(&dir.join("missing/c.las")).is_err());
    assert!(write_cloud(&cloud, dir.join("c.txt")).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A LAZ file `c.laz` in `dir` of 500 points along a line, 1 cm apart.
fn five_hundred_point_laz(dir: &std::path::Path) -> std::path::PathBuf {
    let positions: Vec<DVec3> = (0..500)
        .map(|i| DVec3::new(f64::from(i) * 0.01, 0.0, 1.0))
        .collect();
    let cloud = PointCloud::from_points(DVec3::ZERO, &positions, &vec![0.5; 500], None, Some(0.01))
        .unwrap();
    let path = dir.join("c.laz");
    write_cloud(&cloud, &path).unwrap();
    path
}

/// A LAZ whose chunk table announces 2³² − 1 chunks (our fuzzing's find: the `laz`
/// crate allocated the table from that count, 25 GB, and the process aborted) is
/// refused from the file's size.
#[test]
fn laz_chunk_tables_that_lie_are_refused() {
    let dir = temp_dir("chunks");
    let path = five_hundred_point_laz(&dir);
    let mut bytes = std::fs::read(&path).unwrap();
    // The chunk table's offset is the first 8 bytes of the point data (offset at 96).
    let data = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(bytes[data..data + 8].try_into().unwrap()) as usize;
    bytes[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let message = read_las(&path).unwrap_err().to_string();
    assert!(message.contains("4294967295 chunks"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The offset in `bytes` (a LAS/LAZ file) of the payload of the variable-length record
/// `record_id`.
fn vlr_payload(bytes: &[u8], record_id: u16) -> usize {
    let header_size = usize::from(u16::from_le_bytes(bytes[94..96].try_into().unwrap()));
    let count = u32::from_le_bytes(bytes[100..104].try_into().unwrap());
    let mut at = header_size;
    for _ in 0..count {
        let id = u16::from_le_bytes(bytes[at + 18..at + 20].try_into().unwrap());
        let length = usize::from(u16::from_le_bytes(
            bytes[at + 20..at + 22].try_into().unwrap(),
        ));
        if id == record_id {
            return at + 54;
        }
        at += 54 + length;
    }
    panic!("no record {record_id}");
}

/// A LAZ whose laszip record announces chunks of 2³² − 16 points (the `laz` crate
/// would size its buffer from that: 111 GB for these 500 points, and the process
/// would abort) is refused before decoding, with the chunk's announced size; a chunk
/// size within the budget still reads.
#[test]
fn laz_chunks_larger_than_the_file_could_hold_are_refused() {
    let dir = temp_dir("chunk-size");
    let path = five_hundred_point_laz(&dir);
    let bytes = std::fs::read(&path).unwrap();
    // The laszip record: compressor, coder (2 bytes each), version (4), options (4),
    // then the chunk size (4).
    let chunk_size = vlr_payload(&bytes, 22204) + 12;
    for (points, refused) in [(0xFFFF_FFF0u32, true), (100_000, false)] {
        let mut lying = bytes.clone();
        lying[chunk_size..chunk_size + 4].copy_from_slice(&points.to_le_bytes());
        std::fs::write(&path, &lying).unwrap();
        match read_las(&path) {
            Err(e) if refused => {
                let message = e.to_string();
                assert!(
                    message.contains(&format!("announces {points} points")),
                    "{message}"
                );
            }
            Ok((back, _, _)) if !refused => assert_eq!(back.len(), 500),
            other => panic!("chunk size {points}: {:?}", other.map(|c| c.0.len())),
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A LAS 1.4 file whose extended record announces 2⁴⁰ bytes (`las` would allocate
/// them, 1 TiB, before reading) is refused as truncated; the same file with its true
/// length reads.
#[test]
fn las_extended_records_longer_than_the_file_are_refused() {
    let dir = temp_dir("evlr");
    let path = dir.join("c.las");
    let mut builder = las::Builder::from((1, 4));
    builder.evlrs.push(las::Vlr {
        user_id: "pgm-test".into(),
        record_id: 1,
        description: "an extended record".into(),
        data: vec![7; 100],
    });
    let header = builder.into_header().unwrap();
    let mut writer = las::Writer::from_path(&path, header).unwrap();
    for i in 0..10 {
        let point = las::Point {
            x: f64::from(i),
            y: 0.0,
            z: 1.0,
            ..Default::default()
        };
        writer.write_point(point).unwrap();
    }
    writer.close().unwrap();
    let (back, _, _) = read_las(&path).unwrap();
    assert_eq!(back.len(), 10);
    let mut bytes = std::fs::read(&path).unwrap();
    let start = u64::from_le_bytes(bytes[235..243].try_into().unwrap()) as usize;
    assert_eq!(
        u64::from_le_bytes(bytes[start + 20..start + 28].try_into().unwrap()),
        100
    );
    bytes[start + 20..start + 28].copy_from_slice(&(1u64 << 40).to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    match read_las(&path) {
        Err(CloudIoError::Truncated { found, .. }) => {
            assert!(found.contains("1099511627776 bytes"), "{found}");
        }
        other => panic!("{:?}", other.map(|c| c.0.len())),
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
