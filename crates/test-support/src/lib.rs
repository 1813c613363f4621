//! Helpers shared by the workspace's integration tests: where the workspace and the
//! shared real data are, and the CRC of PNG chunks. A dev-dependency only, never
//! published.
#![deny(missing_docs)]

use std::path::PathBuf;

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The shared real data: `PGM_DATA_DIR`, else `../shared/data` beside the checkout.
/// `None` (the test is skipped, with a message) only outside CI: in CI (`CI` set) a
/// missing data folder fails the test.
pub fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("PGM_DATA_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else if std::env::var_os("CI").is_some() {
        panic!("PGM_DATA_DIR ({}) is not a folder in CI", dir.display());
    } else {
        eprintln!(
            "skipped: no data folder at {} (set PGM_DATA_DIR)",
            dir.display()
        );
        None
    }
}

/// The CRC-32 of PNG chunks (ISO 3309), bit by bit: for tests that rewrite a PNG's
/// header.
pub fn png_crc32(bytes: &[u8]) -> u32 {
    let mut crc = u32::MAX;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}
