//! Plain views of the renderer's atomic buffers for the single-threaded passes.
//!
//! The buffers are atomics so that the multi-threaded passes can share them; one
//! thread that holds them exclusively reads and writes them as plain integers, which
//! lets a pass load and store several pixels with one instruction (atomics are never
//! vectorised). These are `AtomicU32::get_mut_slice` and `AtomicU64::get_mut_slice`,
//! unstable in the Rust this project builds with (`atomic_from_mut`, stabilised
//! later): to be replaced by them once the toolchain has them.

use std::sync::atomic::{AtomicU32, AtomicU64};

/// The depth buffer as plain keys.
#[allow(unsafe_code)]
pub(super) fn depths(depth: &mut [AtomicU32]) -> &mut [u32] {
    // SAFETY: `AtomicU32` has the same size, alignment and bit validity as `u32` (its
    // documentation: "the same in-memory representation as the underlying integer
    // type"), and the exclusive borrow rules out any other access, atomic or not,
    // while the plain view lives (std's `get_mut_slice` is this cast).
    unsafe { &mut *(std::ptr::from_mut(depth) as *mut [u32]) }
}

/// The accumulators as plain sums.
#[allow(unsafe_code)]
pub(super) fn sums(accum: &mut [[AtomicU64; 2]]) -> &mut [[u64; 2]] {
    // SAFETY: as in `depths`: `AtomicU64` has the size and bit validity of `u64` and
    // an alignment at least `u64`'s (so every `[AtomicU64; 2]` is a valid, aligned
    // `[u64; 2]`), and the borrow is exclusive.
    unsafe { &mut *(std::ptr::from_mut(accum) as *mut [[u64; 2]]) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::Ordering;

    /// The views read what the atomics hold and write what they then load.
    #[test]
    fn views_are_the_atomics_values() {
        let mut depth: Vec<AtomicU32> = (0..5).map(AtomicU32::new).collect();
        let plain = depths(&mut depth);
        assert_eq!(plain, &[0, 1, 2, 3, 4]);
        plain[3] = 42;
        assert_eq!(depth[3].load(Ordering::Relaxed), 42);
        let mut accum: Vec<[AtomicU64; 2]> = (0..3)
            .map(|k| [AtomicU64::new(k), AtomicU64::new(10 * k)])
            .collect();
        let plain = sums(&mut accum);
        assert_eq!(plain, &[[0, 0], [1, 10], [2, 20]]);
        plain[2][1] += 1;
        assert_eq!(accum[2][1].load(Ordering::Relaxed), 21);
    }
}
