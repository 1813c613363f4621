//! Construction errors, TOML files and masks.

use crate::common::*;
use ucm::{Camera, Distortion, Intrinsics, Mask, UcmError, ValidRegion};

fn good() -> Intrinsics {
    Intrinsics {
        alpha_u: 54.0,
        alpha_v: 54.0,
        u0: 159.5,
        v0: 119.5,
        xi: 0.9,
        skew: 0.0,
    }
}

#[test]
fn bad_intrinsics_are_typed_errors() {
    let cases: Vec<(Intrinsics, &str)> = vec![
        (
            Intrinsics {
                alpha_u: 0.0,
                ..good()
            },
            "alpha_u",
        ),
        (
            Intrinsics {
                alpha_v: -3.0,
                ..good()
            },
            "alpha_v",
        ),
        (
            Intrinsics {
                u0: f64::NAN,
                ..good()
            },
            "u0",
        ),
        (
            Intrinsics {
                xi: f64::INFINITY,
                ..good()
            },
            "xi",
        ),
    ];
    for (intrinsics, name) in cases {
        let err = Camera::new(intrinsics, None, 320, 240, ValidRegion::Full).unwrap_err();
        assert!(err.to_string().contains(name), "{err}");
    }
    assert!(matches!(
        Camera::new(
            Intrinsics { xi: -0.1, ..good() },
            None,
            320,
            240,
            ValidRegion::Full
        ),
        Err(UcmError::NegativeXi(_))
    ));
    assert!(matches!(
        Camera::new(good(), None, 0, 240, ValidRegion::Full),
        Err(UcmError::EmptyImage { .. })
    ));
    assert!(matches!(
        Camera::new(
            good(),
            Some(Distortion {
                k1: f64::NAN,
                ..Default::default()
            }),
            320,
            240,
            ValidRegion::Full
        ),
        Err(UcmError::NonFinite { name: "k1", .. })
    ));
    assert!(matches!(
        Camera::new(good(), None, 320, 240, annulus(50.0, 20.0)),
        Err(UcmError::BadAnnulus { .. })
    ));
    // An annulus entirely outside the image leaves nothing valid.
    assert!(matches!(
        Camera::new(good(), None, 320, 240, annulus(500.0, 600.0)),
        Err(UcmError::EmptyRegion)
    ));
    let mask = Mask::new(10, 10, vec![true; 100]).unwrap();
    assert!(matches!(
        Camera::new(good(), None, 320, 240, ValidRegion::Mask(mask)),
        Err(UcmError::MaskSizeMismatch { .. })
    ));
}

#[test]
fn bad_toml_is_a_typed_error() {
    let base = std::fs::read_to_string(root().join("fixtures/omni-320x240.toml")).unwrap();
    let cases = [
        ("not toml at all [[[", "invalid camera file"),
        (&base.replace("\nxi = 0.9", "\nxi = -1.0"), "xi"),
        (&base.replace("\nxi = 0.9", "\nxi = nan"), "xi"),
        (&base.replace("alpha_u = 54.0", "alpha_u = 0.0"), "alpha_u"),
        (
            &base.replace("\nxi = 0.9", "\nxi = 0.9\nfocal = 3.0"),
            "unknown field",
        ),
        (&base.replace("alpha_v = 54.0\n", ""), "alpha_v"),
        (&base.replace("width = 320", "width = 0"), "image size"),
        (
            &base.replace("width = 320", "width = -5"),
            "invalid camera file",
        ),
        (
            &base.replace("kind = \"annulus\"", "kind = \"donut\""),
            "donut",
        ),
        (
            &base.replace("outer_radius_px = 116.91", "outer_radius_px = 10.0"),
            "annulus",
        ),
    ];
    for (text, expected) in cases {
        let err = Camera::from_toml_str(text, None).unwrap_err();
        assert!(
            err.to_string().contains(expected),
            "expected `{expected}` in: {err}"
        );
    }
    let missing = Camera::load_toml("/nonexistent/camera.toml").unwrap_err();
    assert!(matches!(missing, UcmError::Io { .. }), "{missing}");
    let mask = base.replace(
        "kind = \"annulus\"\ninner_radius_px = 26.81\nouter_radius_px = 116.91",
        "kind = \"mask\"\npath = \"missing-mask.png\"",
    );
    assert!(matches!(
        Camera::from_toml_str(&mask, None),
        Err(UcmError::MaskImage { .. })
    ));
}

