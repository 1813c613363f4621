//! Measured images: reading files of every depth and colour, crops, sizes, pyramids;
//! the `AnyImage` view of frames and images.

use std::path::PathBuf;

use frame::{AnyImage, Frame, FrameError, Image, PixelStatus};
use proptest::prelude::*;
use ucm::{Annulus, Camera, Intrinsics, ValidRegion};

fn camera(width: u32, height: u32, region: ValidRegion) -> Camera {
    let intrinsics = Intrinsics {
        alpha_u: 20.0,
        alpha_v: 20.0,
        u0: f64::from(width) / 2.0 - 0.5,
        v0: f64::from(height) / 2.0 - 0.5,
        xi: 0.9,
        skew: 0.0,
    };
    Camera::new(intrinsics, None, width, height, region).unwrap()
}

fn annulus(width: u32, height: u32) -> ValidRegion {
    ValidRegion::Annulus(Annulus {
        center_px: [f64::from(width) / 2.0 - 0.5, f64::from(height) / 2.0 - 0.5],
        inner_radius_px: 3.0,
        outer_radius_px: f64::from(height) / 2.0,
    })
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("frame-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A grey ramp, 8 bits, read back exactly and masked by the camera's region.
#[test]
fn reads_8_bit_grey_and_masks_the_region() {
    let (w, h) = (40, 30);
    let picture = image::GrayImage::from_fn(w, h, |x, y| image::Luma([(x * 6 + y) as u8]));
    let path = temp("grey8.png");
    picture.save(&path).unwrap();
    let camera = camera(w, h, annulus(w, h));
    let read = Image::load(&path, &camera, None).unwrap();
    assert_eq!((read.width(), read.height()), (w, h));
    for y in 0..h {
        for x in 0..w {
            let k = (y * w + x) as usize;
            assert_eq!(read.valid[k], camera.valid_pixels()[k]);
            let expected = if read.valid[k] {
                f32::from((x * 6 + y) as u8) / 255.0
            } else {
                0.0
            };
            assert_eq!(read.intensity[k], expected, "pixel {x},{y}");
        }
    }
    assert!(read.valid_count() > 0 && read.valid_count() < (w * h) as usize);
}

/// 16-bit pictures keep their precision; colour becomes Rec. 709 luminance.
#[test]
fn reads_16_bit_and_colour() {
    let (w, h) = (16, 12);
    let camera = camera(w, h, ValidRegion::Full);
    let grey16 = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
        image::Luma([(x * 4000 + y * 10) as u16])
    });
    let path = temp("grey16.png");
    grey16.save(&path).unwrap();
    let read = Image::load(&path, &camera, None).unwrap();
    assert_eq!(read.intensity[3], (3.0 * 4000.0) / 65535.0);
    assert_eq!(read.intensity[(w + 1) as usize], (4000.0 + 10.0) / 65535.0);

    // Pure red, green and blue columns: the luminance weights, within 8-bit rounding.
    let colours = [[255u8, 0, 0], [0, 255, 0], [0, 0, 255]];
    let rgb = image::RgbImage::from_fn(w, h, |x, _| image::Rgb(colours[(x % 3) as usize]));
    let path = temp("rgb8.png");
    rgb.save(&path).unwrap();
    let read = Image::load(&path, &camera, None).unwrap();
    for (x, weight) in [0.2126f32, 0.7152, 0.0722].into_iter().enumerate() {
        assert!(
            (read.intensity[x] - weight).abs() <= 0.5 / 255.0 + 1e-6,
            "column {x}: {} vs {weight}",
            read.intensity[x]
        );
    }

    // The same through a JPEG (lossy: only roughly).
    let path = temp("rgb8.jpg");
    image::RgbImage::from_pixel(w, h, image::Rgb([0, 255, 0]))
        .save(&path)
        .unwrap();
    let read = Image::load(&path, &camera, None).unwrap();
    assert!((read.intensity[50] - 0.7152).abs() < 0.03);
}

/// A crop selects the calibrated part; a crop that leaves the picture, a size that is
/// not the camera's, a missing or broken file are typed errors.
#[test]
fn crops_and_refuses_bad_input() {
    let picture = image::GrayImage::from_fn(50, 40, |x, y| image::Luma([(x + 2 * y) as u8]));
    let path = temp("big.png");
    picture.save(&path).unwrap();
    let camera = camera(20, 10, ValidRegion::Full);
    let read = Image::load(&path, &camera, Some([7, 5, 20, 10])).unwrap();
    assert_eq!(read.intensity[0], f32::from(7u8 + 10) / 255.0);
    assert_eq!(read.intensity[21], f32::from(8u8 + 12) / 255.0);
    assert!(matches!(
        Image::load(&path, &camera, Some([40, 5, 20, 10])),
        Err(FrameError::Crop { .. })
    ));
    assert!(matches!(
        Image::load(&path, &camera, Some([u32::MAX, 5, 20, 10])),
        Err(FrameError::Crop { .. })
    ));
    assert!(matches!(
        Image::load(&path, &camera, None),
        Err(FrameError::Size { .. })
    ));
    assert!(matches!(
        Image::load(temp("missing.png"), &camera, None),
        Err(FrameError::Image { .. })
    ));
    let broken = temp("broken.png");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&broken, &bytes).unwrap();
    let err = Image::load(&broken, &camera, Some([7, 5, 20, 10])).unwrap_err();
    assert!(matches!(err, FrameError::Image { .. }), "{err}");
    std::fs::write(&broken, b"not a picture at all").unwrap();
    assert!(Image::load(&broken, &camera, None).is_err());
}

