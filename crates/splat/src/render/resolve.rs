//! Pass 3 (resolve): each pixel's means, sky or mask from the buffers, which are
//! cleared on the way for the next rendering; then the filling of isolated holes.

use frame::{Frame, PixelStatus};

use super::view::Region;
use super::{COUNT_BITS, COUNT_MASK, EMPTY, INTENSITY_SCALE, RANGE_SCALE, Renderer};

impl Renderer {
    /// Pass 3, the resolve: the frame's intensity, range and status of every pixel from
    /// the buffers, which it clears as it reads them (then marks them cleared if every
    /// row was). Returns the pixels hit.
    #[inline(always)]
    pub(super) fn resolve(&mut self, frame: &mut Frame) -> usize {
        // Resolve: pixels outside the valid pixels' box are masked; inside it, row by
        // row without a branch (whether a pixel is hit is unpredictable at edges).
        let background = self.options.background;
        let valid = self.camera.valid_pixels();
        let image_width = self.camera.width() as usize;
        let Region {
            u0,
            v0,
            width,
            height,
        } = self.region;
        let (depth, accum) = (&mut self.depth[..], &mut self.accum[..]);
        let mut pixels_hit = 0;
        let mut rows_resolved = 0;
        let rows = frame
            .intensity
            .chunks_exact_mut(image_width)
            .zip(frame.range_m.chunks_exact_mut(image_width))
            .zip(frame.status.chunks_exact_mut(image_width))
            .zip(valid.chunks_exact(image_width));
        for (y, (((intensity, range_m), status), valid)) in rows.enumerate() {
            let inside = if (v0..v0 + height).contains(&y) {
                u0..u0 + width
            } else {
                0..0
            };
            for part in [0..inside.start, inside.end.max(inside.start)..image_width] {
                intensity[part.clone()].fill(0.0);
                range_m[part.clone()].fill(f32::NAN);
                status[part].fill(PixelStatus::Masked);
            }
            if inside.is_empty() {
                continue;
            }
            let r = (y - v0) * width;
            rows_resolved += 1;
            pixels_hit += resolve_row(
                &mut depth[r..r + width],
                &mut accum[r..r + width],
                &valid[inside.clone()],
                background,
                &mut intensity[inside.clone()],
                &mut range_m[inside.clone()],
                &mut status[inside],
            );
        }
        // Every row of the region resolved, hence cleared (`render` checked the frame's
        // buffers, so all of them are).
        self.cleared = rows_resolved == height;
        pixels_hit
    }

    /// Fill isolated sky pixels surrounded by hits (decided on the statuses before
    /// filling, so the result does not depend on the scan order). Returns the number
    /// of pixels filled. A row's hit neighbours are counted first for all its pixels at
    /// once (without a branch): only the sky pixels with three or more are candidates,
    /// where most sky pixels, in open sky, have none.
    #[inline(always)]
    pub(super) fn fill_holes(&mut self, frame: &mut Frame) -> usize {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        if w < 3 || h < 3 {
            return 0; // no pixel has eight neighbours
        }
        self.status.copy_from_slice(&frame.status);
        let hit = |s: &PixelStatus| u8::from(*s == PixelStatus::Hit);
        let mut filled = 0;
        let [columns, candidates] = &mut self.hole_rows;
        for j in 1..h.saturating_sub(1) {
            let rows = &self.status[(j - 1) * w..(j + 2) * w];
            let (above, rest) = rows.split_at(w);
            let (row, below) = rest.split_at(w);
            for (((count, a), r), b) in columns.iter_mut().zip(above).zip(row).zip(below) {
                *count = hit(a) + hit(r) + hit(b);
            }
            // Sky pixels with three hit neighbours or more (the pixel itself is not a
            // hit): the candidates, flagged for the row's inner pixels.
            let inner = w.saturating_sub(2);
            let sides = columns[..inner].iter().zip(&columns[2..]);
            let middle = columns[1..].iter().zip(&row[1..]);
            let flags = candidates[1..=inner].iter_mut().zip(sides.zip(middle));
            for (flag, ((&left, &right), (&centre, &status))) in flags {
                let neighbours = left + centre + right;
                *flag = u8::from(status == PixelStatus::Sky) & u8::from(neighbours >= 3);
            }
            for (group, flags) in candidates.chunks(8).enumerate() {
                let none = match <[u8; 8]>::try_from(flags) {
                    Ok(eight) => u64::from_ne_bytes(eight) == 0,
                    Err(_) => flags.iter().all(|&f| f == 0),
                };
                if none {
                    continue;
                }
                for (offset, _) in flags.iter().enumerate().filter(|(_, f)| **f != 0) {
                    let k = j * w + group * 8 + offset;
                    let mut sum = 0.0f32;
                    let mut count = 0;
                    let mut masked = 0;
                    let mut nearest = f32::INFINITY;
                    for dj in [-1isize, 0, 1] {
                        for di in [-1isize, 0, 1] {
                            let n = (k as isize + dj * w as isize + di) as usize;
                            if n != k && self.status[n] == PixelStatus::Hit {
                                sum += frame.intensity[n];
                                nearest = nearest.min(frame.range_m[n]);
                                count += 1;
                            }
                            masked += usize::from(self.status[n] == PixelStatus::Masked);
                        }
                    }
                    // At the valid region's edge: every valid neighbour (at least 3) hit.
                    if count >= 6 || (count >= 3 && count + masked == 8) {
                        frame.intensity[k] = sum / count as f32;
                        frame.range_m[k] = nearest; // the nearest neighbour's mean range
                        frame.status[k] = PixelStatus::Hit;
                        filled += 1;
                    }
                }
            }
        }
        filled
    }
}

