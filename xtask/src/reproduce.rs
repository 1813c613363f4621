//! `cargo xtask reproduce-fig3`: run the protocol with the release build of
//! `bench-conv`, then check the results for consistency.

use std::process::Command;

use anyhow::{Context, ensure};

use crate::project_root;

/// How `bench-conv` is compiled for a reproduction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Build {
    /// For the instruction set of the machine that runs it (`-C target-cpu=native`, in
    /// its own target folder `target/native`): the reproduction runs where it is built.
    /// The numbers are the same as the portable build's, bit for bit: Rust never fuses
    /// or reorders floating-point operations, so wider vector instructions compute the
    /// same IEEE operations (CI compares the two builds' quick Fig. 3).
    Native,
    /// For the baseline instruction set of the target, like any `cargo build`.
    Portable,
}

/// `cargo run --release -p bench-conv -- <args>` from the project root.
fn bench_conv(args: &[&std::ffi::OsStr], build: Build) -> anyhow::Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut command = Command::new(cargo);
    command
        .current_dir(project_root())
        .args(["run", "--release", "--quiet", "-p", "bench-conv"]);
    if build == Build::Native {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map_or_else(|| project_root().join("target"), Into::into);
        let mut flags = std::env::var("RUSTFLAGS").unwrap_or_default();
        flags.push_str(" -C target-cpu=native");
        command
            .arg("--target-dir")
            .arg(target.join("native"))
            .env("RUSTFLAGS", flags.trim_start());
    }
    // A reproduction replaces its earlier results (`--force`).
    let status = command
        .args(["--", "--force"])
        .args(args)
        .status()
        .context("running bench-conv")?;
    ensure!(status.success(), "bench-conv failed: {status}");
    Ok(())
}

/// Run the tracking experiment of Fig. 4 as the paper tracks (`sequence-fig4.toml`)
/// and beyond it (`sequence-fig4-improved.toml`, and over 110 m through two streets,
/// `sequence-long.toml`: vignetting estimated with the pose,
/// the last displacement repeated), or their quick subsets, and check the results.
pub fn fig4(quick: bool, build: Build) -> anyhow::Result<()> {
    let root = project_root();
    let runs: [(&str, &str); 3] = if quick {
        [
            ("sequence-fig4-quick.toml", "fig4-quick"),
            ("sequence-fig4-quick-improved.toml", "fig4-quick-improved"),
            ("sequence-long-quick.toml", "long-quick"),
        ]
    } else {
        [
            ("sequence-fig4.toml", "fig4"),
            ("sequence-fig4-improved.toml", "fig4-improved"),
            ("sequence-long.toml", "long"),
        ]
    };
    for (sequence, out) in runs {
        let sequence = root.join("fixtures").join(sequence);
        let out = root.join("results").join(out);
        for command in ["track", "check-track"] {
            bench_conv(
                &[
                    command.as_ref(),
                    sequence.as_os_str(),
                    "--out".as_ref(),
                    out.as_os_str(),
                ],
                build,
            )?;
        }
    }
    Ok(())
}

/// Run the Fig. 3 protocol (or its quick subset) and check the result files; with
/// `domain`, also the domain curve below the paper's offsets and the basin along each
/// axis (`fixtures/protocol-fig3-{domain,axes}[-quick].toml`), gathered with the
/// paper's protocol into `results/domain[-quick]/`.
pub fn fig3(quick: bool, extras: bool, domain: bool, build: Build) -> anyhow::Result<()> {
    let root = project_root();
    let suffix = if quick { "-quick" } else { "" };
    let fixture = |name: &str| {
        root.join("fixtures")
            .join(format!("protocol-{name}{suffix}.toml"))
    };
    let results = |name: &str| root.join("results").join(format!("{name}{suffix}"));
    run_protocol(&fixture("fig3"), &results("fig3"), extras, build)?;
    check(&fixture("fig3"), &results("fig3"), quick, extras, build)?;
    if !domain {
        return Ok(());
    }
    for name in ["fig3-domain", "fig3-axes"] {
        run_protocol(&fixture(name), &results(name), false, build)?;
        check(&fixture(name), &results(name), false, false, build)?;
    }
    let axes_protocol = fixture("fig3-axes");
    let (paper, below, axes, out) = (
        results("fig3"),
        results("fig3-domain"),
        results("fig3-axes"),
        results("domain"),
    );
    bench_conv(
        &[
            "domain".as_ref(),
            paper.as_os_str(),
            below.as_os_str(),
            "--axes-protocol".as_ref(),
            axes_protocol.as_os_str(),
            "--axes".as_ref(),
            axes.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ],
        build,
    )
}