/// A truncated JPEG is refused, where the decoder fills what it lacks with grey: cut
/// in half, cut to its headers and first bytes of data, cut just before its end marker.
/// The whole file, and the file with bytes after its end, are read.
#[test]
fn refuses_truncated_jpegs() {
    let picture = image::RgbImage::from_fn(64, 48, |x, y| {
        image::Rgb([(x * 4) as u8, (y * 5) as u8, ((x * y) % 251) as u8])
    });
    let path = temp("whole.jpg");
    picture.save(&path).unwrap();
    let camera = camera(64, 48, ValidRegion::Full);
    let whole = Image::load(&path, &camera, None).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let cut = temp("cut.jpg");
    let scan = bytes.windows(2).position(|w| w == [0xFF, 0xDA]).unwrap();
    for length in [bytes.len() / 2, scan + 40, bytes.len() - 2] {
        std::fs::write(&cut, &bytes[..length]).unwrap();
        match Image::load(&cut, &camera, None) {
            Err(FrameError::TruncatedJpeg { path }) => assert_eq!(path, cut),
            other => panic!("{length} of {} bytes: {other:?}", bytes.len()),
        }
    }
    let mut trailing = bytes.clone();
    trailing.extend_from_slice(b"trailing bytes");
    std::fs::write(&cut, &trailing).unwrap();
    assert_eq!(Image::load(&cut, &camera, None).unwrap(), whole);
}

/// A PNG header announcing more pixels than `ucm::MAX_PIXELS` is refused before any
/// decoding (the file itself is tiny).
#[test]
fn refuses_huge_announced_sizes() {
    let path = temp("huge.png");
    let mut png = Vec::new();
    png.extend_from_slice(b"\x89PNG\r\n\x1a\n");
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(b"IHDR");
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    png.extend_from_slice(&13u32.to_be_bytes());
    png.extend_from_slice(&ihdr);
    png.extend_from_slice(&test_support::png_crc32(&ihdr).to_be_bytes());
    for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
        png.extend_from_slice(&0u32.to_be_bytes());
        png.extend_from_slice(chunk);
        png.extend_from_slice(&test_support::png_crc32(chunk).to_be_bytes());
    }
    std::fs::write(&path, &png).unwrap();
    let camera = camera(20, 10, ValidRegion::Full);
    let err = Image::load(&path, &camera, None).unwrap_err();
    assert!(matches!(err, FrameError::TooManyPixels { .. }), "{err}");
}

