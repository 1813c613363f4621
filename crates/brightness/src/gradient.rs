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
        let row = j * width;
        for i in 0..width {
            let k = row + i;
            if !valid[k] {
                out[k] = [0.0, 0.0];
                continue;
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
            out[k] = [gu, gv];
        }
    }
}
