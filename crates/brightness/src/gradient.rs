//! The image gradient inside a valid region.

/// Gradient `(∂I/∂u, ∂I/∂v)` of a row-major `width × height` image, inside the pixels
/// where `valid` is true: central differences where both neighbours are valid,
/// one-sided where one is, zero where none is (and zero outside the region). The edge
/// of the region, which does not move with the scene, therefore creates no gradient.
///
/// # Panics
/// If the slices do not all have `width × height` elements (callers check).
pub fn masked_gradient(
    image: &[f32],
    valid: &[bool],
    width: usize,
    height: usize,
    out: &mut [[f32; 2]],
) {
    let n = width * height;
    assert!(image.len() == n && valid.len() == n && out.len() == n);
    for j in 0..height {
        for i in 0..width {
            out[j * width + i] = gradient_at(image, valid, width, height, i, j);
        }
    }
}

/// [`masked_gradient`] at pixel `(i, j)`.
#[inline]
fn gradient_at(
    image: &[f32],
    valid: &[bool],
    width: usize,
    height: usize,
    i: usize,
    j: usize,
) -> [f32; 2] {
    let k = j * width + i;
    if !valid[k] {
        return [0.0, 0.0];
    }
    let left = i > 0 && valid[k - 1];
    let right = i + 1 < width && valid[k + 1];
    let gu = match (left, right) {
        (true, true) => 0.5 * (image[k + 1] - image[k - 1]),
        (true, false) => image[k] - image[k - 1],
        (false, true) => image[k + 1] - image[k],
        (false, false) => 0.0,
    };
    let up = j > 0 && valid[k - width];
    let down = j + 1 < height && valid[k + width];
    let gv = match (up, down) {
        (true, true) => 0.5 * (image[k + width] - image[k - width]),
        (true, false) => image[k] - image[k - width],
        (false, true) => image[k + width] - image[k],
        (false, false) => 0.0,
    };
    [gu, gv]
}

/// The valid region of an image split for [`MaskedGradient::compute`]: runs of
/// pixels whose four neighbours are all valid (central differences on both axes,
/// computed without a branch) and the other valid pixels, one by one.
#[derive(Clone, Debug, Default)]
pub(crate) struct MaskedGradient {
    width: usize,
    height: usize,
    /// `[start, end)` row-major pixel ranges of interior pixels.
    interior: Vec<[u32; 2]>,
    /// Valid pixels with at least one neighbour missing (invalid or outside).
    edge: Vec<u32>,
    /// The region planned (a picture compared against keeps its region from one
    /// iteration to the next: its plan is then kept, not built again).
    valid: Vec<bool>,
}

impl MaskedGradient {
    pub(crate) fn new(valid: &[bool], width: usize, height: usize) -> Self {
        let mut plan = Self::default();
        plan.rebuild(valid, width, height);
        plan
    }

    /// The plan of another region, in place (the buffers kept; nothing to do if the
    /// region is the one planned).
    pub(crate) fn rebuild(&mut self, valid: &[bool], width: usize, height: usize) {
        if (self.width, self.height) == (width, height) && self.valid == valid {
            return;
        }
        self.valid.clear();
        self.valid.extend_from_slice(valid);
        let (interior, edge) = (&mut self.interior, &mut self.edge);
        interior.clear();
        edge.clear();
        for j in 0..height {
            let row = j * width;
            for i in 0..width {
                let k = row + i;
                if !valid[k] {
                    continue;
                }
                let inside = i > 0
                    && i + 1 < width
                    && j > 0
                    && j + 1 < height
                    && valid[k - 1]
                    && valid[k + 1]
                    && valid[k - width]
                    && valid[k + width];
                if inside {
                    match interior.last_mut() {
                        // Interior pixels are never in the first or last column: a run
                        // never crosses a row.
                        Some(run) if run[1] as usize == k => run[1] += 1,
                        _ => interior.push([k as u32, k as u32 + 1]),
                    }
                } else {
                    edge.push(k as u32);
                }
            }
        }
        self.width = width;
        self.height = height;
    }

    /// [`masked_gradient`] at the valid pixels (the same values, bit for bit); `out` is
    /// left as it is at the others.
    #[inline(always)]
    pub(crate) fn compute(&self, image: &[f32], valid: &[bool], out: &mut [[f32; 2]]) {
        let w = self.width;
        for &[start, end] in &self.interior {
            let (start, end) = (start as usize, end as usize);
            let out = &mut out[start..end];
            let left = &image[start - 1..end - 1];
            let right = &image[start + 1..end + 1];
            let up = &image[start - w..end - w];
            let down = &image[start + w..end + w];
            for ((((o, &l), &r), &u), &d) in out.iter_mut().zip(left).zip(right).zip(up).zip(down) {
                *o = [0.5 * (r - l), 0.5 * (d - u)];
            }
        }
        for &k in &self.edge {
            let k = k as usize;
            out[k] = gradient_at(image, valid, w, self.height, k % w, k / w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The split computation equals the reference at every valid pixel, bit for
        /// bit, on random masks (holes, borders, isolated pixels).
        #[test]
        fn split_gradient_is_the_reference(
            width in 1usize..40,
            height in 1usize..30,
            seed in 0u64..10_000,
            density in 0.3f64..1.0,
        ) {
            let n = width * height;
            let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let mut next = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let valid: Vec<bool> = (0..n).map(|_| next() < density).collect();
            let image: Vec<f32> = (0..n).map(|_| next() as f32 * 2.0 - 0.5).collect();
            let mut expected = vec![[0.0f32; 2]; n];
            masked_gradient(&image, &valid, width, height, &mut expected);
            let mut got = vec![[0.0f32; 2]; n];
            MaskedGradient::new(&valid, width, height).compute(&image, &valid, &mut got);
            for k in 0..n {
                prop_assert_eq!(got[k].map(f32::to_bits), expected[k].map(f32::to_bits), "pixel {}", k);
            }
        }

        /// A plan rebuilt in place (for another region, for the same one again, back
        /// to the first, and for the same pixels read as another shape) computes what a
        /// new plan of that region does.
        #[test]
        fn a_plan_rebuilt_is_the_plan_of_its_region(
            width in 1usize..30,
            height in 1usize..20,
            seed in 0u64..10_000,
        ) {
            let n = width * height;
            let mut state = seed | 1;
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let first: Vec<bool> = (0..n).map(|_| next() < 0.7).collect();
            let mut second = first.clone();
            second[(next() * n as f64) as usize % n] ^= true;
            let image: Vec<f32> = (0..n).map(|_| next() as f32).collect();
            let mut plan = MaskedGradient::new(&first, width, height);
            for (valid, w, h) in [
                (&second, width, height),
                (&second, width, height),
                (&first, width, height),
                (&first, height, width),
            ] {
                plan.rebuild(valid, w, h);
                let mut got = vec![[0.0f32; 2]; n];
                plan.compute(&image, valid, &mut got);
                let mut expected = vec![[0.0f32; 2]; n];
                MaskedGradient::new(valid, w, h).compute(&image, valid, &mut expected);
                for k in 0..n {
                    prop_assert_eq!(got[k].map(f32::to_bits), expected[k].map(f32::to_bits));
                }
            }
        }
    }
}
