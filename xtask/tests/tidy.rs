//! Tidy checks of the repository, run as tests (as rust-analyzer does).

use std::fs;
use std::path::Path;

use xtask::project_root;

fn read(path: &Path) -> String {
    fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn crate_dirs() -> Vec<std::path::PathBuf> {
    let mut dirs: Vec<_> = fs::read_dir(project_root().join("crates"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("Cargo.toml").exists())
        .collect();
    dirs.sort();
    dirs
}

#[test]
fn the_workspace_has_the_agreed_shape() {
    let root = project_root();
    for entry in [
        "Cargo.toml",
        "crates",
        "xtask",
        "fixtures",
        "benches",
        "docs",
        "README.md",
    ] {
        assert!(root.join(entry).exists(), "missing top-level {entry}");
    }
    assert!(root.join("docs/ARCHITECTURE.md").exists());
    let names: Vec<_> = crate_dirs()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for expected in ["bench-conv", "brightness", "pgm", "splat", "ucm", "vvs"] {
        assert!(
            names.iter().any(|n| n == expected),
            "missing crates/{expected}"
        );
    }
}

#[test]
fn every_member_inherits_the_workspace_lints_and_package() {
    let mut manifests: Vec<_> = crate_dirs().iter().map(|d| d.join("Cargo.toml")).collect();
    manifests.push(project_root().join("xtask/Cargo.toml"));
    manifests.push(project_root().join("benches/Cargo.toml"));
    for manifest in manifests {
        let text = read(&manifest);
        assert!(
            text.contains("[lints]\nworkspace = true"),
            "{} does not inherit [workspace.lints]",
            manifest.display()
        );
        assert!(
            text.contains("edition.workspace = true"),
            "{}",
            manifest.display()
        );
        // Versions are pinned once, in the root manifest.
        for line in text.lines() {
            let line = line.trim();
            assert!(
                !line.contains("version = \"") || line.starts_with("version.workspace"),
                "{}: pin `{line}` in [workspace.dependencies]",
                manifest.display()
            );
        }
    }
}

#[test]
fn every_library_denies_missing_docs_and_every_crate_is_in_the_architecture() {
    let architecture = read(&project_root().join("docs/ARCHITECTURE.md"));
    for dir in crate_dirs() {
        let lib = dir.join("src/lib.rs");
        if lib.exists() {
            assert!(
                read(&lib).contains("#![deny(missing_docs)]"),
                "{} lacks #![deny(missing_docs)]",
                lib.display()
            );
        }
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            architecture.contains(&format!("`{name}`")),
            "docs/ARCHITECTURE.md does not describe `{name}`"
        );
    }
}

#[test]
fn fixtures_are_up_to_date() {
    for (name, text) in xtask::fixtures::camera_files().unwrap() {
        let path = project_root().join("fixtures").join(name);
        assert_eq!(
            read(&path),
            text,
            "{name} is stale: run `cargo xtask fixtures`"
        );
    }
}

#[test]
fn readme_names_the_test_command_ci_runs() {
    let readme = read(&project_root().join("README.md"));
    let ci = read(&project_root().join(".ci/run"));
    let command = "cargo test --workspace";
    assert!(readme.contains(command), "README.md must give `{command}`");
    assert!(ci.contains(command), ".ci/run must run `{command}`");
}

/// The documents report rather than narrate: docs/RESULTS.md says where each experiment
/// stands (its newest figures, not their history) and README.md is a newcomer's page.
#[test]
fn results_and_readme_stay_short() {
    for (file, max_lines) in [("docs/RESULTS.md", 600), ("README.md", 150)] {
        let lines = read(&project_root().join(file)).lines().count();
        assert!(
            lines <= max_lines,
            "{file} has {lines} lines, more than {max_lines}: condense it"
        );
    }
}

/// A crate depends only on what its concept needs: the pictures and the features never
/// see the renderer, cloud files or the synthetic world (not even in their tests), the
/// renderer never sees a feature or a file format, and xtask links none of the
/// project's heavy crates.
#[test]
fn crates_depend_only_on_what_their_concept_needs() {
    let forbidden: [(&str, &[&str]); 8] = [
        (
            "crates/frame",
            &[
                "splat",
                "world",
                "las",
                "laz",
                "e57",
                "cloud-io",
                "brightness",
                "pgm",
                "vvs",
            ],
        ),
        (
            "crates/brightness",
            &[
                "splat", "world", "las", "laz", "e57", "cloud-io", "pgm", "vvs",
            ],
        ),
        (
            "crates/pgm",
            &["splat", "world", "las", "laz", "e57", "cloud-io", "vvs"],
        ),
        (
            "crates/splat",
            &[
                "las",
                "laz",
                "e57",
                "cloud-io",
                "brightness",
                "pgm",
                "vvs",
                "bench-conv",
            ],
        ),
        (
            "crates/cloud-io",
            &["world", "frame", "brightness", "pgm", "vvs", "bench-conv"],
        ),
        ("crates/world", &["brightness", "pgm", "vvs", "bench-conv"]),
        (
            "crates/rgbd",
            &["frame", "brightness", "pgm", "vvs", "world", "bench-conv"],
        ),
        (
            "xtask",
            &[
                "bench-conv",
                "vvs",
                "splat",
                "cloud-io",
                "pgm",
                "faer",
                "las",
                "plotters",
            ],
        ),
    ];
    for (dir, names) in forbidden {
        let manifest = project_root().join(dir).join("Cargo.toml");
        let text = read(&manifest);
        for line in text.lines() {
            let key = line.split(['.', '=', ' ']).next().unwrap_or("");
            assert!(
                !names.contains(&key),
                "{} depends on `{key}`",
                manifest.display()
            );
        }
    }
}

/// No Rust source file of the project holds more than 1200 lines: a longer one holds
/// several concepts, which get a module each.
#[test]
fn no_source_file_is_longer_than_1200_lines() {
    fn visit(dir: &Path, long: &mut Vec<String>) {
        for entry in fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy();
            if path.is_dir() {
                if name != "target" && !name.starts_with('.') {
                    visit(&path, long);
                }
            } else if name.ends_with(".rs") {
                let lines = read(&path).lines().count();
                if lines > 1200 {
                    long.push(format!("{} ({lines} lines)", path.display()));
                }
            }
        }
    }
    let mut long = Vec::new();
    for dir in ["crates", "xtask", "benches"] {
        visit(&project_root().join(dir), &mut long);
    }
    assert!(long.is_empty(), "split by concept: {long:?}");
}

