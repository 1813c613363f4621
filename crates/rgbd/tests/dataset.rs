//! Dataset descriptions and their files: name patterns, every pose format, a
//! non-orthonormal rotation, bad files, the same cloud as frames added by hand and
//! whatever the thread count; the real house pictures.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use rgbd::{FuseOptions, Fusion, RgbdDataset, RgbdError, Sensor, frame_path, nearest_rotation};
use ucm::Isometry3;

use crate::scenes::{Scene, at, pinhole};

const WALL: Scene = Scene {
    square_half_m: Some(0.15),
};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rgbd-tests-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const CAMERA_TOML: &str = "[image]\nwidth = 64\nheight = 48\n\n[intrinsics]\nalpha_u = 60.0\nalpha_v = 60.0\nu0 = 31.5\nv0 = 23.5\nxi = 0.0\n\n[region]\nkind = \"full\"\n";

fn poses() -> Vec<Isometry3> {
    (0..4)
        .map(|k| {
            let turn =
                Isometry3::from_pose_vector([0.0, 0.0, 0.0, 0.0, 0.02 * k as f64, 0.01]).unwrap();
            at(0.03 * k as f64, -0.02 * k as f64) * turn
        })
        .collect()
}

/// Frames 10..=13 of the wall scene written as 16-bit millimetre PNGs and PNG colour
/// pictures under `dir/data`, with the description; returns its path.
fn write_dataset(dir: &Path, poses_section: &str, pose_files: &[(&str, String)]) -> PathBuf {
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let camera = pinhole(60.0);
    for (k, pose) in poses().iter().enumerate() {
        let number = 10 + k;
        let depth = WALL.depth(&camera, pose);
        let samples: Vec<u16> = depth
            .depth_m
            .iter()
            .map(|&d| (d * 1000.0).round() as u16)
            .collect();
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(64, 48, samples)
            .unwrap()
            .save(data.join(format!("d{number:03}.png")))
            .unwrap();
        let color = WALL.color(&camera, pose);
        image::RgbImage::from_raw(64, 48, color.rgb.concat())
            .unwrap()
            .save(data.join(format!("c{number}.png")))
            .unwrap();
    }
    for (name, text) in pose_files {
        std::fs::write(data.join(name), text).unwrap();
    }
    std::fs::write(dir.join("camera.toml"), CAMERA_TOML).unwrap();
    let description = dir.join("dataset.toml");
    std::fs::write(
        &description,
        format!(
            "frames = [10, 13]\ncolor = \"c{{}}.png\"\ndepth = \"d{{:03}}.png\"\ndepth_scale_m = 0.001\ncolor_camera = \"camera.toml\"\n\n{poses_section}"
        ),
    )
    .unwrap();
    description
}

fn matrix_text(pose: &Isometry3) -> String {
    let r = pose.rotation_matrix();
    let t = pose.translation;
    let mut text = String::new();
    for i in 0..3 {
        let row = r.row(i);
        text += &format!("{:.12} {:.12} {:.12} {:.12}\n", row.x, row.y, row.z, t[i]);
    }
    text + "0 0 0 1\n"
}

fn tum_line(pose: &Isometry3) -> String {
    let (t, q) = (pose.translation, pose.rotation);
    format!(
        "{:.12} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12}\n",
        t.x, t.y, t.z, q.x, q.y, q.z, q.w
    )
}

/// A COLMAP `images.txt` line of `world_from_camera` (it writes `camera_from_world`),
/// translations divided by `scale`.
fn colmap_line(name: &str, pose: &Isometry3, scale: f64) -> String {
    let inverse = pose.inverse();
    let (t, q) = (inverse.translation / scale, inverse.rotation);
    format!(
        "{name} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12} 525.5\n",
        q.w, q.x, q.y, q.z, t.x, t.y, t.z
    )
}

fn options() -> FuseOptions {
    FuseOptions {
        voxel_size_m: 0.02,
        min_frames: 2,
        ..FuseOptions::default()
    }
}

/// The cloud of the same frames added by hand, from the pictures as written (depth
/// rounded to millimetres, colour to 8 bits).
fn by_hand(dataset: &RgbdDataset) -> splat::PointCloud {
    let mut fusion = Fusion::new(Sensor::registered(pinhole(60.0)), options()).unwrap();
    for k in 10..=13 {
        let (depth, color) = dataset.read(k).unwrap();
        fusion
            .add(&depth, &color, &dataset.world_from_depth(k).unwrap())
            .unwrap();
    }
    fusion.cloud().unwrap()
}

