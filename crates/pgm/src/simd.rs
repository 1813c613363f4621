//! Kernels run on the widest instruction set found at run time.
//!
//! [`on_widest`] runs a [`Kernel`] on the widest instruction set found at run time:
//! AVX-512, AVX2, or SSE4.2 (`pulp`'s x86-64 levels v4, v3, v2; every x86-64 processor
//! of the last fifteen years has the last), else the baseline. The kernel's `run` is
//! always inlined, so each instruction set gets its own copy of the loops, compiled
//! for it; the loops do the same operations in the same order on wider vectors, and
//! Rust never fuses a multiply and an add, so every instruction set gives the same
//! bits (tested on each level this processor has against the baseline). `pulp`
//! makes this safe: the workspace denies unsafe code, and calling a `target_feature`
//! function needs it.

/// A loop nest to run on the widest instruction set; implement `run` with
/// `#[inline(always)]`. `simd` is the instruction set's token (its vectors are
/// `S::f32s`); a loop left to the compiler ignores it.
pub(crate) trait Kernel: Sized {
    /// Run it.
    fn run<S: pulp::Simd>(self, simd: S);
}

/// Run `kernel` on the widest instruction set the CPU has.
pub(crate) fn on_widest(kernel: impl Kernel) {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(simd) = isa::avx512() {
            return pulp::Simd::vectorize(simd, Widest(kernel));
        }
        if let Some(simd) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(simd, Widest(kernel));
        }
        if let Some(simd) = pulp::x86::V2::try_new() {
            return pulp::Simd::vectorize(simd, Widest(kernel));
        }
    }
    on_scalar(kernel);
}

/// Run `kernel` compiled for the baseline instruction set.
pub(crate) fn on_scalar(kernel: impl Kernel) {
    pulp::Simd::vectorize(pulp::Scalar, Widest(kernel));
}

/// The instruction sets this processor has, widest first, the baseline last (tests).
#[cfg(test)]
pub(crate) fn levels() -> Vec<&'static str> {
    let mut levels = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        if pulp::x86::V4::try_new().is_some() {
            levels.push("AVX-512");
        }
        if pulp::x86::V3::try_new().is_some() {
            levels.push("AVX2");
        }
        if pulp::x86::V2::try_new().is_some() {
            levels.push("SSE4.2");
        }
    }
    levels.push("baseline");
    levels
}

/// Run `kernel` on the instruction set `level`, one of [`levels`] (tests).
#[cfg(test)]
pub(crate) fn on_level(level: &str, kernel: impl Kernel) {
    #[cfg(target_arch = "x86_64")]
    match level {
        "AVX-512" => {
            return pulp::Simd::vectorize(pulp::x86::V4::try_new().unwrap(), Widest(kernel));
        }
        "AVX2" => return pulp::Simd::vectorize(pulp::x86::V3::try_new().unwrap(), Widest(kernel)),
        "SSE4.2" => {
            return pulp::Simd::vectorize(pulp::x86::V2::try_new().unwrap(), Widest(kernel));
        }
        _ => {}
    }
    assert_eq!(level, "baseline");
    on_scalar(kernel);
}

struct Widest<K>(K);

impl<K: Kernel> pulp::WithSimd for Widest<K> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.0.run(simd);
    }
}
