//! [`Splat`]: a projected point as pass 1 writes it and pass 2 reads it, and the
//! pixels it covers.

use super::view::View;

/// A projected point, written by pass 1 and read by pass 2: four 32-bit words
/// `[where, width | intensity << 16, range, band limit]` (16 bytes, so that the vector
/// kernel writes it whole and a copy is one move). `where` is, for a single-pixel
/// splat (most of them), the index of its pixel in the region, row by row (the passes
/// read it without unpacking a column and a row and multiplying), and for a wider
/// splat `first column | first row << 16` of its top-left pixel (16-bit two's
/// complement each: it may start left of or above the region). The width is
/// [`NOT_DRAWN`] if the point is not seen (then the other fields are meaningless); the
/// intensity is in 16-bit fixed point; the range and its [`band_limit`] in metres, as
/// `f32` bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(align(16))]
pub(super) struct Splat(pub(super) [u32; 4]);

impl Splat {
    /// The splat whose top-left pixel is at column `iu` and row `iv` of a region
    /// `region_width` pixels wide.
    #[inline(always)]
    pub(super) fn new(
        [iu, iv, region_width]: [i32; 3],
        width: i32,
        intensity: i32,
        range_m: f32,
        limit_m: f32,
    ) -> Self {
        // Wrapping: a point that is not seen may have any column and row (its word is
        // then meaningless).
        let at = if width == 1 {
            iv.wrapping_mul(region_width).wrapping_add(iu) as u32
        } else {
            (iu as u32 & 0xFFFF) | ((iv as u32) << 16)
        };
        Self([
            at,
            (width as u32 & 0xFFFF) | ((intensity as u32) << 16),
            range_m.to_bits(),
            limit_m.to_bits(),
        ])
    }

    /// A point that is not seen.
    pub(super) fn not_drawn() -> Self {
        Self::new([0, 0, 0], i32::from(NOT_DRAWN), 0, 0.0, 0.0)
    }

    /// The first column (of a splat wider than a pixel).
    #[inline(always)]
    fn iu(&self) -> i32 {
        i32::from(self.0[0] as u16 as i16)
    }

    /// The first row (of a splat wider than a pixel).
    #[inline(always)]
    fn iv(&self) -> i32 {
        i32::from((self.0[0] >> 16) as u16 as i16)
    }

    #[inline(always)]
    pub(super) fn width(&self) -> u16 {
        self.0[1] as u16
    }

    #[inline(always)]
    pub(super) fn drawn(&self) -> bool {
        self.width() != NOT_DRAWN
    }

    #[inline(always)]
    pub(super) fn intensity(&self) -> u16 {
        (self.0[1] >> 16) as u16
    }

    #[inline(always)]
    pub(super) fn range_m(&self) -> f32 {
        f32::from_bits(self.0[2])
    }

    /// [`band_limit`] of the range.
    #[inline(always)]
    pub(super) fn limit_m(&self) -> f32 {
        f32::from_bits(self.0[3])
    }
}

pub(super) const NOT_DRAWN: u16 = u16::MAX;

impl Splat {
    /// The pixel of a single-pixel splat (drawn splats reach the image, and one pixel
    /// wide they are inside it): its index in the region.
    #[inline(always)]
    pub(super) fn single_pixel(&self) -> usize {
        self.0[0] as usize
    }

    /// The top-left pixel of a 3 × 3 splat inside the image whose rows can be read
    /// four pixels at a time from a buffer of `len` pixels (every 3 × 3 splat but at
    /// the buffer's last pixels).
    #[inline(always)]
    pub(super) fn whole_3x3(&self, view: &View, len: usize) -> Option<usize> {
        let (iu, iv) = (self.iu(), self.iv());
        let inside = self.width() == 3
            && iu >= 0
            && iv >= 0
            && iu + 3 <= view.width
            && iv + 3 <= view.height;
        if !inside {
            return None;
        }
        let first = iv as usize * view.width as usize + iu as usize;
        (first + 2 * view.width as usize + 4 <= len).then_some(first)
    }

    /// Call `f` with the index of every pixel the splat covers, clipped to the image
    /// (a drawn splat: `width != NOT_DRAWN`, so it reaches the image).
    #[inline(always)]
    pub(super) fn for_each_pixel(&self, view: &View, mut f: impl FnMut(usize)) {
        let w = view.width as usize;
        let (iu, iv, n) = (self.iu(), self.iv(), i32::from(self.width()));
        if n == 1 {
            // Most splats: a single pixel, inside the image.
            f(self.single_pixel());
            return;
        }
        if n == 3 && iu >= 0 && iv >= 0 && iu + 3 <= view.width && iv + 3 <= view.height {
            // 3 × 3 splats inside the image, without loops (whose exits a processor
            // cannot predict); the results do not depend on the order of the pixels.
            let first = iv as usize * w + iu as usize;
            for row in [first, first + w, first + 2 * w] {
                f(row);
                f(row + 1);
                f(row + 2);
            }
            return;
        }
        let (u0, u1) = (iu.max(0) as usize, (iu + n).min(view.width) as usize);
        let (v0, v1) = (iv.max(0) as usize, (iv + n).min(view.height) as usize);
        for row in v0..v1 {
            for k in row * w + u0..row * w + u1 {
                f(k);
            }
        }
    }
}

/// Pass 2 keeps a sample of range `range_m` at the pixels whose nearest range is at
/// least this (the sample is within the depth band of the nearest).
#[inline(always)]
pub(super) fn band_limit(range_m: f32, view: &View) -> f32 {
    range_m / view.band_factor
}