fn same(a: &splat::PointCloud, b: &splat::PointCloud) -> bool {
    a.len() == b.len()
        && a.origin() == b.origin()
        && a.decoded().eq(b.decoded())
        && a.colors() == b.colors()
}

#[test]
fn both_pose_formats_give_the_poses_and_the_same_cloud_on_any_thread_count() {
    let dir = temp_dir("formats");
    let matrices: Vec<(String, String)> = poses()
        .iter()
        .enumerate()
        .map(|(k, p)| (format!("pose-{:02}.txt", 10 + k), matrix_text(p)))
        .collect();
    let lines = format!(
        "# tx ty tz qx qy qz qw\n{}",
        poses().iter().map(tum_line).collect::<String>()
    );
    // TUM's layout, a timestamp first.
    let tum = poses()
        .iter()
        .enumerate()
        .map(|(k, p)| format!("{}.5 {}", 1000 + k, tum_line(p)))
        .collect::<String>();
    let mut files: Vec<(&str, String)> = matrices
        .iter()
        .map(|(n, t)| (n.as_str(), t.clone()))
        .collect();
    files.push(("poses.txt", lines));
    files.push(("tum.txt", tum));
    files.push(("all.txt", poses().iter().map(matrix_text).collect()));
    // COLMAP's layout: out of order, among other pictures' lines, in units of 2 m.
    let mut colmap = String::from("# IMAGE_ID QW QX QY QZ TX TY TZ\n");
    for (k, p) in poses().iter().enumerate().rev() {
        colmap += &colmap_line(&format!("seq/f{}.png", 10 + k), p, 2.0);
        colmap += &colmap_line(&format!("other/f{}.png", 10 + k), &Isometry3::IDENTITY, 1.0);
    }
    files.push(("images.txt", colmap));
    let sections = [
        "[poses]\nkind = \"matrix\"\npath = \"pose-{:02}.txt\"\nof = \"color\"\n",
        "[poses]\nkind = \"matrix\"\npath = \"all.txt\"\nof = \"depth\"\n",
        "[poses]\nkind = \"lines\"\npath = \"poses.txt\"\nof = \"color\"\n",
        "[poses]\nkind = \"lines\"\npath = \"tum.txt\"\nof = \"depth\"\n",
        "[poses]\nkind = \"colmap\"\npath = \"images.txt\"\nof = \"color\"\nname = \"seq/f{}.png\"\nscale = 2.0\n",
    ];
    let mut clouds = Vec::new();
    for section in sections {
        let description = write_dataset(&dir, section, &files);
        let dataset = RgbdDataset::load(&description, dir.join("data")).unwrap();
        assert_eq!(dataset.frames(), [10, 13]);
        for (k, pose) in poses().iter().enumerate() {
            let got = dataset.world_from_color(10 + k as u64).unwrap();
            let (dt, dr) = got.distance_to(pose);
            assert!(
                dt < 1e-9 && dr < 1e-9,
                "{section}: frame {k}: {dt} m, {dr} rad"
            );
        }
        let frames = [10, 11, 12, 13];
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let mut calls = 0;
        let (a, report) = one
            .install(|| {
                dataset.fuse(&frames, options(), |done, total| {
                    calls += 1;
                    assert!(done <= total && total == 4);
                })
            })
            .unwrap();
        assert_eq!(calls, 4);
        assert_eq!(report.frames, 4);
        assert_eq!(report.points, a.len());
        let (b, _) = two
            .install(|| dataset.fuse(&frames, options(), |_, _| ()))
            .unwrap();
        assert!(same(&a, &b), "{section}: one and two threads differ");
        assert!(
            same(&a, &by_hand(&dataset)),
            "{section}: differs from frames added by hand"
        );
        clouds.push(a);
    }
    for c in &clouds[1..] {
        assert!(same(c, &clouds[0]));
    }
}

