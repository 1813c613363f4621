//! Fuzzing of every parser a user feeds, on stable Rust: each case mutates a valid
//! input (structure-aware: numbers replaced by extreme values, lines deleted,
//! duplicated or cut; and byte mutations: flips, insertions, truncation) from a seed
//! that proptest draws, then parses it. Any outcome but a panic or an abort passes;
//! inputs are small, and every size read from a file is checked before it is
//! allocated (a header that announces more than the file holds is an error), so memory
//! stays bounded. Cases per parser: `FUZZ_CASES` (default 96; CI runs the default).

use std::path::{Path, PathBuf};

use glam::DVec3;
use proptest::prelude::*;
use splat::rng::SplitMix64;
use test_support::workspace_root as root;

fn cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(96)
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bench-conv-fuzz-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Values that break careless parsers.
const EXTREMES: [&str; 14] = [
    "0",
    "-1",
    "1e300",
    "-1e300",
    "nan",
    "inf",
    "-inf",
    "4294967295",
    "18446744073709551615",
    "100000000000",
    "1e-300",
    "0.0",
    "\"x\"",
    "[]",
];

/// A structure-aware mutation of a text file: 1 to 4 edits.
fn mutate_text(text: &str, seed: u64) -> String {
    let mut rng = SplitMix64::new(seed);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for _ in 0..=rng.below(3) {
        if lines.is_empty() {
            break;
        }
        let k = rng.below(lines.len() as u64) as usize;
        match rng.below(6) {
            // A number (or the value after `=`) replaced by an extreme value.
            0 | 1 => {
                let extreme = EXTREMES[rng.below(EXTREMES.len() as u64) as usize];
                let line = &lines[k];
                let starts: Vec<usize> = line
                    .char_indices()
                    .filter(|&(i, c)| {
                        (c.is_ascii_digit() || c == '-')
                            && !line[..i].ends_with(|p: char| p.is_ascii_alphanumeric() || p == '.')
                    })
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&start) = starts.get(rng.below(starts.len().max(1) as u64) as usize) {
                    let end = line[start..]
                        .find(|c: char| !(c.is_ascii_alphanumeric() || "+-.".contains(c)))
                        .map_or(line.len(), |e| start + e);
                    lines[k] = format!("{}{extreme}{}", &line[..start], &line[end..]);
                } else if let Some(eq) = line.find('=') {
                    lines[k] = format!("{} {extreme}", &line[..=eq]);
                }
            }
            2 => {
                lines.remove(k);
            }
            3 => {
                let copy = lines[k].clone();
                lines.insert(k, copy);
            }
            4 => {
                let cut = rng.below(lines[k].len() as u64 + 1) as usize;
                let cut = (0..=cut)
                    .rev()
                    .find(|&c| lines[k].is_char_boundary(c))
                    .unwrap_or(0);
                lines[k].truncate(cut);
            }
            _ => {
                let junk = ["[", "]", "=", "\"", ",", "[[desired]]", "{", "\u{0}"];
                lines[k].push_str(junk[rng.below(junk.len() as u64) as usize]);
            }
        }
    }
    lines.join("\n")
}

/// A byte mutation: flips, insertions, a truncation.
fn mutate_bytes(bytes: &[u8], seed: u64) -> Vec<u8> {
    let mut rng = SplitMix64::new(seed);
    let mut out = bytes.to_vec();
    for _ in 0..=rng.below(8) {
        if out.is_empty() {
            break;
        }
        let k = rng.below(out.len() as u64) as usize;
        match rng.below(4) {
            0 | 1 => out[k] = rng.next_u64() as u8,
            2 => out.insert(k, rng.next_u64() as u8),
            _ => {
                // A header field overwritten with an extreme integer (little endian).
                let v = [u32::MAX, 0, 1 << 31, 100_000_000][rng.below(4) as usize].to_le_bytes();
                for (j, b) in v.iter().enumerate() {
                    if k + j < out.len() {
                        out[k + j] = *b;
                    }
                }
            }
        }
    }
    if rng.chance(0.3) {
        let keep = rng.below(out.len() as u64 + 1) as usize;
        out.truncate(keep);
    }
    out
}

fn small_las(dir: &Path, name: &str) -> Vec<u8> {
    small_cloud_file(dir, name)
}

