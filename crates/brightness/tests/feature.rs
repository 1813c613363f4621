use brightness::{Brightness, PixelRows, masked_gradient, normal_equations};
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
    let camera = annulus_camera();
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

/// A 64×48 catadioptric camera with an annulus.
fn annulus_camera() -> Camera {
    Camera::new(
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
    .unwrap()
}

/// The annulus camera and a smooth frame on it whose hits leave holes (every pixel of a
/// disc and of a band is sky).
fn holed_scene() -> (Camera, Frame) {
    let camera = annulus_camera();
    let mut frame = Frame::for_camera(&camera);
    for k in 0..frame.intensity.len() {
        let (x, y) = ((k % 64) as f32, (k / 64) as f32);
        frame.intensity[k] = 0.5 + 0.3 * (x * 0.3).sin() * (y * 0.2).cos();
        frame.range_m[k] = 2.0 + (k % 5) as f32;
        let hole = (x - 20.0).powi(2) + (y - 20.0).powi(2) < 25.0 || (30.0..33.0).contains(&x);
        frame.status[k] = match (camera.valid_pixels()[k], hole) {
            (false, _) => PixelStatus::Masked,
            (true, true) => PixelStatus::Sky,
            (true, false) => PixelStatus::Hit,
        };
    }
    (camera, frame)
}

/// Whether each pixel of `frame` is a rendered point.
fn hits(frame: &Frame) -> Vec<bool> {
    frame
        .status
        .iter()
        .map(|&s| s == PixelStatus::Hit)
        .collect()
}

/// A feature sharing another's tables (`Brightness::sharing_tables`) computes what
/// `Brightness::new` computes, bit for bit, after the other has computed something
/// else; so does a PGM built on it (`Pgm::from_brightness` is `pgm`'s, tested there).
#[test]
fn a_feature_sharing_tables_computes_what_a_new_one_does() {
    let (camera, frame) = holed_scene();
    let mut first = Brightness::new(&camera).with_normalization(true);
    first.compute(&frame).unwrap();
    let mut shared = first.sharing_tables().with_normalization(true);
    let mut new = Brightness::new(&camera).with_normalization(true);
    let mut other = frame.clone();
    other.intensity.iter_mut().for_each(|i| *i = 1.0 - *i);
    first.compute(&other).unwrap();
    shared.compute(&frame).unwrap();
    new.compute(&frame).unwrap();
    assert_eq!(shared.samples(), new.samples());
    assert_eq!(shared.values(), new.values());
    assert_eq!(shared.interaction(), new.interaction());
    assert_eq!(shared.gradient(), new.gradient());
    assert_ne!(first.values(), new.values());
}

/// A picture that holds intensities on part of the region is normalised over those
/// pixels alone, is 0 elsewhere, and has its gradient inside them.
#[test]
fn a_partly_observed_picture_is_normalised_and_differentiated_where_it_is_observed() {
    use frame::Restricted;
    let (camera, frame) = holed_scene();
    let hits = hits(&frame);
    let view = Restricted::new(&frame, &hits).unwrap();
    let mut feature = Brightness::new(&camera).with_normalization(true);
    feature.compute(&view).unwrap();
    assert!(!feature.all_observed());
    let image = feature.image();
    let (mut sum, mut squares) = (0.0f64, 0.0f64);
    for k in 0..image.len() {
        if hits[k] {
            sum += f64::from(image[k]);
            squares += f64::from(image[k]).powi(2);
        } else {
            assert_eq!(image[k], 0.0, "pixel {k} not observed");
        }
        assert_eq!(feature.observed()[k], hits[k]);
    }
    assert!(sum.abs() < 1e-4, "mean {sum}");
    assert!((squares - 1.0).abs() < 1e-4, "norm² {squares}");
    let mut expected = vec![[0.0f32; 2]; image.len()];
    masked_gradient(image, &hits, 64, 48, &mut expected);
    assert_eq!(feature.gradient(), &expected[..]);
    // Every pixel observed: the plain path, bit for bit.
    let all = vec![true; image.len()];
    let mut plain = Brightness::new(&camera).with_normalization(true);
    plain.compute(&frame).unwrap();
    feature
        .compute(&Restricted::new(&frame, &all).unwrap())
        .unwrap();
    assert!(feature.all_observed());
    assert_eq!(feature.values(), plain.values());
    assert_eq!(feature.interaction(), plain.interaction());
}

/// Against a picture, the gradient is `∇(H R) − P ∇H` inside the picture's observed
/// pixels, and the pixels next to the support's edge outside it take their neighbours'
/// inverse range; the values are the rendering's.
#[test]
fn rows_against_a_picture_follow_the_edge_of_the_support() {
    use brightness::Against;
    use frame::Restricted;
    let (camera, frame) = holed_scene();
    let (w, h, n) = (64, 48, 64 * 48);
    let hits = hits(&frame);
    // The picture observes the region but a corner.
    let observed: Vec<bool> = (0..n)
        .map(|k| camera.valid_pixels()[k] && !(k % w > 45 && k / w > 30))
        .collect();
    let picture: Vec<f32> = (0..n)
        .map(|k| {
            if observed[k] {
                0.4 + 0.01 * (k % 7) as f32
            } else {
                0.0
            }
        })
        .collect();
    let support: Vec<bool> = hits.iter().zip(&observed).map(|(&a, &b)| a && b).collect();
    let view = Restricted::new(&frame, &support).unwrap();
    let mut feature = Brightness::new(&camera);
    let against = Against {
        intensity: &picture,
        observed: &observed,
    };
    feature.compute_against(&view, against).unwrap();
    let mut plain = Brightness::new(&camera);
    plain.compute(&view).unwrap();
    assert_eq!(feature.values(), plain.values());
    let masked: Vec<f32> = (0..n)
        .map(|k| if support[k] { frame.intensity[k] } else { 0.0 })
        .collect();
    let indicator: Vec<f32> = support.iter().map(|&s| f32::from(u8::from(s))).collect();
    let (mut g_r, mut g_h) = (vec![[0.0f32; 2]; n], vec![[0.0f32; 2]; n]);
    masked_gradient(&masked, &observed, w, h, &mut g_r);
    masked_gradient(&indicator, &observed, w, h, &mut g_h);
    let grid = PixelGrid::new(&camera);
    let mut edge_pixels = 0;
    for k in 0..n {
        let expected = [
            g_r[k][0] - picture[k] * g_h[k][0],
            g_r[k][1] - picture[k] * g_h[k][1],
        ];
        let got = feature.gradient()[k];
        for c in 0..2 {
            assert!(
                (got[c] - expected[c]).abs() < 1e-6,
                "pixel {k}: {got:?} vs {expected:?}"
            );
        }
        if observed[k] && !support[k] && g_h[k] != [0.0; 2] {
            edge_pixels += 1;
            let (x, y) = (k % w, k / w);
            let neighbours: Vec<f32> = [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)]
                .into_iter()
                .map(|(a, b)| b * w + a)
                .filter(|&j| support[j])
                .map(|j| 1.0 / frame.range_m[j])
                .collect();
            let inverse = neighbours.iter().sum::<f32>() / neighbours.len().max(1) as f32;
            let row = grid.factors()[k].photometric(got, inverse);
            let s = feature
                .samples()
                .iter()
                .position(|&p| p as usize == k)
                .unwrap();
            for c in 0..6 {
                assert!(
                    (feature.interaction()[s][c] - row[c]).abs() < 1e-5,
                    "pixel {k}"
                );
            }
        }
    }
    assert!(edge_pixels > 20, "{edge_pixels} pixels on the edge");
    // Buffers of the wrong size are refused.
    let short = Against {
        intensity: &picture[1..],
        observed: &observed,
    };
    assert!(feature.compute_against(&view, short).is_err());
}