/// TUM RGB-D's layout: pictures named by timestamps, listed by an association file,
/// and motion-capture poses at their own rate, interpolated at each colour timestamp.
#[test]
fn timestamped_poses_are_interpolated_at_the_frames_of_an_association_file() {
    let dir = temp_dir("timestamped");
    write_dataset(&dir, "", &[]);
    let time = |k: usize| 1_305_031_229.5 + 0.1 * k as f64;
    // Line 0 lists a frame the description leaves out; lines 1..=4 the frames 10..=13.
    let mut associations = String::from("# timestamp rgb timestamp depth\n");
    associations += &format!(
        "{:.6} c10.png {:.6} d010.png\n",
        time(0) - 0.1,
        time(0) - 0.1
    );
    for k in 0..4 {
        associations += &format!(
            "{:.6} c{}.png {:.6} d{:03}.png\n",
            time(k),
            10 + k,
            time(k) + 0.004,
            10 + k
        );
    }
    // Two poses 10 ms apart around each frame, 5 mm on either side of its pose along
    // x: the frame's own pose halfway.
    let mut groundtruth = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (k, pose) in poses().iter().enumerate() {
        for (dt, dx) in [(-0.005, -0.005), (0.005, 0.005)] {
            let shifted = Isometry3::from_rotation_translation(
                pose.rotation,
                pose.translation + DVec3::new(dx, 0.0, 0.0),
            );
            groundtruth += &format!("{:.6} {}", time(k) + dt, tum_line(&shifted));
        }
    }
    std::fs::write(dir.join("data/associations.txt"), &associations).unwrap();
    std::fs::write(dir.join("data/groundtruth.txt"), &groundtruth).unwrap();
    let description = dir.join("tum.toml");
    let text = "frames = [1, 4]\nassociations = \"associations.txt\"\ndepth_scale_m = 0.001\n\
                color_camera = \"camera.toml\"\n\n[poses]\nkind = \"timestamped\"\n\
                path = \"groundtruth.txt\"\nof = \"color\"\n";
    std::fs::write(&description, text).unwrap();
    let dataset = RgbdDataset::load(&description, dir.join("data")).unwrap();
    assert_eq!(dataset.frames(), [1, 4]);
    for (k, pose) in poses().iter().enumerate() {
        let frame = 1 + k as u64;
        let got = dataset.world_from_color(frame).unwrap();
        // Timestamps of 1.3e9 s hold 0.2 µs: the halfway point to 1e-5 of the 1 cm.
        assert!((got.translation - pose.translation).length() < 1e-6, "{k}");
        assert!(got.rotation.angle_between(pose.rotation) < 1e-9, "{k}");
        // The depth picture 4 ms later: its camera's pose 4 mm along x.
        let depth_at = dataset.world_from_depth(frame).unwrap();
        let moved = pose.translation + DVec3::new(0.004, 0.0, 0.0);
        assert!((depth_at.translation - moved).length() < 1e-6, "{k}");
        assert_eq!(
            dataset.color_path(frame).unwrap(),
            dir.join(format!("data/c{}.png", 10 + k))
        );
        assert_eq!(
            dataset.depth_path(frame).unwrap(),
            dir.join(format!("data/d{:03}.png", 10 + k))
        );
        dataset.read(frame).unwrap();
    }
    // A frame whose poses are farther apart than max_gap_s, or beyond the poses: an
    // error when it is used (motion capture loses the camera now and then), not when
    // the dataset is read.
    for (gap, expected, frame) in [
        (
            text.replace("of = \"color\"", "of = \"color\"\nmax_gap_s = 0.005"),
            "apart",
            2,
        ),
        (
            text.replace("frames = [1, 4]", "frames = [0, 4]"),
            "both sides",
            0,
        ),
    ] {
        std::fs::write(&description, &gap).unwrap();
        let dataset = RgbdDataset::load(&description, dir.join("data")).unwrap();
        assert!(!dataset.has_pose(frame));
        let error = dataset.world_from_color(frame).unwrap_err().to_string();
        assert!(error.contains(expected), "{gap}: {error}");
        assert!(dataset.fuse(&[frame], options(), |_, _| ()).is_err());
    }
    // Timestamped poses without timestamps, more frames than listed, a line of three
    // words, patterns and associations together.
    for (bad, expected) in [
        (
            text.replace(
                "associations = \"associations.txt\"",
                "color = \"c{}.png\"\ndepth = \"d{:03}.png\"",
            )
            .replace("frames = [1, 4]", "frames = [10, 13]"),
            "needs the frames' timestamps",
        ),
        (
            text.replace("frames = [1, 4]", "frames = [1, 5]"),
            "lists 5 frames",
        ),
        (
            text.replace(
                "associations = \"associations.txt\"",
                "associations = \"groundtruth.txt\"",
            ),
            "expected `t_color color_file t_depth depth_file`",
        ),
        (
            text.replace("depth_scale_m", "color = \"c{}.png\"\ndepth_scale_m"),
            "either `color` and `depth`",
        ),
    ] {
        std::fs::write(&description, &bad).unwrap();
        let error = RgbdDataset::load(&description, dir.join("data")).unwrap_err();
        assert!(error.to_string().contains(expected), "{bad}: {error}");
    }
}

