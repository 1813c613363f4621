//! Localise a picture in a cloud, from files: the library call a user copies
//! ([`vvs::Localizer::localize_files`]).
//!
//! ```text
//! cargo run --release -p vvs --example localize -- \
//!     --picture image.png --camera camera.toml --cloud city.laz \
//!     --initial tx,ty,tz,θwx,θwy,θwz [--prior 8,2,1.5,10,10,15 [--heading-spacing 15]] \
//!     [--method rule2] \
//!     [--crop x,y,w,h] [--mei-yaml calib.yml --annulus inner,outer] [--truth tx,…]
//! ```
//!
//! Poses are the paper's `r = (t, θw)` of `world_from_camera` (metres, radians). With
//! `--prior` (the box's ±X,±Y,±Z metres and ±θwX,±θwY,±θwZ degrees, in the camera's
//! frame) the global search of `vvs::global` runs inside that box around `--initial`;
//! without a compass, give `--prior 8,2,1.5,10,10,180` (headings 15° apart are tried).

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Parser;
use ucm::Isometry3;
use vvs::{CameraFile, LocalizeFiles, Localizer, Method, PriorBox};

#[derive(Parser, Debug)]
#[command(
    about = "Localise a picture in a cloud (LAS, LAZ, PLY or E57) by PGM virtual visual servoing"
)]
struct Args {
    /// The picture (PNG or JPEG, grey or colour, 8 or 16 bits).
    #[arg(long)]
    picture: PathBuf,
    /// Camera TOML file (or give --mei-yaml).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Mei calibration (omniunwarp YAML) instead of --camera.
    #[arg(long)]
    mei_yaml: Option<PathBuf>,
    /// With --mei-yaml: inner,outer radius of the mirror's annulus (pixels).
    #[arg(long)]
    annulus: Option<String>,
    /// The calibrated part of the picture: x,y,width,height (pixels).
    #[arg(long)]
    crop: Option<String>,
    /// The cloud: LAS, LAZ, PLY or E57 (told apart by content).
    #[arg(long)]
    cloud: PathBuf,
    /// Initial world_from_camera, tx,ty,tz,θwx,θwy,θwz (m, rad).
    #[arg(long, allow_hyphen_values = true)]
    initial: String,
    /// Prior box for the global search: X,Y,Z (m), θwX,θwY,θwZ (degrees).
    #[arg(long)]
    prior: Option<String>,
    /// With --prior: try headings (rotations about the optical axis) at most this many
    /// degrees apart when the box's θwZ range exceeds it (180: any heading, no compass).
    #[arg(long, default_value_t = 15.0)]
    heading_spacing: f64,
    /// Local method without a prior box (povs, rule0, rule1, rule2).
    #[arg(long, default_value = "rule2")]
    method: Method,
    /// The true pose, if known, to print the error.
    #[arg(long, allow_hyphen_values = true)]
    truth: Option<String>,
}

fn numbers<const N: usize>(text: &str) -> anyhow::Result<[f64; N]> {
    let values: Vec<f64> = text
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .with_context(|| format!("`{s}` is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    values.try_into().map_err(|v: Vec<f64>| {
        anyhow::anyhow!("expected {N} comma-separated numbers, got {}", v.len())
    })
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    // Every argument is checked before the files are read.
    let truth = args
        .truth
        .as_deref()
        .map(|text| -> anyhow::Result<Isometry3> {
            Ok(Isometry3::from_pose_vector(
                numbers::<6>(text).context("--truth")?,
            )?)
        })
        .transpose()?;
    let camera = match (args.camera, args.mei_yaml) {
        (Some(_), None) if args.annulus.is_some() => {
            bail!("--annulus applies to --mei-yaml (a --camera file states its own region)")
        }
        (Some(path), None) => CameraFile::Toml(path),
        (None, Some(path)) => CameraFile::MeiYaml {
            path,
            annulus_radii_px: args.annulus.as_deref().map(numbers::<2>).transpose()?,
        },
        _ => bail!("give exactly one of --camera and --mei-yaml"),
    };
    let crop = match args.crop.as_deref() {
        Some(text) => {
            let v = numbers::<4>(text)?;
            anyhow::ensure!(
                v.iter()
                    .all(|x| x.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(x)),
                "--crop takes four pixel counts"
            );
            Some(v.map(|x| x as u32))
        }
        None => None,
    };
    let files = LocalizeFiles {
        picture: args.picture,
        crop,
        camera,
        cloud: args.cloud,
    };
    let initial = Isometry3::from_pose_vector(numbers::<6>(&args.initial)?)?;
    let mut localizer = Localizer {
        method: args.method,
        prior: match args.prior.as_deref() {
            Some(text) => {
                let [x, y, z, a, b, c] = numbers::<6>(text)?;
                Some(PriorBox {
                    translation_m: [x, y, z],
                    rotation_deg: [a, b, c],
                })
            }
            None => None,
        },
        ..Localizer::default()
    };
    localizer.config.global.heading_spacing_deg = Some(args.heading_spacing);
    // A global search runs for seconds: its phases on stderr, at most twice a second.
    let mut shown: Option<(std::time::Instant, vvs::SearchPhase)> = None;
    let mut show = |p: vvs::SearchProgress| {
        let due = match shown {
            None => true,
            Some((at, phase)) => phase != p.phase || at.elapsed().as_secs_f64() >= 0.5,
        };
        if due || p.done == p.total {
            eprintln!("global search: {} {}/{}", p.phase.name(), p.done, p.total);
            shown = Some((std::time::Instant::now(), p.phase));
        }
    };
    let localized = localizer.localize_files_with_progress(&files, initial, &mut show)?;
    let o = &localized.outcome;
    println!(
        "read {} points and {} valid pixels in {:.1} s",
        localized.cloud_points, localized.valid_pixels, localized.load_time_s
    );
    let method = if localizer.prior.is_some() {
        Method::Global
    } else {
        localizer.method
    };
    println!(
        "{method}: {:?} after {:?} iterations in {:.1} s, cost {:.3e}",
        o.stop, o.iterations, o.time_s, o.cost
    );
    if let Some(search) = &o.search {
        let [screening, descents, refinement] = search.phase_times_s;
        println!(
            "search: {} candidates ({screening:.1} s), {} descents, {} run on ({descents:.1} s), {} refinements ({refinement:.1} s)",
            search.candidates, search.descents, search.continued, search.refinements
        );
    }
    let r = o.world_from_camera.to_pose_vector();
    println!(
        "world_from_camera (t, θw): {:.4},{:.4},{:.4},{:.5},{:.5},{:.5}",
        r[0], r[1], r[2], r[3], r[4], r[5]
    );
    if let Some(truth) = truth {
        let (dt, dr) = o.world_from_camera.distance_to(&truth);
        let (t0, r0) = initial.distance_to(&truth);
        println!(
            "error: {:.4} m, {:.3}° (initial {t0:.2} m, {:.1}°)",
            dt,
            dr.to_degrees(),
            r0.to_degrees()
        );
    }
    // A run that diverged answers nothing: say so in the exit status too.
    if let vvs::StopReason::Diverged(why) = o.stop {
        bail!("the localisation diverged ({why:?}): the pose printed is not an answer");
    }
    Ok(())
}