/// The repository speaks of the project, not of how it was made: no tracked file
/// reads as a diary of its making (history is in git and `CHANGELOG.md`).
#[test]
fn no_file_is_a_diary() {
    let listed = std::process::Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(project_root())
        .output();
    // Outside a git checkout (a packaged crate) there is nothing to check.
    let Ok(listed) = listed else { return };
    let word = ["ses", "sion"].concat();
    let mut diary = Vec::new();
    for path in listed.stdout.split(|&b| b == 0).filter(|p| !p.is_empty()) {
        let path = project_root().join(String::from_utf8_lossy(path).as_ref());
        if let Ok(text) = fs::read_to_string(&path)
            && text.to_lowercase().contains(&word)
        {
            diary.push(path.display().to_string());
        }
    }
    assert!(diary.is_empty(), "files speaking of {word}s: {diary:?}");
}

/// Libraries report through their return values, not by printing, and read no
/// environment variable (but `isa`, whose switch for the AVX-512 paths is one): a
/// timer or a print left from a measurement fails here. Test modules (from a
/// `#[cfg(test)]` line followed by a `mod`) and comments are not read; `bench-conv`
/// (the experiments' program) and `test-support` are not libraries of the method.
#[test]
fn libraries_neither_print_nor_read_the_environment() {
    fn visit(dir: &Path, found: &mut Vec<String>) {
        for entry in fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                visit(&path, found);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = read(&path);
                let lines: Vec<&str> = text.lines().collect();
                for (i, line) in lines.iter().enumerate() {
                    let code = line.trim_start();
                    if code == "#[cfg(test)]"
                        && lines
                            .get(i + 1)
                            .is_some_and(|l| l.trim_start().starts_with("mod "))
                    {
                        break;
                    }
                    if code.starts_with("//") {
                        continue;
                    }
                    let allowed_env = path.ends_with("crates/isa/src/lib.rs");
                    let prints = ["println!", "print!(", "dbg!("]
                        .iter()
                        .any(|p| code.contains(p));
                    let reads_env = code.contains("env::var") && !allowed_env;
                    if prints || reads_env {
                        found.push(format!("{}:{}: {}", path.display(), i + 1, code));
                    }
                }
            }
        }
    }
    let mut found = Vec::new();
    for dir in crate_dirs() {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        if name != "bench-conv" && name != "test-support" {
            visit(&dir.join("src"), &mut found);
        }
    }
    assert!(found.is_empty(), "{found:#?}");
}