/// Run the global localisation protocols (method `global`, beyond the paper): the
/// paper's poses at the corners of the box and at half of them, starts drawn
/// uniformly inside it, and starts with any heading searched without a compass (or the
/// quick subsets), and check the result files.
pub fn global(quick: bool, build: Build) -> anyhow::Result<()> {
    let root = project_root();
    let runs: &[(&str, &str)] = if quick {
        &[
            ("protocol-global-quick.toml", "global-quick"),
            (
                "protocol-global-any-heading-quick.toml",
                "global-any-heading-quick",
            ),
        ]
    } else {
        &[
            ("protocol-global.toml", "global"),
            ("protocol-global-uniform.toml", "global-uniform"),
            ("protocol-global-any-heading.toml", "global-any-heading"),
            (
                "protocol-global-any-heading-wide.toml",
                "global-any-heading-wide",
            ),
            ("protocol-global-twice.toml", "global-twice"),
        ]
    };
    for (protocol, out) in runs {
        let protocol_path = root.join("fixtures").join(protocol);
        let out = root.join("results").join(out);
        run_protocol(&protocol_path, &out, false, build)?;
        check(&protocol_path, &out, false, false, build)?;
    }
    Ok(())
}

/// `bench-conv run PROTOCOL --out OUT [--extras]`.
fn run_protocol(
    protocol_path: &std::path::Path,
    out: &std::path::Path,
    extras: bool,
    build: Build,
) -> anyhow::Result<()> {
    let mut args = vec![
        "run".as_ref(),
        protocol_path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    if extras {
        args.push("--extras".as_ref());
    }
    bench_conv(&args, build)
}

/// `bench-conv check PROTOCOL --out OUT [--quick] [--extras]`: the result files exist,
/// every method has one row per (desired, scale, initial) pose, and in quick mode PoVS
/// fails from 8 m and Rule2 succeeds at least as often as Rule0.
fn check(
    protocol_path: &std::path::Path,
    out: &std::path::Path,
    quick: bool,
    extras: bool,
    build: Build,
) -> anyhow::Result<()> {
    let mut args = vec![
        "check".as_ref(),
        protocol_path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    if quick {
        args.push("--quick".as_ref());
    }
    if extras {
        args.push("--extras".as_ref());
    }
    bench_conv(&args, build)
}

/// How to get the 7-Scenes frames of `reproduce-real --seven-scenes`.
const SEVEN_SCENES_HELP: &str = "7-Scenes redkitchen seq-01 (1000 frames, Microsoft's \
non-commercial research licence: never commit them) is the folder data/ of the GitHub \
repository andyzeng/tsdf-fusion-python: `git clone --depth 1 \
https://github.com/andyzeng/tsdf-fusion-python` and pass \
`--seven-scenes tsdf-fusion-python/data`";

/// The structure-from-motion poses of 7-Scenes redkitchen, in the frames' folder.
const SFM_POSES: &str = "sfm_redkitchen_train.txt";

/// How to get them.
const SFM_HELP: &str = "the structure-from-motion pseudo ground truth of 7-Scenes \
(Brachmann et al., ICCV 2021; same licence as 7-Scenes) is the file \
pgt/sfm/7scenes/redkitchen_train.txt of the GitHub repository \
tsattler/visloc_pseudo_gt_limitations: copy it into the 7-Scenes folder as \
sfm_redkitchen_train.txt";

/// How to get TUM RGB-D freiburg1_rpy for `reproduce-real --tum`.
const TUM_HELP: &str = "TUM RGB-D freiburg1_rpy (Sturm et al., IROS 2012; CC BY 4.0) is \
rgbd_dataset_freiburg1_rpy.tgz of the dataset's download page (cvg.cit.tum.de/data/\
datasets/rgbd-dataset/download): unpack it, write associations.txt with TUM's \
associate.py (`python associate.py rgb.txt depth.txt > associations.txt`, colour \
first) and pass the folder";

/// The shared data folder: `PGM_DATA_DIR`, else `../shared/data` beside the checkout.
fn data_dir() -> std::path::PathBuf {
    std::env::var_os("PGM_DATA_DIR")
        .map(Into::into)
        .unwrap_or_else(|| project_root().join("../shared/data"))
}

/// Run the real-data benchmarks: the house of the shared data (or its quick subset),
/// 7-Scenes redkitchen and TUM RGB-D freiburg1_rpy when their frames are given; then check that the localiser
/// reached its pictures' photometric optimum.
pub fn real(
    quick: bool,
    seven_scenes: Option<&std::path::Path>,
    tum: Option<&std::path::Path>,
    build: Build,
) -> anyhow::Result<()> {
    let root = project_root();
    let house = data_dir().join("rgbd/house");
    ensure!(
        house.is_dir(),
        "no house pictures at {} (set PGM_DATA_DIR to the shared data folder)",
        house.display()
    );
    let mut runs = vec![(
        if quick {
            "bench-house-quick.toml"
        } else {
            "bench-house.toml"
        },
        house,
        if quick { "house-quick" } else { "house" },
    )];
    match seven_scenes {
        Some(dir) => {
            ensure!(
                dir.join("frame-000000.color.jpg").is_file()
                    && dir.join("frame-000999.pose.txt").is_file(),
                "{} does not hold the 7-Scenes frames frame-000000 to frame-000999. {SEVEN_SCENES_HELP}",
                dir.display()
            );
            runs.push(("bench-redkitchen.toml", dir.to_path_buf(), "redkitchen"));
            if dir.join(SFM_POSES).is_file() {
                runs.push((
                    "bench-redkitchen-sfm.toml",
                    dir.to_path_buf(),
                    "redkitchen-sfm",
                ));
            } else {
                eprintln!("7-Scenes with structure-from-motion poses skipped: {SFM_HELP}.");
            }
        }
        None if !quick => eprintln!("7-Scenes skipped: {SEVEN_SCENES_HELP}."),
        None => {}
    }
    match tum {
        Some(dir) => {
            ensure!(
                dir.join("associations.txt").is_file() && dir.join("groundtruth.txt").is_file(),
                "{} does not hold associations.txt and groundtruth.txt. {TUM_HELP}",
                dir.display()
            );
            runs.push(("bench-tum-fr1-rpy.toml", dir.to_path_buf(), "tum-fr1-rpy"));
        }
        None if !quick => eprintln!("TUM RGB-D skipped: {TUM_HELP}."),
        None => {}
    }
    for (bench, data, out) in runs {
        let out = root.join("results/real").join(out);
        bench_conv(
            &[
                "real".as_ref(),
                root.join("fixtures/real").join(bench).as_os_str(),
                "--data".as_ref(),
                data.as_os_str(),
                "--out".as_ref(),
                out.as_os_str(),
            ],
            build,
        )?;
        check_real(&out)?;
    }
    Ok(())
}

/// The localiser's runs of a real benchmark (`runs.csv`) end near their pictures'
/// photometric optimum: at least 4 in 5 within 2 cm of it, from every start.
fn check_real(out: &std::path::Path) -> anyhow::Result<()> {
    let path = out.join("runs.csv");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .context("an empty runs.csv")?
        .split(',')
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .with_context(|| format!("{}: no column {name}", path.display()))
    };
    let (method, reference) = (column("method")?, column("to_reference_m")?);
    let (mut runs, mut near) = (0, 0);
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        if fields.get(method) == Some(&"localizer") {
            runs += 1;
            if fields
                .get(reference)
                .and_then(|v| v.parse::<f64>().ok())
                .is_some_and(|d| d < 0.02)
            {
                near += 1;
            }
        }
    }
    ensure!(runs > 0, "{}: no localiser run", path.display());
    ensure!(
        5 * near >= 4 * runs,
        "{}: the localiser ended within 2 cm of the photometric optimum in {near} of {runs} runs",
        path.display()
    );
    println!(
        "checked: the localiser ended within 2 cm of the photometric optimum in {near} of {runs} runs ({})",
        out.display()
    );
    Ok(())
}