/// `Brightness::compute_image` gives what `compute_pixels` gives of the image (values,
/// observed pixels, inverse ranges, normalisation), bit for bit, partly observed or not,
/// normalised or not, and leaves the derivatives as they were.
#[test]
fn the_image_alone_is_the_image_of_the_whole_computation() {
    use frame::Restricted;
    let (camera, frame) = holed_scene();
    let hits = hits(&frame);
    let all = vec![true; hits.len()];
    let mut other = frame.clone();
    other.intensity.iter_mut().for_each(|i| *i = 1.0 - *i);
    for normalize in [false, true] {
        for observed in [&hits, &all] {
            let view = Restricted::new(&frame, observed).unwrap();
            let mut whole = Brightness::new(&camera).with_normalization(normalize);
            whole.compute_pixels(&view, PixelRows::Stored).unwrap();
            let mut image = Brightness::new(&camera).with_normalization(normalize);
            image.compute_pixels(&other, PixelRows::Stored).unwrap();
            let (ranges, gradient, rows) = (
                image.inverse_range().to_vec(),
                image.gradient().to_vec(),
                image.pixel_interaction().to_vec(),
            );
            image.compute_image(&view).unwrap();
            assert_eq!(image.image(), whole.image());
            assert_eq!(image.observed(), whole.observed());
            assert_eq!(image.all_observed(), whole.all_observed());
            assert_eq!(image.normalization_mean(), whole.normalization_mean());
            assert_eq!(image.normalization_scale(), whole.normalization_scale());
            assert_eq!(image.inverse_range(), &ranges[..]);
            assert_eq!(image.gradient(), &gradient[..]);
            assert_eq!(image.pixel_interaction(), &rows[..]);
            assert_ne!(image.gradient(), whole.gradient());
        }
    }
}

