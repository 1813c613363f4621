#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

use std::sync::OnceLock;

/// The environment variable that keeps the kernels off AVX-512.
pub const NO_AVX512: &str = "PGM_NO_AVX512";

/// Whether the kernels may use AVX-512 (read once: [`NO_AVX512`] unset, empty or `0`).
pub fn avx512_allowed() -> bool {
    static ALLOWED: OnceLock<bool> = OnceLock::new();
    *ALLOWED.get_or_init(|| std::env::var_os(NO_AVX512).is_none_or(|v| v.is_empty() || v == "0"))
}

/// AVX-512 (pulp's `V4`), if the processor has it and it is allowed.
#[cfg(target_arch = "x86_64")]
pub fn avx512() -> Option<pulp::x86::V4> {
    if avx512_allowed() {
        pulp::x86::V4::try_new()
    } else {
        None
    }
}

/// AVX-512 is never available off x86-64.
#[cfg(not(target_arch = "x86_64"))]
pub fn avx512() -> Option<std::convert::Infallible> {
    None
}

/// The widest instruction set allowed, for `pulp::Arch::dispatch`.
pub fn arch() -> pulp::Arch {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(simd) = avx512() {
            return pulp::Arch::V4(simd);
        }
        if let Some(simd) = pulp::x86::V3::try_new() {
            return pulp::Arch::V3(simd);
        }
        pulp::Arch::Scalar
    }
    #[cfg(not(target_arch = "x86_64"))]
    pulp::Arch::new()
}

/// The name of the widest instruction set allowed (reports).
pub fn widest_name() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if avx512().is_some() {
            return "AVX-512";
        }
        if pulp::x86::V3::try_new().is_some() {
            return "AVX2";
        }
    }
    "baseline"
}