/// A small cloud written in the format `name`'s extension names.
fn small_cloud_file(dir: &Path, name: &str) -> Vec<u8> {
    let positions: Vec<DVec3> = (0..300)
        .map(|i| DVec3::new(f64::from(i) * 0.02, f64::from(i % 9) * 0.1, 1.0))
        .collect();
    let cloud = splat::PointCloud::from_points(
        DVec3::ZERO,
        &positions,
        &vec![0.4; positions.len()],
        None,
        Some(0.02),
    )
    .unwrap();
    let path = dir.join(name);
    cloud_io::write_cloud(&cloud, &path).unwrap();
    std::fs::read(&path).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// LAS and LAZ through our loader: byte mutations of small valid files.
    #[test]
    fn las_and_laz_files(seed in any::<u64>(), compressed in any::<bool>()) {
        let dir = temp("las");
        let name = if compressed { "c.laz" } else { "c.las" };
        let valid = small_las(&dir, name);
        let path = dir.join(format!("m-{seed}-{name}"));
        std::fs::write(&path, mutate_bytes(&valid, seed)).unwrap();
        let _ = cloud_io::read_cloud(&path);
        std::fs::remove_file(&path).unwrap();
    }

    /// PLY and E57 through the same loader: byte mutations of files written by other
    /// programs (binary and ASCII PLY, a structured and a coloured E57) and of our own
    /// PLY and E57 output; PLY headers also mutated as text.
    #[test]
    fn ply_and_e57_files(seed in any::<u64>(), which in 0usize..7, text in any::<bool>()) {
        let dir = temp("ply-e57");
        let (name, valid) = match which {
            0 => ("c.ply", small_cloud_file(&dir, "c.ply")),
            1 => ("c.e57", small_cloud_file(&dir, "c.e57")),
            k => {
                let name = [
                    "open3d_pcd_double_rgb.ply",
                    "blender_ascii_rgb.ply",
                    "happly_big_endian_mesh.ply",
                    "tinyCartesianFloatRgb.e57",
                    "read_error.e57",
                ][k - 2];
                (name, std::fs::read(root().join("fixtures/clouds").join(name)).unwrap())
            }
        };
        let mutated = if text && name.ends_with(".ply") {
            // The header as text (lines deleted, numbers replaced), the body as it was.
            let end = valid.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
            let header = mutate_text(&String::from_utf8_lossy(&valid[..end]), seed);
            [header.as_bytes(), &valid[end..]].concat()
        } else {
            mutate_bytes(&valid, seed)
        };
        let path = dir.join(format!("m-{seed}-{name}"));
        std::fs::write(&path, mutated).unwrap();
        let _ = cloud_io::read_cloud(&path);
        std::fs::remove_file(&path).unwrap();
    }

    /// Camera TOML files (every fixture), structure-aware and byte mutations.
    #[test]
    fn camera_toml(seed in any::<u64>(), bytes in any::<bool>()) {
        for name in ["omni-320x240.toml", "omni-640x480.toml", "omni-wide-400x400.toml"] {
            let text = std::fs::read_to_string(root().join("fixtures").join(name)).unwrap();
            let mutated = if bytes {
                String::from_utf8_lossy(&mutate_bytes(text.as_bytes(), seed)).into_owned()
            } else {
                mutate_text(&text, seed)
            };
            let _ = ucm::Camera::from_toml_str(&mutated, None);
        }
    }

    /// Mei calibrations (omniunwarp YAML) in every layout the reader takes — flow
    /// lists, block lists, OpenCV matrices, a non-ASCII comment — with LF or CRLF line
    /// ends, mutated as text or as bytes, with a crop size drawn too.
    #[test]
    fn mei_yaml(
        seed in any::<u64>(),
        layout in 0usize..4,
        crlf in any::<bool>(),
        bytes in any::<bool>(),
        width in 0u32..5000,
        height in 0u32..5000,
    ) {
        let dir = temp("mei");
        let text = match layout {
            0 => "# Intrinsic Matrix\nK: [470.0, 0.9, 615.0,\n    0.0, 463.0, 518.0,\n    \
                  0.0, 0.0, 1.0\n]\nD: [-0.15, 0.67, -0.02, -0.005]\nXi: [1.5]\n",
            1 => "K:\n  - 470.0\n  - 0.9\n  - 615.0\n  - 0.0\n  - 463.0\n  - 518.0\n  - 0.0\n  \
                  - 0.0\n  - 1.0\nD:\n  - -0.15\n  - 0.67\n  - -0.02\n  - -0.005\nXi: 1.5\n",
            2 => "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
                  data: [470.0, 0.9, 615.0, 0.0, 463.0, 518.0, 0.0, 0.0, 1.0]\nD: !!opencv-matrix\n   \
                  rows: 1\n   cols: 4\n   dt: d\n   data: [-0.15, 0.67, -0.02, -0.005]\nXi: [1.5]\n",
            _ => "# Étalonnage — caméra catadioptrique, D = [0, 0, 0, 0] avant correction\n\
                  K: [470.0, 0.9, 615.0, 0.0, 463.0, 518.0, 0.0, 0.0, 1.0]\n\
                  D: [-0.15, 0.67, -0.02, -0.005] # après\nXi: [1.5]\n",
        };
        let text = if crlf { text.replace('\n', "\r\n") } else { text.to_string() };
        let mutated = if bytes {
            mutate_bytes(text.as_bytes(), seed)
        } else {
            mutate_text(&text, seed).into_bytes()
        };
        let path = dir.join(format!("m-{seed}.yaml"));
        std::fs::write(&path, mutated).unwrap();
        let _ = ucm::Camera::load_mei_yaml(&path, width, height, ucm::ValidRegion::Full);
        std::fs::remove_file(&path).unwrap();
    }

    /// The manifest (`run.toml`) beside a shard's CSV, as `merge` reads it, and the
    /// completeness of merges of it with a valid shard.
    #[test]
    fn run_manifest(seed in any::<u64>(), bytes in any::<bool>()) {
        let dir = temp(&format!("manifest-{seed}"));
        let valid = bench_conv::report::RunManifest {
            protocol: "fig3".into(),
            protocol_hash: Some(bench_conv::report::fingerprint(b"fig3")),
            extras: false,
            total_runs: 10,
            run_id_limit: Some(10),
            shard: Some([1, 3]),
            runs: 3,
        };
        bench_conv::report::write_manifest(&dir, &valid).unwrap();
        let path = dir.join(bench_conv::report::MANIFEST);
        let text = std::fs::read(&path).unwrap();
        let mutated = if bytes {
            mutate_bytes(&text, seed)
        } else {
            mutate_text(&String::from_utf8_lossy(&text), seed).into_bytes()
        };
        std::fs::write(&path, mutated).unwrap();
        if let Ok(manifest) = bench_conv::report::read_manifest(&dir.join("runs.csv")) {
            let first = Some(bench_conv::report::RunManifest { shard: Some([0, 3]), runs: 4, ..valid });
            let _ = bench_conv::report::completeness(&[first, manifest], 7);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Protocol and sequence files (every fixture): parsed and checked, never run.
    #[test]
    fn protocol_and_sequence_files(seed in any::<u64>()) {
        let dir = temp("protocol");
        for camera in ["omni-320x240.toml", "omni-640x480.toml", "omni-wide-400x400.toml"] {
            let _ = std::fs::copy(root().join("fixtures").join(camera), dir.join(camera));
        }
        for name in [
            "protocol-fig3.toml",
            "protocol-fig3-domain.toml",
            "protocol-global.toml",
            "sequence-fig4.toml",
        ] {
            let text = std::fs::read_to_string(root().join("fixtures").join(name)).unwrap();
            let path = dir.join(format!("m-{seed}-{name}"));
            std::fs::write(&path, mutate_text(&text, seed)).unwrap();
            if name.starts_with("protocol") {
                let _ = bench_conv::protocol::Protocol::load(&path);
            } else {
                let _ = bench_conv::tracking::SequenceSpec::load(&path);
            }
            std::fs::remove_file(&path).unwrap();
        }
    }

    /// The runs CSV that `merge` reads.
    #[test]
    fn runs_csv(seed in any::<u64>(), bytes in any::<bool>()) {
        let dir = temp("csv");
        let record = |id: usize| crate::protocol::sample_record(id, id == 0);
        let valid = dir.join(format!("v-{seed}.csv"));
        bench_conv::report::write_csv(&valid, &[record(0), record(1), record(2)]).unwrap();
        let text = std::fs::read(&valid).unwrap();
        let mutated = if bytes {
            mutate_bytes(&text, seed)
        } else {
            mutate_text(&String::from_utf8_lossy(&text), seed).into_bytes()
        };
        let path = dir.join(format!("m-{seed}.csv"));
        std::fs::write(&path, mutated).unwrap();
        if let Ok(records) = bench_conv::report::read_csv(&path) {
            let _ = bench_conv::report::merge(vec![records]);
        }
        std::fs::remove_file(&path).unwrap();
        std::fs::remove_file(&valid).unwrap();
    }

    /// Image files for `pgm-image`: byte mutations of a PNG and a JPEG, with crops.
    #[test]
    fn image_files(seed in any::<u64>(), jpeg in any::<bool>(), x in 0u32..=80, y in 0u32..=60) {
        let dir = temp("image");
        let name = if jpeg { "i.jpg" } else { "i.png" };
        let valid = dir.join(format!("v-{seed}-{name}"));
        image::GrayImage::from_fn(400, 300, |i, j| image::Luma([((i * 7 + j * 3) % 256) as u8]))
            .save(&valid)
            .unwrap();
        let bytes = std::fs::read(&valid).unwrap();
        let path = dir.join(format!("m-{seed}-{name}"));
        std::fs::write(&path, mutate_bytes(&bytes, seed)).unwrap();
        let camera =
            ucm::Camera::load_toml(root().join("fixtures/omni-320x240.toml")).unwrap();
        let _ = frame::Image::load(&path, &camera, Some([x, y, 320, 240]));
        // Cut anywhere before its end, a picture is refused (a JPEG's grey fill and a
        // PNG's missing rows are no picture) — but for a PNG's last 4 bytes, the end
        // chunk's checksum, which decoders do not read once its type says "the end".
        let whole = if jpeg { bytes.len() } else { bytes.len() - 4 };
        let cut = (seed % whole as u64) as usize;
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let truncated = frame::Image::load(&path, &camera, Some([x, y, 320, 240]));
        prop_assert!(truncated.is_err(), "{name} cut at {cut} of {} bytes was read", bytes.len());
        std::fs::remove_file(&path).unwrap();
        std::fs::remove_file(&valid).unwrap();
    }

    /// RGB-D dataset descriptions, their pose files (TUM lines, 4×4 matrices), 16-bit
    /// depth pictures, and real-data benchmark files: read, never fused.
    #[test]
    fn rgbd_datasets_poses_depth_and_benchmarks(seed in any::<u64>(), which in 0usize..5) {
        let dir = temp("rgbd");
        let real = root().join("fixtures/real");
        for name in ["house-camera.toml", "house-mask.png", "kinect-7scenes-color.toml", "kinect-7scenes-depth.toml", "house.toml", "redkitchen.toml"] {
            let _ = std::fs::copy(real.join(name), dir.join(name));
        }
        let data = dir.join(format!("data-{seed}"));
        std::fs::create_dir_all(&data).unwrap();
        let lines = "-0.2289 0.0064 0.0287 -0.0004 -0.1131 -0.0326 0.9930\n".repeat(5);
        let matrix = "0.909 0.272 -0.314 -0.340\n-0.272 0.961 0.045 0.016\n0.314 0.044 0.948 0.296\n0 0 0 1\n";
        match which {
            0 => {
                std::fs::write(data.join("pose.txt"), mutate_text(&lines, seed)).unwrap();
                let _ = rgbd::RgbdDataset::load(dir.join("house.toml"), &data);
            }
            1 => {
                std::fs::write(data.join("frame-000000.pose.txt"), mutate_text(matrix, seed)).unwrap();
                let description = std::fs::read_to_string(dir.join("redkitchen.toml"))
                    .unwrap()
                    .replace("frames = [0, 999]", "frames = [0, 0]");
                std::fs::write(dir.join("one.toml"), description).unwrap();
                let _ = rgbd::RgbdDataset::load(dir.join("one.toml"), &data);
            }
            2 => {
                let text = std::fs::read_to_string(dir.join("redkitchen.toml")).unwrap();
                std::fs::write(dir.join("m.toml"), mutate_text(&text, seed)).unwrap();
                let _ = rgbd::RgbdDataset::load(dir.join("m.toml"), &data);
            }
            3 => {
                let path = data.join("d.png");
                image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(64, 48, |i, j| image::Luma([(i * 300 + j) as u16]))
                    .save(&path)
                    .unwrap();
                let bytes = std::fs::read(&path).unwrap();
                std::fs::write(&path, mutate_bytes(&bytes, seed)).unwrap();
                let _ = rgbd::DepthImage::load(&path, 0.001, &[65535]);
            }
            _ => {
                for name in ["bench-house.toml", "bench-redkitchen.toml"] {
                    let text = std::fs::read_to_string(real.join(name)).unwrap();
                    let path = dir.join(format!("m-{seed}-{name}"));
                    std::fs::write(&path, mutate_text(&text, seed)).unwrap();
                    let _ = bench_conv::real::RealSpec::load(&path);
                    std::fs::remove_file(&path).unwrap();
                }
            }
        }
        let _ = std::fs::remove_dir_all(&data);
    }
}
