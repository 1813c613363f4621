//! Shared helpers: the fixture camera's path, a street-like frame.

use frame::{Frame, PixelStatus};
pub use test_support::workspace_root as root;

/// A deterministic frame with the statistics of a street view (the render → feature
/// pipeline itself is tested in `vvs`, which composes the renderer and the features):
/// texture at scales from 2 to 60 pixels, sharp edges, ranges from 2 to 40 m, a band
/// of sky, masked outside the camera's region.
pub fn street_like(camera: &ucm::Camera) -> Frame {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let mut frame = Frame::for_camera(camera);
    let hash = |x: i64, y: i64| {
        let mut v = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        v ^= v >> 29;
        v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        (v >> 40) as f64 / (1u64 << 24) as f64
    };
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            if !camera.valid_pixels()[k] {
                frame.intensity[k] = 0.0;
                frame.range_m[k] = f32::NAN;
                frame.status[k] = PixelStatus::Masked;
                continue;
            }
            let (u, v) = (x as f64, y as f64);
            let radius = ((u - cx).powi(2) + (v - cy).powi(2)).sqrt();
            let angle = (v - cy).atan2(u - cx);
            if radius > 0.93 * cy && angle.sin() > 0.3 {
                frame.intensity[k] = 0.85;
                frame.status[k] = PixelStatus::Sky;
                continue;
            }
            let blocks = hash((u / 9.0).floor() as i64, (v / 7.0).floor() as i64);
            let fine = hash(x as i64, y as i64);
            let value = 0.45
                + 0.15 * (u / 23.0 + 1.3 * (v / 31.0).sin()).sin()
                + 0.1 * (angle * 7.0).cos()
                + 0.15 * (blocks - 0.5)
                + 0.06 * (fine - 0.5)
                + if (angle * 5.0).sin() > 0.6 { 0.12 } else { 0.0 };
            frame.intensity[k] = value.clamp(0.0, 1.0) as f32;
            frame.range_m[k] =
                (2.0 + 38.0 * (radius / cy).powi(3) * (1.0 + 0.2 * (angle * 3.0).sin())) as f32;
            frame.status[k] = PixelStatus::Hit;
        }
    }
    frame
}