/// Rows computed on demand (`interaction_row`) are the stored rows, bit for bit, after
/// a computation that stores them or one that does not, of a partly observed picture
/// or a whole one, against a picture or not, normalised or not.
#[test]
fn rows_on_demand_are_the_stored_rows() {
    use brightness::Against;
    use frame::Restricted;
    let (camera, frame) = holed_scene();
    let (w, h) = (64, 48);
    let hits = hits(&frame);
    let all = vec![true; hits.len()];
    let picture: Vec<f32> = (0..w * h).map(|k| 0.3 + 0.01 * (k % 11) as f32).collect();
    let against = Against {
        intensity: &picture,
        observed: camera.valid_pixels(),
    };
    let on_demand_rows = |b: &Brightness| {
        let mut rows = vec![[f32::NAN; 6]; w * h];
        for (y, row) in rows.chunks_exact_mut(w).enumerate() {
            b.interaction_row(y, row);
        }
        rows
    };
    let bits = |rows: &[[f32; 6]]| {
        rows.iter()
            .flatten()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    };
    for normalize in [false, true] {
        for observed in [&hits, &all] {
            let view = Restricted::new(&frame, observed).unwrap();
            for with_picture in [false, true] {
                let compute = |b: &mut Brightness, rows| {
                    if with_picture {
                        b.compute_pixels_against(&view, against, rows).unwrap();
                    } else {
                        b.compute_pixels(&view, rows).unwrap();
                    }
                };
                let mut stored = Brightness::new(&camera).with_normalization(normalize);
                compute(&mut stored, PixelRows::Stored);
                let mut deferred = Brightness::new(&camera).with_normalization(normalize);
                compute(&mut deferred, PixelRows::OnDemand);
                assert!(
                    deferred
                        .pixel_interaction()
                        .iter()
                        .flatten()
                        .all(|&v| v == 0.0)
                );
                assert_eq!(
                    bits(&on_demand_rows(&stored)),
                    bits(stored.pixel_interaction())
                );
                assert_eq!(
                    bits(&on_demand_rows(&deferred)),
                    bits(stored.pixel_interaction())
                );
                assert!(
                    stored
                        .pixel_interaction()
                        .iter()
                        .flatten()
                        .any(|&v| v != 0.0)
                );
            }
        }
    }
}
