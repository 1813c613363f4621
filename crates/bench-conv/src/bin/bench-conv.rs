//! `bench-conv`: command-line tools of the PGM project (see the crate documentation).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand};
use frame::Frame;
use splat::{RenderOptions, Renderer};
use world::city::{City, CityParams};

#[derive(Parser)]
#[command(version, about = "Tools of the PGM omnidirectional VVS project")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Replace the results of an earlier run in the results folder (--out of run,
    /// track, merge, domain and real), which is refused otherwise.
    #[arg(long, global = true)]
    force: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run a convergence protocol (format: crates/bench-conv/src/protocol.rs).
    Run {
        /// Protocol file.
        protocol: PathBuf,
        /// Results folder (created).
        #[arg(long)]
        out: PathBuf,
        /// Run shard i of n only (i/n): every method from the poses k ≡ i (mod n), poses numbered desired-major.
        #[arg(long)]
        shard: Option<String>,
        /// Also run the protocol's extra methods ([[variant]]: LM, robust weighting…).
        #[arg(long)]
        extras: bool,
    },
    /// Track a generated sequence by successive alignments (format:
    /// crates/bench-conv/src/tracking/sequence.rs), the paper's §4.
    Track {
        /// Sequence file.
        sequence: PathBuf,
        /// Results folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Merge the runs.csv of shards into one results folder (CSV, summary, plots).
    Merge {
        /// The shards' CSV files.
        #[arg(required = true)]
        csv: Vec<PathBuf>,
        /// Results folder (created).
        #[arg(long)]
        out: PathBuf,
        /// Success threshold, metres.
        #[arg(long, default_value_t = 0.02, allow_negative_numbers = true)]
        threshold_m: f64,
    },
    /// The convergence domain from finished protocol runs: success against the offset
    /// scale of every method (domain.csv, domain.png/svg) and, from an axes protocol,
    /// the basin along each axis, together in domain.md.
    Domain {
        /// Results folders (each with its runs.csv) whose runs make the curve.
        #[arg(required = true)]
        curve: Vec<PathBuf>,
        /// An axes protocol file (`sampling = "axes"`) …
        #[arg(long, requires = "axes")]
        axes_protocol: Option<PathBuf>,
        /// … and the results folder of its run.
        #[arg(long, requires = "axes_protocol")]
        axes: Option<PathBuf>,
        /// Results folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// The PGM of a real catadioptric image at several λ (the paper's Fig. 1).
    PgmImage {
        /// The image (JPEG, PNG…).
        #[arg(long)]
        image: PathBuf,
        /// Its Mei calibration (omniunwarp YAML).
        #[arg(long)]
        mei_yaml: PathBuf,
        /// The calibrated crop x,y,width,height (pixels).
        #[arg(long)]
        crop: String,
        /// Valid annulus around the principal point, inner,outer radii (pixels).
        #[arg(long, default_value = "30,470")]
        annulus: String,
        /// Extents λ, pixels.
        #[arg(long, default_value = "1,5,15,30")]
        lambdas: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Generate the synthetic city and write it as a cloud file (LAS, LAZ, PLY or E57
    /// by the extension).
    City {
        /// Output file (.las, .laz, .ply or .e57).
        #[arg(long)]
        out: PathBuf,
        /// Seed of the city.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Point spacing, metres.
        #[arg(long, default_value_t = 0.05)]
        spacing_m: f64,
        /// Folder of photographic textures (brick.png, gravel.png, grass.png).
        #[arg(long)]
        textures: Option<PathBuf>,
    },
    /// Convert a cloud file into another format (by the output's extension: .las,
    /// .laz, .ply, .e57; the input's format is read from its content), keeping its
    /// coordinates (`f64`; LAS on the source's grid or 0.1 mm) and its 8- or 16-bit
    /// colours exactly.
    Convert {
        /// The cloud to read.
        input: PathBuf,
        /// The file to write.
        output: PathBuf,
    },
    /// Fuse RGB-D frames (colour, 16-bit depth, poses) into a coloured cloud
    /// (dataset format: crates/rgbd/src/dataset.rs).
    Fuse {
        /// The dataset's description (TOML).
        #[arg(long)]
        dataset: PathBuf,
        /// The folder of its frames.
        #[arg(long)]
        data: PathBuf,
        /// Frames to fuse: numbers and ranges, `0-999/10,1200` (a range's step after /).
        #[arg(long)]
        frames: String,
        /// Frames left out of --frames (same syntax).
        #[arg(long)]
        exclude: Option<String>,
        /// Voxel edge, metres: one point per voxel.
        #[arg(long, default_value_t = rgbd::FuseOptions::default().voxel_size_m)]
        voxel_m: f64,
        /// Keep voxels seen by at least this many frames.
        #[arg(long, default_value_t = rgbd::FuseOptions::default().min_frames)]
        min_frames: u32,
        /// Drop depth pixels whose neighbours' depth differs by more than this fraction
        /// (0: keep them all).
        #[arg(long, default_value_t = 0.03)]
        flying_jump: f32,
        /// Nearest and farthest depth kept, metres.
        #[arg(long, default_value = "0.2,6")]
        depth_range_m: String,
        /// Output cloud (.las, .laz, .ply or .e57).
        #[arg(long)]
        out: PathBuf,
    },
    /// The real-data benchmark (format: crates/bench-conv/src/real/mod.rs): real
    /// photographs localised and tracked in clouds fused from RGB-D frames.
    Real {
        /// The benchmark file.
        benchmark: PathBuf,
        /// The folder of the dataset's frames.
        #[arg(long)]
        data: PathBuf,
        /// Results folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Check a protocol's results folder against the protocol file.
    Check {
        /// The protocol file.
        protocol: PathBuf,
        /// The results folder.
        #[arg(long)]
        out: PathBuf,
        /// The quick subset's extra expectations (PoVS fails from 8 m, Rule2 at least
        /// as good as Rule0).
        #[arg(long)]
        quick: bool,
        /// The run included the extra methods.
        #[arg(long)]
        extras: bool,
    },
    /// Check a tracking results folder against the sequence file.
    CheckTrack {
        /// The sequence file.
        sequence: PathBuf,
        /// The results folder.
        #[arg(long)]
        out: PathBuf,
    },
    Render {
        /// Camera TOML file.
        #[arg(long)]
        camera: PathBuf,
        /// A cloud file: LAS, LAZ, PLY or E57 (else the synthetic city of --city-seed).
        #[arg(long)]
        cloud: Option<PathBuf>,
        /// Seed of the synthetic city, when no --cloud is given.
        #[arg(long, default_value_t = 1)]
        city_seed: u64,
        /// Camera pose in the world, the paper's r = tx,ty,tz,θwx,θwy,θwz (m, rad).
        #[arg(long, allow_hyphen_values = true)]
        pose: Option<String>,
        /// A camera looking down at x,y,z (m) with its X axis at heading (degrees).
        #[arg(long, allow_hyphen_values = true)]
        looking_down: Option<String>,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Draw every point (no level of detail).
        #[arg(long)]
        no_lod: bool,
        /// Write what a real camera would measure instead of the rendering: the
        /// acquisition simulator with its default settings (world::Acquisition:
        /// vignetting, gain and offset drift, blur, noise), and, for the synthetic city,
        /// another point sampling of its surfaces.
        #[arg(long)]
        acquire: bool,
    },
}

#[allow(clippy::too_many_arguments)]
fn write_results(
    out: &std::path::Path,
    title: &str,
    note: Option<&str>,
    records: &[bench_conv::report::RunRecord],
    threshold_m: f64,
    wall_time_s: Option<f64>,
    axes: Option<([f64; 6], f64)>,
    manifest: Option<&bench_conv::report::RunManifest>,
) -> anyhow::Result<()> {
    use bench_conv::report;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    report::write_csv(&out.join("runs.csv"), records)?;
    if let Some(manifest) = manifest {
        report::write_manifest(out, manifest)?;
    }
    let mut summary = report::summary_markdown(title, records, threshold_m, wall_time_s);
    if let Some(note) = note {
        // After the title line.
        let at = summary.find('\n').map_or(summary.len(), |i| i + 1);
        summary.insert_str(at, &format!("\n{note}\n"));
    }
    let domain = report::domain(records);
    if domain
        .iter()
        .any(|p| p.offset_scale != domain[0].offset_scale)
    {
        summary.push_str(
            "
## Success against the scale of the offsets

",
        );
        summary.push_str(&report::domain_markdown(&domain));
        report::write_domain_csv(&out.join("domain.csv"), &domain)?;
        report::plot_domain(&domain, &out.join("domain.png"), &out.join("domain.svg"))?;
    }
    if let Some((magnitudes, top_scale)) = axes {
        summary.push_str(
            "
## Basin along each axis alone

The largest offset of those run from which every run along the axis (both signs, every desired pose) converged, at that and every smaller offset.\n\n",
        );
        summary.push_str(&report::axis_basins_markdown(
            &report::axis_basins(records),
            magnitudes,
            top_scale,
        ));
    }
    report::write_atomically(&out.join("summary.md"), summary.as_bytes())?;
    report::plot_cdf(
        records,
        threshold_m,
        &out.join("cdf.png"),
        &out.join("cdf.svg"),
    )?;
    report::finish_results(out)?;
    println!("{summary}");
    println!("results in {}", out.display());
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let force = cli.force;
    match cli.command {
        Command::Run {
            protocol,
            out,
            shard,
            extras,
        } => {
            let started = Instant::now();
            let protocol_path = protocol;
            let protocol = bench_conv::protocol::Protocol::load(&protocol_path)?;
            let shard = shard
                .as_deref()
                .map(bench_conv::run::Shard::parse)
                .transpose()?;
            bench_conv::run::check_shard(&protocol, extras, shard)?;
            let _lock = bench_conv::report::begin_results(&out, force)?;
            let (cloud, scene) = bench_conv::run::load_scene(&protocol)?;
            let records = bench_conv::run::run_protocol(&protocol, &cloud, &scene, extras, shard)?;
            let title = match shard {
                Some(s) => format!("{} (shard {}/{})", protocol.name, s.index, s.count),
                None => protocol.name.clone(),
            };
            let protocol_bytes = std::fs::read(&protocol_path)
                .with_context(|| format!("reading {}", protocol_path.display()))?;
            let run_ids = protocol.runs(extras)?.len();
            let manifest = bench_conv::report::RunManifest {
                protocol: protocol.name.clone(),
                protocol_hash: Some(bench_conv::report::fingerprint(&protocol_bytes)),
                extras,
                // An adaptive protocol needs only the runs it ran.
                total_runs: if protocol.offsets.adaptive {
                    records.len()
                } else {
                    run_ids
                },
                run_id_limit: Some(run_ids),
                shard: shard.map(|s| [s.index, s.count]),
                runs: records.len(),
            };
            write_results(
                &out,
                &title,
                None,
                &records,
                protocol.success_threshold_m,
                Some(started.elapsed().as_secs_f64()),
                (protocol.offsets.sampling == bench_conv::protocol::Sampling::Axes).then(|| {
                    let (t, r) = (
                        protocol.offsets.translation_m,
                        protocol.offsets.rotation_deg,
                    );
                    let top = protocol.offsets.scales.iter().copied().fold(0.0, f64::max);
                    ([t[0], t[1], t[2], r[0], r[1], r[2]], top)
                }),
                Some(&manifest),
            )?;
        }
        Command::Track { sequence, out } => {
            use bench_conv::tracking;
            let spec = tracking::SequenceSpec::load(&sequence)?;
            let _lock = bench_conv::report::begin_results(&out, force)?;
            let camera = spec.load_camera()?;
            let (cloud, acquired_cloud) = spec.load_clouds()?;
            let (results, acquired) =
                tracking::run_sequence(&spec, &camera, &cloud, acquired_cloud.as_ref())?;
            let summary =
                tracking::write_results(&spec, &camera, &cloud, &results, &acquired, &out)?;
            bench_conv::report::finish_results(&out)?;
            println!("{summary}");
            println!("results in {}", out.display());
        }
        Command::PgmImage {
            image,
            mei_yaml,
            crop,
            annulus,
            lambdas,
            out,
        } => {
            let [x, y, w, h] =
                bench_conv::parse_pixels::<4>(&crop).with_context(|| format!("--crop {crop}"))?;
            let [inner, outer] = bench_conv::parse_numbers::<2>(&annulus)?;
            let probe = ucm::Camera::load_mei_yaml(&mei_yaml, w, h, ucm::ValidRegion::Full)?;
            let i = probe.intrinsics();
            let region = ucm::ValidRegion::Annulus(ucm::Annulus {
                center_px: [i.u0, i.v0],
                inner_radius_px: inner,
                outer_radius_px: outer,
            });
            let camera = probe.with_region(region)?;
            let picture = frame::Image::load(&image, &camera, Some([x, y, w, h]))?;
            let lambdas: Vec<f32> = lambdas
                .split(',')
                .map(|s| s.trim().parse::<f32>().with_context(|| format!("λ `{s}`")))
                .collect::<anyhow::Result<_>>()?;
            for path in bench_conv::real_image::write_pgm_images(&picture, &camera, &lambdas, &out)?
            {
                println!("wrote {}", path.display());
            }
        }
        Command::Domain {
            curve,
            axes_protocol,
            axes,
            out,
        } => {
            let curve = curve
                .iter()
                .map(|dir| bench_conv::report::read_csv(&dir.join("runs.csv")))
                .collect::<anyhow::Result<Vec<_>>>()?;
            let axes = match (axes_protocol, axes) {
                (Some(protocol), Some(dir)) => Some((
                    bench_conv::protocol::Protocol::load(&protocol)?,
                    bench_conv::report::read_csv(&dir.join("runs.csv"))?,
                )),
                _ => None,
            };
            let text = bench_conv::report::write_domain(&out, &curve, axes.as_ref(), force)?;
            println!("{text}");
            println!("results in {}", out.display());
        }
        Command::Merge {
            csv,
            out,
            threshold_m,
        } => {
            let parts = csv
                .iter()
                .map(|p| bench_conv::report::read_csv(p))
                .collect::<anyhow::Result<Vec<_>>>()?;
            let manifests = csv
                .iter()
                .map(|p| bench_conv::report::read_manifest(p))
                .collect::<anyhow::Result<Vec<_>>>()?;
            for ((path, part), manifest) in csv.iter().zip(&parts).zip(&manifests) {
                if let Some(m) = manifest {
                    anyhow::ensure!(
                        m.runs == part.len(),
                        "{} holds {} runs where its manifest says {}: a row was added or \
                         deleted",
                        path.display(),
                        part.len(),
                        m.runs
                    );
                }
            }
            let mut records = bench_conv::report::merge(parts)?;
            anyhow::ensure!(
                !records.is_empty(),
                "the CSV files hold no run: nothing to merge"
            );
            let completeness = bench_conv::report::completeness(&manifests, records.len())?;
            bench_conv::report::check_run_ids(&records, &manifests)?;
            // Success follows the threshold given here, not the one of the runs.
            bench_conv::report::apply_threshold(&mut records, threshold_m)
                .context("--threshold-m")?;
            let _lock = bench_conv::report::begin_results(&out, force)?;
            let (title, manifest) = match &completeness {
                bench_conv::report::Completeness::Complete { protocol, runs } => (
                    format!("{protocol} (merged)"),
                    manifests[0]
                        .clone()
                        .map(|m| bench_conv::report::RunManifest {
                            shard: None,
                            runs: *runs,
                            ..m
                        }),
                ),
                bench_conv::report::Completeness::Partial { protocol, .. } => {
                    (format!("{protocol} (PARTIAL merge)"), None)
                }
                bench_conv::report::Completeness::Unknown => ("merged".to_string(), None),
            };
            if let bench_conv::report::Completeness::Partial { .. } = completeness {
                eprintln!("warning: {}", completeness.markdown().replace("**", ""));
            }
            write_results(
                &out,
                &title,
                Some(&completeness.markdown()),
                &records,
                threshold_m,
                None,
                None,
                manifest.as_ref(),
            )?;
        }
        Command::City {
            out,
            seed,
            spacing_m,
            textures,
        } => {
            let params = CityParams {
                seed,
                spacing_m,
                texture_dir: textures,
                ..CityParams::default()
            };
            // Fail before the work: a wrong extension or a folder that does not exist.
            cloud_io::CloudFormat::of_output(&out)?;
            let city = City::generate(&params)?;
            println!(
                "generated {} points in {:.2} s",
                city.cloud.len(),
                city.generation_time_s
            );
            cloud_io::write_cloud(&city.cloud, &out)?;
            println!("wrote {}", out.display());
        }
        Command::Convert { input, output } => {
            let started = Instant::now();
            let info = cloud_io::convert(&input, &output)?;
            println!(
                "{} ({}, {} points) -> {} in {:.1} s",
                input.display(),
                info.format,
                info.points,
                output.display(),
                started.elapsed().as_secs_f64()
            );
        }
        Command::Fuse {
            dataset,
            data,
            frames,
            exclude,
            voxel_m,
            min_frames,
            flying_jump,
            depth_range_m,
            out,
        } => {
            cloud_io::CloudFormat::of_output(&out)?;
            let dataset = rgbd::RgbdDataset::load(&dataset, &data)?;
            let mut list = bench_conv::parse_frames(&frames).context("--frames")?;
            if let Some(exclude) = exclude {
                let exclude = bench_conv::parse_frames(&exclude).context("--exclude")?;
                list.retain(|k| !exclude.contains(k));
            }
            anyhow::ensure!(!list.is_empty(), "no frame to fuse");
            let [near, far] = bench_conv::parse_numbers::<2>(&depth_range_m)?;
            let options = rgbd::FuseOptions {
                voxel_size_m: voxel_m,
                min_frames,
                flying_pixel_jump: (flying_jump > 0.0).then_some(flying_jump),
                depth_range_m: [near as f32, far as f32],
                ..rgbd::FuseOptions::default()
            };
            options.validate()?;
            let started = Instant::now();
            let progress = bench_conv::progress::Progress::new(list.len() as u64, "frames");
            let (cloud, report) = dataset.fuse(&list, options, |_, _| progress.inc(1, ""))?;
            progress.finish();
            let p = report.pixels;
            println!(
                "{} frames in {:.1} s: {} depth pixels measured, {} flying, {} outside the colour picture, {} hidden from it; {} fused into {} voxels, {} seen by {min_frames} frames or more",
                report.frames,
                started.elapsed().as_secs_f64(),
                p.measured,
                p.flying,
                p.outside_color,
                p.occluded,
                p.fused,
                report.voxels,
                report.points
            );
            cloud_io::write_cloud(&cloud, &out)?;
            println!("wrote {}", out.display());
        }
        Command::Real {
            benchmark,
            data,
            out,
        } => {
            let started = Instant::now();
            let spec = bench_conv::real::RealSpec::load(&benchmark)?;
            anyhow::ensure!(
                data.is_dir(),
                "the data folder {} does not exist",
                data.display()
            );
            let _lock = bench_conv::report::begin_results(&out, force)?;
            let (prepared, results) = bench_conv::real::run_benchmark(spec, &data)?;
            let summary = bench_conv::real::write_results(
                &prepared,
                &results,
                started.elapsed().as_secs_f64(),
                &out,
            )?;
            bench_conv::report::finish_results(&out)?;
            println!("{summary}");
            println!("results in {}", out.display());
        }
        Command::Check {
            protocol,
            out,
            quick,
            extras,
        } => {
            bench_conv::check::check_protocol(&protocol, &out, quick, extras)?;
            println!(
                "checked: {} is consistent with {}",
                out.display(),
                protocol.display()
            );
        }
        Command::CheckTrack { sequence, out } => {
            bench_conv::check::check_sequence(&sequence, &out)?;
            println!(
                "checked: {} is consistent with {}",
                out.display(),
                sequence.display()
            );
        }
        Command::Render {
            camera,
            cloud,
            city_seed,
            pose,
            looking_down,
            out,
            no_lod,
            acquire,
        } => {
            let world_from_camera =
                bench_conv::parse_pose(pose.as_deref(), looking_down.as_deref())?;
            let camera = ucm::Camera::load_toml(&camera)?;
            let cloud = match cloud {
                Some(path) => {
                    let (cloud, info, source) = cloud_io::read_cloud(&path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    println!(
                        "{}: {} {} points, {source:?}",
                        path.display(),
                        info.format,
                        cloud.len(),
                    );
                    cloud
                }
                None => {
                    let city = City::generate(&CityParams {
                        seed: city_seed,
                        sampling_seed: acquire
                            .then_some(world::Acquisition::default().sampling_seed),
                        ..CityParams::default()
                    })?;
                    println!(
                        "city {city_seed}: {} points in {:.2} s",
                        city.cloud.len(),
                        city.generation_time_s
                    );
                    city.cloud
                }
            };
            let options = RenderOptions {
                lod_spacing_px: if no_lod {
                    None
                } else {
                    RenderOptions::default().lod_spacing_px
                },
                ..RenderOptions::default()
            };
            let mut renderer = Renderer::new(camera.clone(), options)?;
            let mut frame = Frame::for_camera(&camera);
            let started = Instant::now();
            let stats = renderer.render(&cloud, &world_from_camera.inverse(), &mut frame)?;
            let elapsed = started.elapsed();
            let (hit, sky, masked) = frame.counts();
            println!(
                "rendered {} of {} points ({} cells) in {:.2} ms: {hit} hit, {sky} sky, {masked} masked pixels",
                stats.points_drawn,
                cloud.len(),
                stats.cells_drawn,
                elapsed.as_secs_f64() * 1e3
            );
            if acquire {
                world::Acquisition::default()
                    .acquire(&frame, &camera, 0, 0.0)?
                    .save_png(&out)?;
            } else {
                frame.save_png(&out)?;
            }
            println!("wrote {}", out.display());
        }
    }
    Ok(())
}
