//! Project automation behind `cargo xtask <command>` (see `cargo xtask help`).
//!
//! Kept to few dependencies: it builds the project's own crates and writes files.
#![deny(missing_docs)]

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::reproduce::Build;

pub mod fixtures;
pub mod reproduce;

/// The workspace root (the parent of `xtask/`).
pub fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask/ lives in the workspace root")
        .to_path_buf()
}

const HELP: &str = "\
cargo xtask <command>

commands:
  reproduce-fig3 [--quick] [--extras] [--paper-only] [--portable]
                       the convergence domain (§3, Fig. 3) on the synthetic city, as a
                       curve: the paper's protocol fixtures/protocol-fig3.toml (s = 1,
                       all 448 poses), the same at 0.25, 0.5 and 0.75 of its offsets on a
                       balanced subset (fixtures/protocol-fig3-domain.toml) and the basin
                       along each axis (fixtures/protocol-fig3-axes.toml, adaptive); the
                       curve and the basins in results/domain/ (domain.md, domain.csv,
                       domain.png/svg), each protocol's runs in results/fig3*/ (CSV,
                       summary.md, cdf.png/svg), all checked for consistency.
                       --quick: the CI subsets (fixtures/protocol-fig3*-quick.toml,
                       results/domain-quick/); --paper-only: the paper's protocol alone;
                       --extras: also the methods beyond the paper on the paper's protocol.
  reproduce-global [--quick] [--portable]
                       global localisation inside the prior box (beyond the paper, method
                       `global`): fixtures/protocol-global.toml (the 448 poses of Fig. 3 at
                       the paper's offsets and at half of them) and
                       fixtures/protocol-global-uniform.toml (starts drawn inside the box),
                       fixtures/protocol-global-any-heading*.toml (any heading, no compass;
                       the paper's translations and twice them),
                       fixtures/protocol-global-twice.toml (twice every offset); --quick:
                       fixtures/protocol-global*-quick.toml. Results in results/global*/.
  reproduce-fig4 [--quick] [--portable]
                       tracking by successive alignments (§4, Fig. 4): a shaken sequence
                       through the synthetic city tracked by PoT and PGMoT with 1 frame in
                       N, fixtures/sequence-fig4.toml; beyond the paper the same tracked
                       with the vignetting estimated and the last displacement repeated
                       (sequence-fig4-improved.toml), and over 110 m through two streets
                       (sequence-long.toml); --quick: their CI subsets (*-quick*.toml).
                       Results (frames.csv, summary.md, plots, overlays) in results/fig4*/
                       and results/long*/, checked for consistency.
  reproduce-real [--quick] [--seven-scenes DIR] [--tum DIR] [--portable]
                       real photographs localised and tracked in clouds fused from RGB-D
                       frames (fixtures/real/bench-*.toml): the house of
                       $PGM_DATA_DIR/rgbd/house (default ../shared/data), each picture left
                       out of a cloud of the others; with --seven-scenes DIR, 7-Scenes
                       redkitchen seq-01 (the folder data/ of the GitHub repository
                       andyzeng/tsdf-fusion-python; non-commercial licence, never
                       committed): localisation near the map and in a held-out block, a
                       global search, tracking, the queries resampled to a catadioptric
                       camera; and again with the structure-from-motion poses of
                       Brachmann et al. (ICCV 2021) when DIR holds
                       sfm_redkitchen_train.txt; with --tum DIR, TUM RGB-D freiburg1_rpy
                       judged against motion capture (TUM's archive unpacked, with the
                       association file of its associate.py as associations.txt).
                       Results in results/real/<name>/ (summary.md, runs.csv,
                       tracking.csv, plots, pictures/). --quick: the house's CI subset.

  All build bench-conv in release mode for this machine's instruction set
  (-C target-cpu=native, in target/native): the same numbers bit for bit, about 20 %
  sooner. --portable builds it for the baseline instruction set instead.
  fixtures [--check]   write fixtures/*.toml from their definition in xtask/src/fixtures.rs
                       (--check: fail if the committed files differ)
  help                 this text
";

/// Run one command with its arguments.
pub fn run(args: Vec<String>) -> anyhow::Result<()> {
    let (command, rest) = match args.split_first() {
        Some((c, rest)) => (c.as_str(), rest),
        None => ("help", &[][..]),
    };
    match command {
        "fixtures" => {
            let check = match rest {
                [] => false,
                [flag] if flag == "--check" => true,
                _ => bail!("usage: cargo xtask fixtures [--check]"),
            };
            let dir = project_root().join("fixtures");
            for (name, text) in fixtures::camera_files()? {
                let path = dir.join(name);
                if check {
                    let on_disk = std::fs::read_to_string(&path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    if on_disk != text {
                        bail!("{} is stale: run `cargo xtask fixtures`", path.display());
                    }
                } else {
                    std::fs::write(&path, text)
                        .with_context(|| format!("writing {}", path.display()))?;
                    println!("wrote {}", path.display());
                }
            }
            Ok(())
        }
        "reproduce-fig3" => {
            let (mut quick, mut extras, mut paper_only, mut build) =
                (false, false, false, Build::Native);
            for flag in rest {
                match flag.as_str() {
                    "--quick" => quick = true,
                    "--extras" => extras = true,
                    "--paper-only" => paper_only = true,
                    "--portable" => build = Build::Portable,
                    other => bail!("unknown flag `{other}`\n\n{HELP}"),
                }
            }
            reproduce::fig3(quick, extras, !paper_only, build)
        }
        "reproduce-global" => {
            let (quick, build) = quick_and_build(rest)?;
            reproduce::global(quick, build)
        }
        "reproduce-fig4" => {
            let (quick, build) = quick_and_build(rest)?;
            reproduce::fig4(quick, build)
        }
        "reproduce-real" => {
            let (mut quick, mut seven_scenes, mut tum, mut build) =
                (false, None, None, Build::Native);
            let mut flags = rest.iter();
            while let Some(flag) = flags.next() {
                match flag.as_str() {
                    "--quick" => quick = true,
                    "--portable" => build = Build::Portable,
                    "--seven-scenes" => {
                        let dir = flags
                            .next()
                            .with_context(|| format!("--seven-scenes needs a folder\n\n{HELP}"))?;
                        seven_scenes = Some(PathBuf::from(dir));
                    }
                    "--tum" => {
                        let dir = flags
                            .next()
                            .with_context(|| format!("--tum needs a folder\n\n{HELP}"))?;
                        tum = Some(PathBuf::from(dir));
                    }
                    other => bail!("unknown flag `{other}`\n\n{HELP}"),
                }
            }
            reproduce::real(quick, seven_scenes.as_deref(), tum.as_deref(), build)
        }
        "help" | "--help" | "-h" => {
            print!("{HELP}");
            Ok(())
        }
        other => bail!("unknown command `{other}`\n\n{HELP}"),
    }
}

/// The flags `--quick` and `--portable`, the only ones of most reproductions.
fn quick_and_build(flags: &[String]) -> anyhow::Result<(bool, Build)> {
    let (mut quick, mut build) = (false, Build::Native);
    for flag in flags {
        match flag.as_str() {
            "--quick" => quick = true,
            "--portable" => build = Build::Portable,
            other => bail!("unknown flag `{other}`\n\n{HELP}"),
        }
    }
    Ok((quick, build))
}