/// Resolve a row of the valid pixels' box: the mean intensity and range of a pixel's
/// samples if it has some (a hit), the background and an infinite range if it has
/// none (sky), 0 and NaN outside the valid region (masked). Every pixel's means are
/// computed, and kept or not, so that the loop has no branch. Returns the hits. Leaves
/// the row's keys cleared ([`EMPTY`], 0 at masked pixels: `Renderer::valid_bits`) and
/// its sums zero, for the next rendering.
#[inline(always)]
fn resolve_row(
    depth: &mut [u32],
    accum: &mut [[u64; 2]],
    valid: &[bool],
    background: f32,
    intensity: &mut [f32],
    range_m: &mut [f32],
    status: &mut [PixelStatus],
) -> usize {
    let mut hits = 0;
    let pixels = depth
        .iter()
        .zip(accum.iter())
        .zip(valid)
        .zip(intensity.iter_mut())
        .zip(range_m.iter_mut())
        .zip(status.iter_mut());
    for (((((&key, &[sums, range_sum]), &valid), intensity), range_m), status) in pixels {
        let count = sums & COUNT_MASK;
        let hit = key != EMPTY && count != 0;
        let n = count as f64;
        let mean = ((sums >> COUNT_BITS) as f64 / (n * f64::from(INTENSITY_SCALE))) as f32;
        let mean_range = (range_sum as f64 / (n * f64::from(RANGE_SCALE))) as f32;
        (*intensity, *range_m, *status) = match (valid, hit) {
            (false, _) => (0.0, f32::NAN, PixelStatus::Masked),
            (true, true) => (mean, mean_range, PixelStatus::Hit),
            (true, false) => (background, f32::INFINITY, PixelStatus::Sky),
        };
        hits += usize::from(valid && hit);
    }
    // Cleared while the row is in the first level of cache.
    for (key, &valid) in depth.iter_mut().zip(valid) {
        *key = if valid { EMPTY } else { 0 };
    }
    accum.fill([0; 2]);
    hits
}

#[cfg(test)]
mod tests {
    //! The hole filling against its plain definition.

    use proptest::prelude::*;
    use ucm::{Camera, Intrinsics, ValidRegion};

    use super::*;
    use crate::render::tests::test_setup;

    /// The hole filling as it is defined: every sky pixel inside the image's border,
    /// looked at in turn, on the statuses before filling.
    fn fill_holes_plainly(frame: &mut Frame) -> usize {
        let status = frame.status.clone();
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let mut filled = 0;
        for j in 1..h - 1 {
            for i in 1..w - 1 {
                let k = j * w + i;
                if status[k] != PixelStatus::Sky {
                    continue;
                }
                let (mut sum, mut count, mut masked, mut nearest) = (0.0f32, 0, 0, f32::INFINITY);
                for n in [
                    k - w - 1,
                    k - w,
                    k - w + 1,
                    k - 1,
                    k,
                    k + 1,
                    k + w - 1,
                    k + w,
                    k + w + 1,
                ] {
                    if n != k && status[n] == PixelStatus::Hit {
                        sum += frame.intensity[n];
                        nearest = nearest.min(frame.range_m[n]);
                        count += 1;
                    }
                    masked += usize::from(status[n] == PixelStatus::Masked);
                }
                if count >= 6 || (count >= 3 && count + masked == 8) {
                    frame.intensity[k] = sum / count as f32;
                    frame.range_m[k] = nearest;
                    frame.status[k] = PixelStatus::Hit;
                    filled += 1;
                }
            }
        }
        filled
    }

    proptest! {
        /// The same pixels filled with the same bits as the plain definition, on random
        /// statuses (hits as dense as `hit_fraction`, some masked pixels), in images of
        /// any size (rows shorter than a group of eight flags, or than three pixels).
        #[test]
        fn holes_are_filled_as_defined(
            seed in any::<u64>(),
            hit_fraction in 0.0f64..1.0,
            masked_fraction in 0.0f64..0.3,
            (width, height) in prop_oneof![Just((320u32, 240u32)), (1u32..40, 1u32..40)],
        ) {
            let (_, options) = test_setup(200.0, 1.0, 0.0, 0.0, 1.25, 8);
            let intrinsics = Intrinsics {
                alpha_u: 200.0,
                alpha_v: 200.0,
                u0: f64::from(width) / 2.0,
                v0: f64::from(height) / 2.0,
                xi: 0.0,
                skew: 0.0,
            };
            let camera = Camera::new(intrinsics, None, width, height, ValidRegion::Full).unwrap();
            let mut renderer = Renderer::new(camera.clone(), options).unwrap();
            let mut frame = Frame::for_camera(&camera);
            let mut rng = crate::rng::SplitMix64::new(seed);
            for k in 0..frame.status.len() {
                let x = rng.unit();
                frame.status[k] = if x < masked_fraction {
                    PixelStatus::Masked
                } else if x < masked_fraction + (1.0 - masked_fraction) * hit_fraction {
                    PixelStatus::Hit
                } else {
                    PixelStatus::Sky
                };
                frame.intensity[k] = rng.unit() as f32;
                frame.range_m[k] = 1.0 + 10.0 * rng.unit() as f32;
            }
            let mut expected = frame.clone();
            let expected_filled = fill_holes_plainly(&mut expected);
            prop_assert_eq!(renderer.fill_holes(&mut frame), expected_filled);
            prop_assert_eq!(&frame.status, &expected.status);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(&frame.intensity), bits(&expected.intensity));
            prop_assert_eq!(bits(&frame.range_m), bits(&expected.range_m));
        }
    }
}