#[test]
fn toml_round_trip_with_distortion_skew_and_mask() {
    let dir = std::env::temp_dir().join(format!("ucm-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();

    let camera = Camera::new(
        Intrinsics {
            skew: 0.25,
            ..good()
        },
        Some(Distortion {
            k1: -0.1,
            k2: 0.05,
            p1: 0.001,
            p2: -0.002,
            k3: 0.01,
        }),
        320,
        240,
        annulus(20.0, 110.0),
    )
    .unwrap();
    let path = dir.join("cam.toml");
    camera.save_toml(&path).unwrap();
    assert_eq!(Camera::load_toml(&path).unwrap(), camera);

    // A mask region: written beside the TOML as a PNG and read back identically.
    let flags: Vec<bool> = (0..320 * 240)
        .map(|i| (i / 320 + i % 320) % 3 != 0)
        .collect();
    let masked = camera
        .with_region(ValidRegion::Mask(
            Mask::new(320, 240, flags.clone()).unwrap(),
        ))
        .unwrap();
    let path = dir.join("masked.toml");
    masked.save_toml(&path).unwrap();
    let back = Camera::load_toml(&path).unwrap();
    assert_eq!(back.valid_pixels(), &flags[..]);
    assert!(dir.join("masked.mask.png").exists());
    // In memory, a mask has no path to write.
    assert!(masked.to_toml_string().is_err());
    // A mask picture whose header announces 100 000 × 100 000 pixels is refused from
    // its header, before it is decoded.
    let png = dir.join("masked.mask.png");
    let mut bytes = std::fs::read(&png).unwrap();
    // The IHDR chunk: length (4), type (4), width (4), height (4), ..., its CRC after
    // its 13 bytes of data.
    assert_eq!(&bytes[12..16], b"IHDR");
    bytes[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    bytes[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    let crc = test_support::png_crc32(&bytes[12..29]);
    bytes[29..33].copy_from_slice(&crc.to_be_bytes());
    std::fs::write(&png, &bytes).unwrap();
    assert!(matches!(
        Mask::from_image_file(&png),
        Err(UcmError::TooManyPixels {
            width: 100_000,
            height: 100_000
        })
    ));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn mei_yaml_errors() {
    let dir = std::env::temp_dir().join(format!("ucm-yaml-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bad.yaml");
    std::fs::write(&path, "K: [1, 2, 3]\nD: [0, 0, 0, 0]\nXi: [1.0]\n").unwrap();
    let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
    assert!(err.to_string().contains("expected 9 values"), "{err}");
    std::fs::write(&path, "D: [0, 0, 0, 0]\n").unwrap();
    let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
    assert!(err.to_string().contains("`K` not found"), "{err}");
    std::fs::write(
        &path,
        "K: [1, 0, 3, 0, 1, 3, 0, 0, 1]\nD: [0, x, 0, 0]\nXi: [1.0]\n",
    )
    .unwrap();
    let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
    assert!(err.to_string().contains("not a finite number"), "{err}");
    for (text, expected) in [
        (
            "K: [1, 0, 3, 0, 1, 3, 0, 0, 1]\nD: [0, 0, 0, 0]\nXi: [.nan]\n",
            "finite",
        ),
        (
            "K: [1, 0, 3, 0, 1, 3, 0, 0, 1\nD: [0, 0, 0, 0]\n",
            "not YAML",
        ),
        ("[1, 2, 3]\n", "not a mapping"),
        ("", "empty"),
        (
            "K: {rows: 3}\nD: [0, 0, 0, 0]\nXi: 1\n",
            "without a `data` list",
        ),
    ] {
        std::fs::write(&path, text).unwrap();
        let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
        assert!(err.to_string().contains(expected), "{text:?}: {err}");
    }
    // A binary file, and one far larger than a calibration, are refused as such.
    std::fs::write(&path, [0x4b, 0x3a, 0xff, 0xfe, 0x00]).unwrap();
    let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
    assert!(err.to_string().contains("not UTF-8"), "{err}");
    let err = Camera::load_toml(&path).unwrap_err();
    assert!(err.to_string().contains("not UTF-8"), "{err}");
    std::fs::write(&path, "# \n".repeat(1 << 19)).unwrap();
    let err = Camera::load_mei_yaml(&path, 100, 100, ValidRegion::Full).unwrap_err();
    assert!(err.to_string().contains("larger than"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The layouts a Mei calibration comes in are read as one camera: CRLF line ends,
/// comments in any script (and holding lists) before the keys, block-style lists, an
/// OpenCV `!!opencv-matrix` file with its `%YAML:1.0` line, `Xi` as a number.
#[test]
fn mei_yaml_layouts() {
    let dir = std::env::temp_dir().join(format!("ucm-yaml-layouts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let flow = "K: [300.5, 0.25, 160, 0, 301, 120.5, 0, 0, 1]\nD: [-0.1, 0.02, 0.001, -0.002]\nXi: [0.9]\n";
    let block = "K:\n  - 300.5\n  - 0.25\n  - 160\n  - 0\n  - 301\n  - 120.5\n  - 0\n  - 0\n  - 1\nD:\n  - -0.1\n  - 0.02\n  - 0.001\n  - -0.002\nXi: 0.9\n";
    let comments = format!(
        "# Étalonnage du miroir — caméra n° 2 (日本語)\n{}# D: [0, 0, 0, 0]\n{flow}",
        "# a comment line\n".repeat(20)
    );
    let opencv = "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 300.5, 0.25, 160., 0., 301., 120.5, 0., 0., 1. ]\nD: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ -0.1, 0.02, 0.001, -0.002 ]\nXi: !!opencv-matrix\n   rows: 1\n   cols: 1\n   dt: d\n   data: [ 0.9 ]\n";
    let load = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        Camera::load_mei_yaml(&path, 320, 240, ValidRegion::Full)
            .unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let reference = load("flow.yaml", flow);
    assert_eq!(reference.intrinsics().xi, 0.9);
    assert_eq!(reference.intrinsics().skew, 0.25);
    assert_eq!(reference.distortion().unwrap().k1, -0.1);
    for (name, text) in [
        ("crlf.yaml", flow.replace('\n', "\r\n")),
        ("comments-crlf.yaml", comments.replace('\n', "\r\n")),
        ("comments.yaml", comments.clone()),
        ("block.yaml", block.to_owned()),
        ("opencv.yaml", opencv.to_owned()),
    ] {
        let camera = load(name, &text);
        assert_eq!(camera.intrinsics(), reference.intrinsics(), "{name}");
        assert_eq!(camera.distortion(), reference.distortion(), "{name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
