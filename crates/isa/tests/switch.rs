#![cfg(target_arch = "x86_64")]

//! `PGM_NO_AVX512` is read once per process: each case runs in a child process of this
//! test binary with the variable set as it says.

use std::process::Command;

/// Run `test` of this binary in a child with `PGM_NO_AVX512` set to `value`.
fn child(test: &str, value: &str) -> bool {
    Command::new(std::env::current_exe().unwrap())
        .args(["--exact", test, "--test-threads", "1"])
        .env("ISA_CHILD", "1")
        .env(isa::NO_AVX512, value)
        .status()
        .unwrap()
        .success()
}

#[test]
fn set_it_keeps_the_kernels_off_avx512() {
    if std::env::var_os("ISA_CHILD").is_some() {
        assert!(!isa::avx512_allowed());
        assert!(isa::avx512().is_none());
        assert_ne!(isa::widest_name(), "AVX-512");
        assert!(!matches!(isa::arch(), pulp::Arch::V4(_)));
        return;
    }
    assert!(child("set_it_keeps_the_kernels_off_avx512", "1"));
    assert!(child("set_it_keeps_the_kernels_off_avx512", "yes"));
}

#[test]
fn unset_empty_or_zero_allows_avx512() {
    if std::env::var_os("ISA_CHILD").is_some() {
        assert!(isa::avx512_allowed());
        // As wide as the processor goes.
        assert_eq!(isa::avx512().is_some(), pulp::x86::V4::try_new().is_some());
        return;
    }
    assert!(child("unset_empty_or_zero_allows_avx512", "0"));
    assert!(child("unset_empty_or_zero_allows_avx512", ""));
}
