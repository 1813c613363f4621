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
    /// of pixels filled.
    #[inline(always)]
    pub(super) fn fill_holes(&mut self, frame: &mut Frame) -> usize {
        self.status.copy_from_slice(&frame.status);
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let mut filled = 0;
        for j in 1..h.saturating_sub(1) {
            for i in 1..w - 1 {
                let k = j * w + i;
                if self.status[k] != PixelStatus::Sky {
                    continue;
                }
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