#[test]
fn rotations_written_to_few_digits_are_made_orthonormal() {
    let exact = DMat3::from_quat(DQuat::from_rotation_y(0.3) * DQuat::from_rotation_x(-0.2));
    let rounded = DMat3::from_cols_array(&exact.to_cols_array().map(|v| (v * 1e4).round() / 1e4));
    let r = nearest_rotation(rounded, 0.05).unwrap();
    let error = (r.transpose() * r - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(error < 1e-12, "{error}");
    assert!((r - exact).to_cols_array().iter().all(|v| v.abs() < 1e-4));
    // A reflection, a shear and NaN are not rotations.
    assert!(nearest_rotation(DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)), 0.05).is_none());
    assert!(
        nearest_rotation(
            DMat3::from_cols_array(&[1.0, 0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, 1.0]),
            0.05
        )
        .is_none()
    );
    assert!(nearest_rotation(DMat3::from_diagonal(DVec3::splat(f64::NAN)), 0.05).is_none());
}

#[test]
fn frame_name_patterns() {
    assert_eq!(
        frame_path("frame-{:06}.color.jpg", 42).unwrap(),
        "frame-000042.color.jpg"
    );
    assert_eq!(frame_path("color/{}.png", 3).unwrap(), "color/3.png");
    for bad in [
        "no-placeholder.png",
        "{:x}.png",
        "{:0}.png",
        "{:099}.png",
        "{.png",
    ] {
        assert!(frame_path(bad, 1).is_err(), "{bad}");
    }
}

#[test]
fn bad_descriptions_and_pose_files_are_typed_errors() {
    let dir = temp_dir("bad");
    let good_lines = poses().iter().map(tum_line).collect::<String>();
    let colmap = |k: usize| colmap_line(&format!("f{}.png", 10 + k), &poses()[k], 1.0);
    let cases: Vec<(&str, String)> = vec![
        // Too few poses for the frames.
        ("poses.txt", poses()[..2].iter().map(tum_line).collect()),
        // Six numbers on a line.
        ("poses.txt", "1 2 3 4 5 6\n".repeat(4)),
        // Not a number.
        ("poses.txt", good_lines.replacen("0.", "x.", 1)),
        // Not a unit quaternion.
        ("poses.txt", "0 0 0 0 0 0 3\n".repeat(4)),
        // Not a rotation matrix.
        ("all.txt", "1 0 0 0\n0 2 0 0\n0 0 1 0\n0 0 0 1\n".repeat(4)),
        // A last row that is not 0 0 0 1.
        ("all.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n".repeat(4)),
        // A ragged matrix.
        ("all.txt", "1 0 0 0\n0 1 0\n".into()),
        // COLMAP lines: a frame without its line, a picture given twice, a short line.
        ("images.txt", (0..3).map(colmap).collect()),
        ("images.txt", (0..4).chain([2]).map(colmap).collect()),
        (
            "images.txt",
            (1..4).map(colmap).collect::<String>() + "f10.png 1 0 0\n",
        ),
    ];
    for (name, text) in cases {
        let section = match name {
            "poses.txt" => "[poses]\nkind = \"lines\"\npath = \"poses.txt\"\nof = \"color\"\n",
            "all.txt" => "[poses]\nkind = \"matrix\"\npath = \"all.txt\"\nof = \"color\"\n",
            _ => {
                "[poses]\nkind = \"colmap\"\npath = \"images.txt\"\nof = \"color\"\nname = \"f{}.png\"\n"
            }
        };
        let description = write_dataset(&dir, section, &[(name, text.clone())]);
        let error = RgbdDataset::load(&description, dir.join("data")).unwrap_err();
        assert!(
            matches!(
                error,
                RgbdError::Pose { .. } | RgbdError::MissingPose { .. }
            ),
            "{text:?}: {error}"
        );
    }
    // A description with an unknown key, bad frames, or a missing camera.
    let files = [("poses.txt", good_lines.clone())];
    let section = "[poses]\nkind = \"lines\"\npath = \"poses.txt\"\nof = \"color\"\n";
    let description = write_dataset(&dir, section, &files);
    let text = std::fs::read_to_string(&description).unwrap();
    for bad in [
        text.replace("frames = [10, 13]", "frames = [13, 10]"),
        text.replace("depth_scale_m = 0.001", "depth_scale_m = -1.0"),
        text.replace("color = \"c{}.png\"", "color = \"c.png\""),
        text.clone() + "colour_camera = \"camera.toml\"\n",
        text.replace("camera.toml", "missing.toml"),
    ] {
        std::fs::write(&description, &bad).unwrap();
        assert!(
            RgbdDataset::load(&description, dir.join("data")).is_err(),
            "{bad}"
        );
    }
    // A good description whose pictures are missing or of another size.
    std::fs::write(&description, &text).unwrap();
    let dataset = RgbdDataset::load(&description, dir.join("data")).unwrap();
    assert!(dataset.read(9).is_err());
    std::fs::remove_file(dir.join("data/c12.png")).unwrap();
    assert!(matches!(dataset.read(12), Err(RgbdError::Image { .. })));
    image::RgbImage::new(32, 24)
        .save(dir.join("data/c12.png"))
        .unwrap();
    assert!(matches!(dataset.read(12), Err(RgbdError::Size { .. })));
    // A colour picture given as depth.
    std::fs::copy(dir.join("data/c11.png"), dir.join("data/d011.png")).unwrap();
    assert!(matches!(
        dataset.read(11),
        Err(RgbdError::DepthFormat { .. })
    ));
}

