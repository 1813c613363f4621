//! The results folder of a command: locked while one run writes it, marked incomplete
//! until every file is written, its files replaced atomically.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use super::MANIFEST;

/// The file that marks a results folder whose writing has not finished.
pub const INCOMPLETE_MARKER: &str = "INCOMPLETE";

/// The lock file of a results folder being written ([`begin_results`]).
pub const LOCK_FILE: &str = ".lock";

/// What a results folder may hold from an earlier run of any command: cleared by
/// [`begin_results`] with `force`. Files named `acquired-n*-frame*.png` (tracking's
/// last acquired frames) and the folder `pictures/` (the real benchmark's) go too.
pub const RESULT_FILES: &[&str] = &[
    "summary.md",
    "runs.csv",
    MANIFEST,
    "domain.csv",
    "domain.md",
    "domain.png",
    "domain.svg",
    "cdf.png",
    "cdf.svg",
    "frames.csv",
    "rmse.png",
    "rmse.svg",
    "errors.png",
    "errors.svg",
    "tracking.csv",
    "tracking.png",
    "tracking.svg",
    "poses.csv",
    INCOMPLETE_MARKER,
];

/// A results folder held by one run: its [`LOCK_FILE`] names the process, and goes
/// when this is dropped (at the end of the run, or when it fails).
#[derive(Debug)]
#[must_use = "the folder is unlocked when this is dropped"]
pub struct ResultsLock {
    path: PathBuf,
}

impl Drop for ResultsLock {
    fn drop(&mut self) {
        // Nothing to do if it is already gone.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether the process that wrote the lock file `path` still runs (on Linux, from
/// `/proc`; elsewhere a lock is taken as held).
fn lock_is_held(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return true;
    };
    match text.trim().parse::<u32>() {
        Ok(pid) if Path::new("/proc/self").exists() => {
            pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists()
        }
        Ok(_) => true,
        // Unreadable: written by something else, or half-written; held.
        Err(_) => true,
    }
}

/// Prepare the results folder `out` before any work, so that a bad `--out` fails at
/// once, two runs never write one folder, earlier results are never replaced without
/// being asked, and an interrupted run never leaves a folder that looks complete:
///
/// - the folder is created (an existing file there is an error);
/// - a folder another running process writes (its [`LOCK_FILE`]) is refused; a lock
///   left by a process that no longer runs is taken over;
/// - a folder holding results of an earlier run ([`RESULT_FILES`]) is refused unless
///   `force`, which removes them (other files are left alone);
/// - [`INCOMPLETE_MARKER`] is written until [`finish_results`].
pub fn begin_results(out: &Path, force: bool) -> anyhow::Result<ResultsLock> {
    if out.exists() && !out.is_dir() {
        bail!("{} exists and is not a folder", out.display());
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let lock_path = out.join(LOCK_FILE);
    let lock = loop {
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&lock_path)
        {
            Ok(mut file) => {
                use std::io::Write;
                let lock = ResultsLock {
                    path: lock_path.clone(),
                };
                writeln!(file, "{}", std::process::id())
                    .with_context(|| format!("writing {}", lock_path.display()))?;
                break lock;
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                if lock_is_held(&lock_path) {
                    bail!(
                        "another run is writing its results to {} (its lock file {}; remove it \
                         if no such run is going on)",
                        out.display(),
                        lock_path.display()
                    );
                }
                std::fs::remove_file(&lock_path)
                    .with_context(|| format!("removing the stale {}", lock_path.display()))?;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("creating {}", lock_path.display()));
            }
        }
    };
    let mut earlier: Vec<PathBuf> = Vec::new();
    for entry in std::fs::read_dir(out).with_context(|| format!("reading {}", out.display()))? {
        let entry = entry.with_context(|| format!("reading {}", out.display()))?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let ours = RESULT_FILES.contains(&name.as_ref())
            || name == "pictures"
            || (name.starts_with("acquired-n") && name.ends_with(".png"));
        if ours {
            earlier.push(entry.path());
        }
    }
    earlier.sort();
    if !earlier.is_empty() {
        if !force {
            let names: Vec<String> = earlier
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            bail!(
                "{} holds the results of an earlier run ({}): give --force to replace them, \
                 or another --out",
                out.display(),
                names.join(", ")
            );
        }
        for path in &earlier {
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(path)
            } else {
                std::fs::remove_file(path)
            };
            removed.with_context(|| format!("removing the earlier {}", path.display()))?;
        }
    }
    write_atomically(
        &out.join(INCOMPLETE_MARKER),
        b"These results are being written, or their writing was interrupted: do not use them.\n",
    )?;
    Ok(lock)
}

/// Mark the results folder `out` complete (every file written).
pub fn finish_results(out: &Path) -> anyhow::Result<()> {
    let marker = out.join(INCOMPLETE_MARKER);
    std::fs::remove_file(&marker).with_context(|| format!("removing {}", marker.display()))
}

/// Write `bytes` to `path` through a temporary file in the same folder and a rename,
/// so that `path` is never left half-written.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
}
