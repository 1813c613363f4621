#![cfg(target_arch = "x86_64")]

//! `PGM_NO_AVX512` is read once per process: each case runs in a child process of this
//! test binary with the variable set as it says.

use std::process::Command;

/// Run `test` of this binary in a child with `PGM_NO_AVX512` set to `value` (unset:
/// `None`).
fn child(test: &str, value: Option<&str>) -> bool {
    let mut command = Command::new(std::env::current_exe().unwrap());
    command
        .args(["--exact", test, "--test-threads", "1"])
        .env("ISA_CHILD", "1");
    match value {
        Some(value) => command.env(isa::NO_AVX512, value),
        None => command.env_remove(isa::NO_AVX512),
    };
    // Captured, so that the child's report does not mix with this one's.
    let output = command.output().unwrap();
    if !output.status.success() {
        eprintln!("{}", String::from_utf8_lossy(&output.stdout));
        eprintln!("{}", String::from_utf8_lossy(&output.stderr));
    }
    output.status.success()
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
    assert!(child("set_it_keeps_the_kernels_off_avx512", Some("1")));
    assert!(child("set_it_keeps_the_kernels_off_avx512", Some("yes")));
}

#[test]
fn unset_empty_or_zero_allows_avx512() {
    if std::env::var_os("ISA_CHILD").is_some() {
        assert!(isa::avx512_allowed());
        // As wide as the processor goes.
        assert_eq!(isa::avx512().is_some(), pulp::x86::V4::try_new().is_some());
        return;
    }
    assert!(child("unset_empty_or_zero_allows_avx512", None));
    assert!(child("unset_empty_or_zero_allows_avx512", Some("0")));
    assert!(child("unset_empty_or_zero_allows_avx512", Some("")));
}
