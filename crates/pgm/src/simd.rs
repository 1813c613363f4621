//! Kernels run on the widest instruction set found at run time.
//!
//! [`on_widest`] hands a [`Kernel`] to [`pulp`]'s run-time dispatch: AVX-512 or AVX2
//! where the CPU has them, SSE2 on any x86-64. The kernel's `run` is always inlined,
//! so each instruction set gets its own copy of the loops, compiled for it; the loops
//! do the same operations in the same order on wider vectors, and Rust never fuses a
//! multiply and an add, so every instruction set gives the same bits (tested against
//! `on_scalar`). `pulp` makes this safe: the workspace denies unsafe code, and calling
//! a `target_feature` function needs it.

/// A loop nest to run on the widest instruction set; implement `run` with
/// `#[inline(always)]`.
pub(crate) trait Kernel: Sized {
    /// Run it.
    fn run(self);

    /// Run it on the instruction set `simd` (a kernel written with `S`'s vectors
    /// overrides it).
    #[inline(always)]
    fn run_on<S: pulp::Simd>(self, simd: S) {
        let _ = simd;
        self.run();
    }
}

/// Run `kernel` on the widest instruction set the CPU has.
pub(crate) fn on_widest(kernel: impl Kernel) {
    pulp::Arch::new().dispatch(Widest(kernel));
}

/// Run `kernel` compiled for the baseline instruction set (tests).
#[cfg(test)]
pub(crate) fn on_scalar(kernel: impl Kernel) {
    pulp::Simd::vectorize(pulp::Scalar, Widest(kernel));
}

struct Widest<K>(K);

impl<K: Kernel> pulp::WithSimd for Widest<K> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.0.run_on(simd);
    }
}