/// The house of the shared data (`PGM_DATA_DIR`), if it is there.
fn house() -> Option<RgbdDataset> {
    let data = test_support::data_dir()?;
    let root = test_support::workspace_root();
    Some(
        RgbdDataset::load(
            root.join("fixtures/real/house.toml"),
            data.join("rgbd/house"),
        )
        .unwrap(),
    )
}

#[test]
fn the_house_pictures_fuse_into_a_room() {
    let Some(dataset) = house() else {
        return;
    };
    assert_eq!(dataset.frames(), [1, 5]);
    let options = FuseOptions {
        min_frames: 1,
        ..FuseOptions::default()
    };
    let (cloud, report) = dataset.fuse(&[1, 2, 4, 5], options, |_, _| ()).unwrap();
    // 4 pictures of 640×480 with most depths measured, a few per cent on edges.
    assert_eq!(report.frames, 4);
    assert!(report.pixels.measured > 600_000, "{report:?}");
    let flying = report.pixels.flying as f64 / report.pixels.measured as f64;
    assert!((0.005..0.1).contains(&flying), "{report:?}");
    assert!(cloud.len() > 200_000, "{} points", cloud.len());
    // A room a few metres across.
    let (lowest, highest) = cloud.bounds();
    let size = highest - lowest;
    assert!(
        size.max_element() < 15.0 && size.min_element() > 1.0,
        "{size:?}"
    );
}

/// Neighbouring house pictures agree by depth: picture 4 aligned to picture 5 moves by
/// about a centimetre and fits it better; to picture 1, 2 m away along the corridor, it
/// moves by an order more (the SLAM poses disagree there).
#[test]
fn the_house_pictures_align_to_their_neighbours_by_depth() {
    let Some(dataset) = house() else {
        return;
    };
    let camera = &dataset.sensor().depth_camera;
    let options = rgbd::AlignOptions::default();
    let surface = |f| {
        let depth = dataset.read_depth(f).unwrap();
        rgbd::Surface::new(&depth, camera, &dataset.world_from_depth(f).unwrap(), 0.03).unwrap()
    };
    let query = dataset.read_depth(4).unwrap();
    let truth = dataset.world_from_depth(4).unwrap();
    let near = rgbd::align_depth(&query, camera, &truth, &[surface(5)], &options).unwrap();
    let (moved_m, _) = near.world_from_depth.distance_to(&truth);
    assert!(moved_m < 0.03, "{near:?}");
    assert!(near.rms_after_m <= near.rms_before_m, "{near:?}");
    assert!(near.pairs_after >= near.pairs_before, "{near:?}");
    let far = rgbd::align_depth(&query, camera, &truth, &[surface(1)], &options).unwrap();
    let (far_m, _) = far.world_from_depth.distance_to(&truth);
    assert!(far_m > 3.0 * moved_m, "{far:?} vs {near:?}");
}