/// Buffers of the wrong length are refused; invalid pixels read as 0.
#[test]
fn from_parts_checks_lengths() {
    assert!(matches!(
        Image::from_parts(4, 3, vec![0.5; 11], vec![true; 12]),
        Err(FrameError::Length { .. })
    ));
    let mut valid = vec![true; 12];
    valid[5] = false;
    let image = Image::from_parts(4, 3, vec![0.5; 12], valid).unwrap();
    assert_eq!(image.intensity[5], 0.0);
    assert!(!image.is_observed(5) && image.is_observed(4));
    let mut inverse = vec![1.0; 12];
    AnyImage::inverse_range(&image, &mut inverse).unwrap();
    assert!(inverse.iter().all(|&v| v == 0.0));
    assert!(AnyImage::inverse_range(&image, &mut [0.0; 3]).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Downsampling a measured image averages each block's valid pixels, follows the
    /// coarse camera's region, and agrees with the frame of the same observations where
    /// every observed pixel is a hit.
    #[test]
    fn downsampling_averages_valid_pixels(
        seed in 0u64..1000,
        factor in 1u32..4,
    ) {
        let (w, h) = (24 * factor, 18 * factor);
        let fine = camera(w, h, annulus(w, h));
        let coarse = fine.downsampled(factor).unwrap();
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let intensity: Vec<f32> = (0..w * h).map(|_| next()).collect();
        let valid: Vec<bool> = fine.valid_pixels().iter().map(|&v| v && next() > 0.2).collect();
        let image = Image::from_parts(w, h, intensity, valid).unwrap();
        let small = image.downsampled(factor, &coarse).unwrap();
        let mut frame = Frame::new(w, h);
        for k in 0..(w * h) as usize {
            if image.valid[k] {
                frame.intensity[k] = image.intensity[k];
                frame.status[k] = PixelStatus::Hit;
            } else {
                frame.intensity[k] = 0.0;
                frame.range_m[k] = f32::NAN;
                frame.status[k] = PixelStatus::Masked;
            }
        }
        let small_frame = frame.downsampled(factor, &coarse).unwrap();
        let k = factor as usize;
        for y in 0..18usize {
            for x in 0..24usize {
                let i = y * 24 + x;
                let block: Vec<usize> = (0..k)
                    .flat_map(|dy| (0..k).map(move |dx| (y * k + dy) * w as usize + x * k + dx))
                    .filter(|&j| image.valid[j])
                    .collect();
                let expect_valid = coarse.valid_pixels()[i] && !block.is_empty();
                prop_assert_eq!(small.valid[i], expect_valid);
                if expect_valid {
                    let mean = block.iter().map(|&j| image.intensity[j]).sum::<f32>()
                        / block.len() as f32;
                    prop_assert!((small.intensity[i] - mean).abs() < 1e-6);
                    prop_assert_eq!(small_frame.status[i], PixelStatus::Hit);
                    prop_assert_eq!(small_frame.intensity[i].to_bits(), small.intensity[i].to_bits());
                } else {
                    prop_assert_eq!(small.intensity[i], 0.0);
                }
            }
        }
        let wrong = matches!(image.downsampled(factor + 1, &coarse), Err(FrameError::Size { .. }));
        prop_assert!(wrong);
    }
}

/// A frame's observed pixels are its hits and sky; its inverse range is `1/ρ` on hits.
#[test]
fn frame_view() {
    let mut frame = Frame::new(3, 1);
    frame.status = vec![PixelStatus::Hit, PixelStatus::Sky, PixelStatus::Masked];
    frame.range_m = vec![4.0, f32::INFINITY, f32::NAN];
    assert!(frame.is_observed(0) && frame.is_observed(1) && !frame.is_observed(2));
    let mut inverse = vec![9.0; 3];
    AnyImage::inverse_range(&frame, &mut inverse).unwrap();
    assert_eq!(inverse, vec![0.25, 0.0, 0.0]);
    let image = Image::from_frame(&frame);
    assert_eq!(image.valid, vec![true, true, false]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The branch-free `observed_intensity` of frames and images is the trait's
    /// reference (each pixel's `is_observed`), bit for bit, on any stretch of pixels.
    #[test]
    fn observed_intensity_is_each_pixel_s_observation(
        pixels in prop::collection::vec((0u8..3, -2.0f32..2.0), 1..200),
        cut in (0usize..200, 0usize..200),
    ) {
        struct Reference<'a>(&'a Frame);
        impl AnyImage for Reference<'_> {
            fn width(&self) -> u32 { self.0.width() }
            fn height(&self) -> u32 { self.0.height() }
            fn intensity(&self) -> &[f32] { &self.0.intensity }
            fn is_observed(&self, index: usize) -> bool { self.0.is_observed(index) }
            fn inverse_range(&self, out: &mut [f32]) -> Result<(), FrameError> {
                AnyImage::inverse_range(self.0, out)
            }
            fn downsampled(&self, _: u32, _: &Camera) -> Result<Self, FrameError> {
                unreachable!("not used")
            }
        }
        let n = pixels.len();
        let mut frame = Frame::new(n as u32, 1);
        for (k, &(status, intensity)) in pixels.iter().enumerate() {
            frame.status[k] = [PixelStatus::Hit, PixelStatus::Sky, PixelStatus::Masked][status as usize];
            frame.intensity[k] = intensity;
        }
        let (a, b) = (cut.0 % (n + 1), cut.1 % (n + 1));
        let range = a.min(b)..a.max(b);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut expected = vec![7.0; range.len()];
        Reference(&frame).observed_intensity(range.clone(), &mut expected);
        for (k, &e) in range.clone().zip(&expected) {
            prop_assert_eq!(e, if frame.is_observed(k) { frame.intensity[k] } else { 0.0 });
        }
        let mut got = vec![7.0; range.len()];
        frame.observed_intensity(range.clone(), &mut got);
        prop_assert_eq!(bits(&got), bits(&expected));
        let image = Image::from_frame(&frame);
        image.observed_intensity(range.clone(), &mut got);
        let mut from_image = vec![7.0; range.len()];
        for (o, k) in from_image.iter_mut().zip(range) {
            *o = if image.is_observed(k) { image.intensity[k] } else { 0.0 };
        }
        prop_assert_eq!(bits(&got), bits(&from_image));
    }
}
