use brightness::{Brightness, masked_gradient, normal_equations};
use frame::{Frame, PixelStatus};
use proptest::prelude::*;
use ucm::{Camera, Intrinsics, PixelGrid, ValidRegion};

#[test]
fn gradient_stays_inside_the_valid_region() {
    // A ramp in u, valid only in columns 2..6 of an 8×3 image.
    let (w, h) = (8, 3);
    let image: Vec<f32> = (0..w * h)
        .map(|k| (k % w) as f32 * 2.0 + 100.0 * f32::from(u8::from(k % w >= 6)))
        .collect();
    let valid: Vec<bool> = (0..w * h).map(|k| (2..6).contains(&(k % w))).collect();
    let mut out = vec![[9.0f32; 2]; w * h];
    masked_gradient(&image, &valid, w, h, &mut out);
    for k in 0..w * h {
        let i = k % w;
        if (2..6).contains(&i) {
            // The jump at column 6 is outside the region: not seen. One-sided at the edges.
            assert_eq!(out[k][0], 2.0, "column {i}");
            assert_eq!(out[k][1], 0.0);
        } else {
            assert_eq!(out[k], [0.0, 0.0]);
        }
    }
    // An isolated valid pixel has no gradient.
    let valid: Vec<bool> = (0..w * h).map(|k| k == w + 3).collect();
    masked_gradient(&image, &valid, w, h, &mut out);
    assert_eq!(out[w + 3], [0.0, 0.0]);
}

proptest! {
    #[test]
    fn normal_equations_match_the_explicit_product(
        rows in prop::collection::vec(prop::array::uniform7(-2.0f32..2.0), 1..700),
        seed in 0u64..1000,
    ) {
        let e: Vec<f32> = (0..rows.len()).map(|k| ((k as u64 * 7919 + seed) % 13) as f32 - 6.0).collect();
        let w: Vec<f32> = (0..rows.len()).map(|k| if (k as u64 + seed).is_multiple_of(5) { 0.0 } else { 1.0 }).collect();
        let (jtj, jte) = normal_equations::<7>(&rows, &e, Some(&w));
        for r in 0..7 {
            let mut b = 0.0f64;
            for c in 0..7 {
                let mut a = 0.0f64;
                for k in 0..rows.len() {
                    a += f64::from(w[k]) * f64::from(rows[k][r]) * f64::from(rows[k][c]);
                }
                prop_assert!((jtj[r][c] - a).abs() < 1e-3 * (1.0 + a.abs()), "[{r}][{c}] {} vs {a}", jtj[r][c]);
            }
            for k in 0..rows.len() {
                b += f64::from(w[k]) * f64::from(rows[k][r]) * f64::from(e[k]);
            }
            prop_assert!((jte[r] - b).abs() < 1e-3 * (1.0 + b.abs()));
        }
    }
}

#[test]
fn feature_rows_are_the_photometric_rows_of_the_grid() {
    let camera = Camera::new(
        Intrinsics {
            alpha_u: 30.0,
            alpha_v: 30.0,
            u0: 31.5,
            v0: 23.5,
            xi: 0.9,
            skew: 0.0,
        },
        None,
        64,
        48,
        ValidRegion::Annulus(ucm::Annulus {
            center_px: [31.5, 23.5],
            inner_radius_px: 5.0,
            outer_radius_px: 22.0,
        }),
    )
    .unwrap();
    let mut frame = Frame::for_camera(&camera);
    for k in 0..frame.intensity.len() {
        frame.intensity[k] = ((k % 64) as f32 * 0.3).sin() + ((k / 64) as f32 * 0.2).cos();
        frame.range_m[k] = 2.0 + (k % 5) as f32;
        frame.status[k] = if camera.valid_pixels()[k] {
            if k % 11 == 0 {
                PixelStatus::Sky
            } else {
                PixelStatus::Hit
            }
        } else {
            PixelStatus::Masked
        };
    }
    let mut feature = Brightness::new(&camera);
    feature.compute(&frame).unwrap();
    let grid = PixelGrid::new(&camera);
    assert_eq!(feature.samples().len(), camera.valid_pixel_count());
    for (s, &k) in feature.samples().iter().enumerate() {
        let k = k as usize;
        assert_eq!(feature.values()[s], frame.intensity[k]);
        let inv = if frame.status[k] == PixelStatus::Hit {
            1.0 / frame.range_m[k]
        } else {
            0.0
        };
        let expected = grid.factors()[k].photometric(feature.gradient()[k], inv);
        assert_eq!(feature.interaction()[s], expected);
        if frame.status[k] == PixelStatus::Sky {
            // Sky is at infinity: no translational motion.
            assert_eq!(&feature.interaction()[s][..3], &[0.0, 0.0, 0.0]);
        }
    }
    assert!(feature.compute(&Frame::new(3, 3)).is_err());
}
