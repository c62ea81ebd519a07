//! `prt`: the command-line face of prt (docs/conventions.md section 6). Each subcommand turns its
//! options into a settings struct and calls one library function.

mod bake;
mod bench_accuracy;
mod bench_bake;
mod bench_fuzz;
mod bench_gpu;
mod bench_lights;
mod bench_render;
mod bench_surface;
mod progress;
mod relight;
mod render;
mod sample;
mod signals;

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use prt_bake::BakeSettings;
use render::{parse_size, parse_vec3};

#[derive(Parser)]
#[command(
    name = "prt",
    version,
    about = "Precomputed radiance transfer GI: bake, inspect, relight"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum Backend {
    Cpu,
    Gpu,
}

#[derive(Subcommand)]
enum BenchKind {
    /// Mutation fuzzing of the glTF path or the asset loader for a fixed time (issue 8).
    Fuzz(bench_fuzz::FuzzArgs),
    /// GPU update cost against light count: every light moved, and one light moved.
    Lights(bench_lights::LightsArgs),
    /// Bake throughput against bare obvhs tracing of the same rays, and bytes per probe.
    Bake {
        scene: PathBuf,
        #[arg(long)]
        spacing: Option<f32>,
        #[arg(long, value_parser = parse_bounds, allow_hyphen_values = true)]
        bounds: Option<[f32; 6]>,
        #[arg(long, default_value_t = 512)]
        rays: u32,
        #[arg(long)]
        double_sided: bool,
        /// Bakes, each followed by bare obvhs tracing of its rays, in turn: the first run's
        /// report in full, then a last row of every run's ratio and their median (one run's
        /// swings by 10-20% on a shared machine); the bakes after the first are `prt bake`
        /// processes of their own, timed to the asset written and, in a second median, to
        /// their exit.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
        runs: u32,
    },
    /// Sweep rays, brick size, factor encoding and precision against a reference SH file:
    /// error against bake time, with the Pareto front (and earlier sweeps' with --previous).
    Accuracy(bench_accuracy::AccuracyArgs),
    /// GPU runtime costs: update per probe at several probe counts, the gather alone, vs the
    /// prior art's per-probe surfels, an update when nothing changed, a multi-bounce update, and
    /// cost against light count (1, 32, 256, 1,024 lights).
    Gpu {
        scene: PathBuf,
        #[arg(long)]
        lights: PathBuf,
        /// Probe spacings to bake the scene at (one table row each).
        #[arg(long, value_delimiter = ',', default_value = "0.2,0.0857,0.04")]
        spacings: Vec<f32>,
        #[arg(long, default_value_t = 256)]
        rays: u32,
        /// Surfel cell size, fixed so that only the probe count changes between rows.
        #[arg(long, default_value_t = 0.05)]
        cell_size: f32,
    },
    /// Forward+ cost: frame time split into depth, cull and shade, and lights evaluated per
    /// pixel, brute force against tiled culling, at several light counts.
    Render {
        scene: PathBuf,
        /// Light counts (point and spot lights scattered through the scene).
        #[arg(long, value_delimiter = ',', default_value = "16,64,256,1024")]
        lights: Vec<usize>,
        /// Tile sizes of the tiled rows.
        #[arg(long, value_delimiter = ',', default_value = "16,64")]
        tiles: Vec<u32>,
        #[arg(long, value_parser = parse_size, default_value = "1280x720")]
        size: (u32, u32),
        #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
        eye: Option<glam::Vec3>,
        #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
        target: Option<glam::Vec3>,
        #[arg(long, default_value_t = prt_render::camera::DEFAULT_FOV)]
        fov: f32,
        /// Bake with every material double-sided.
        #[arg(long)]
        double_sided: bool,
        /// Frames per stage (the median is reported).
        #[arg(long, default_value_t = 3)]
        frames: usize,
    },
    /// Irradiance at surface points against the oracle's surface references (leaks, holes,
    /// error), at the default spacing and half of it.
    Surface(bench_surface::SurfaceArgs),
}

#[derive(Subcommand)]
enum Command {
    /// Bake a glTF 2.0 scene into a PRT asset.
    Bake(bake::BakeArgs),
    /// Relight an asset once and write every probe's SH9 as JSON.
    Relight(relight::RelightArgs),
    /// Measure speed and accuracy (not tests; see README for the figures).
    Bench {
        #[command(subcommand)]
        kind: BenchKind,
    },
    /// Relight an asset once and write what the engine's sample_irradiance returns at points.
    Sample(sample::SampleArgs),
    /// Render the scene with direct light (tiled Forward+) and the GI's indirect diffuse.
    Render(render::RenderArgs),
    /// Print the summary of an asset.
    Inspect {
        asset: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Fails when `output` is one of the command's input files (it would be replaced).
fn ensure_not_input(output: &std::path::Path, inputs: &[&std::path::Path]) -> Result<()> {
    for input in inputs {
        anyhow::ensure!(
            !prt_format::io::same_file(output, input),
            "{}: is an input of this command ({}); refusing to overwrite it",
            output.display(),
            input.display()
        );
    }
    Ok(())
}

/// The rig at `rig`, or without one the asset's own (KHR_lights_punctual) lights and a black sky.
fn lighting_of(
    rig: Option<&std::path::Path>,
    asset: &prt_format::Asset,
) -> Result<prt_runtime::Lighting> {
    Ok(match rig {
        Some(rig) => {
            let (lighting, warnings) = prt_runtime::load_rig_with_warnings(rig)?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
            lighting
        }
        None => prt_runtime::Lighting {
            rig: prt_format::LightRig {
                lights: asset.lights.clone(),
                sky: None,
            },
            sky: prt_runtime::SkyModel::Black,
        },
    })
}

/// Parses a comma-separated list of numbers (flags of several commands).
fn parse_numbers(s: &str) -> Result<Vec<f32>, String> {
    s.split(',')
        .map(|t| t.trim().parse::<f32>().map_err(|e| format!("{t:?}: {e}")))
        .collect()
}

/// `--normal-bias` in probe spacings, or the runtime's default: finite and non-negative.
fn normal_bias(arg: Option<f32>) -> Result<f32> {
    let bias = arg.unwrap_or(prt_runtime::LookupSettings::default().normal_bias);
    anyhow::ensure!(
        bias.is_finite() && bias >= 0.0,
        "--normal-bias {bias}: expected a finite number of probe spacings >= 0"
    );
    Ok(bias)
}

/// Parses `MINX,MINY,MINZ,MAXX,MAXY,MAXZ`.
fn parse_bounds(s: &str) -> Result<[f32; 6], String> {
    let v = parse_numbers(s)?;
    v.try_into()
        .map_err(|v: Vec<f32>| format!("expected 6 comma-separated numbers, got {}", v.len()))
}

/// The process's peak resident set size in KiB (`VmHWM` of `/proc/self/status`; Linux only).
pub(crate) fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Tells glibc's allocator to keep the memory the process frees for its own later allocations
/// instead of handing it back to the kernel: blocks below 32 MiB (glibc's largest threshold on
/// 64-bit) always come from its heaps, never from mappings of their own (unmapped as soon as
/// they are freed), and the heaps' free tops are not trimmed (a worker thread's heap that
/// becomes wholly free may still be unmapped). A page handed back costs a page fault the next
/// time it is written, 2.1-2.5 us here (a virtual machine that also reports freed pages to its
/// host), and a bake frees and allocates hundreds of megabytes between its stages. Sponza,
/// `--double-sided`, 2 threads, `prt bake`, alternating the build with this and inlined
/// validation (a74d7ea) with the one before (97c1a71): page faults 43.7-44.3k against
/// 55.9-56.4k at 1.9 m, 147.7-149.5k against 155.4-157.1k at 1.0 m, 587k against 600k at
/// 104,949 probes; the price is peak memory, 176-179 MiB against 153-156 MiB at 1.9 m and
/// 506-511 MiB against 477-483 MiB at 1.0 m (1,274-1,290 MiB against 1,283-1,284 MiB at
/// 104,949 probes). End to end the two builds do not differ within this machine's noise
/// (0.49-0.61 s against 0.52-0.64 s at 1.9 m, six bakes each; 2.91-3.10 s against 3.02-3.13 s
/// at 1.0 m, five each); the CPU time of the six bakes at 1.9 m, user and system, summed to
/// 5.67 s against 6.08 s. Serving every block from the heaps (`M_MMAP_MAX` 0) saved more faults
/// at 1.0 m (143k) but, at 104,949 probes, peaked at 1,744 MiB against 1,282 MiB for 97c1a71
/// and took 6.1-6.3 s to number the bricks against 2.5 s. A process-wide setting, so the
/// binary's to make, not the library's: an engine that embeds the bake keeps its own
/// allocator's policy.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu", target_pointer_width = "64"))]
    // SAFETY: `mallopt` sets allocator parameters and touches no memory of ours; called before
    // any other thread exists (the signal thread is started after it). The trim threshold is
    // set only if the mmap threshold was taken: setting it switches off glibc's dynamic mmap
    // threshold, which without ours would stay at 128 KiB.
    unsafe {
        if libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20) == 1 {
            libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        }
    }
}

fn main() {
    // Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not set" on every device
    // they open when the variable is unset (headless machines, CI); point it at the temp dir.
    // Done first thing, before any thread exists.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    keep_freed_memory();
    signals::install();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // One line, as for every other error (docs/conventions.md section 6): clap's message and
            // its list of possible values, without the usage block.
            let text = e.render().to_string();
            let parts: Vec<&str> = text
                .lines()
                .map(str::trim)
                .filter(|l| {
                    !l.is_empty()
                        && !l.starts_with("Usage:")
                        && !l.starts_with("For more information")
                })
                .collect();
            eprintln!("{}", parts.join(" "));
            std::process::exit(2);
        }
    };
    if let Err(e) = run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Bake(args) => bake::run(args),
        Command::Relight(args) => relight::run(args),
        Command::Bench { kind } => bench(kind),
        Command::Sample(args) => sample::run(args),
        Command::Render(args) => render::run(args),
        Command::Inspect { asset, json } => {
            let bytes = prt_format::read_regular_file(&asset)
                .with_context(|| format!("reading {}", asset.display()))?;
            let loaded = prt_format::decode(&bytes)
                .with_context(|| format!("loading {}", asset.display()))?;
            let summary = prt_format::Summary::of(&loaded, bytes.len() as u64);
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("{summary}");
            }
            Ok(())
        }
    }
}

/// `prt bench`: the benchmark `kind` asks for, its report printed.
fn bench(kind: BenchKind) -> Result<()> {
    match kind {
        BenchKind::Bake {
            scene,
            spacing,
            bounds,
            rays,
            double_sided,
            runs,
        } => {
            let settings = BakeSettings {
                rays,
                spacing,
                bounds,
                double_sided,
                ..BakeSettings::default()
            };
            println!("{}", bench_bake::bake(&scene, &settings, runs as usize)?);
            Ok(())
        }
        BenchKind::Accuracy(args) => bench_accuracy::run(args),
        BenchKind::Render {
            scene,
            lights,
            tiles,
            size,
            eye,
            target,
            fov,
            double_sided,
            frames,
        } => {
            let camera = render::camera_of(eye, target, Some(fov))?;
            let bench = bench_render::RenderBench {
                scene: &scene,
                bake: BakeSettings {
                    double_sided,
                    ..BakeSettings::default()
                },
                camera,
                lights,
                tiles,
                size,
                frames: frames.max(1),
            };
            println!("{}", bench_render::render(&bench)?);
            Ok(())
        }
        BenchKind::Gpu {
            scene,
            lights,
            spacings,
            rays,
            cell_size,
        } => {
            let lighting = prt_runtime::load_rig(&lights)?;
            println!(
                "{}",
                bench_gpu::gpu(&scene, &lighting, &spacings, rays, cell_size)?
            );
            // Cost against light count, on the same scene (`prt bench lights` alone).
            println!(
                "{}",
                bench_lights::table(&bench_lights::LightsArgs {
                    scene,
                    lights: vec![1, 32, 256, 1024],
                    spacing: None,
                    rays,
                    double_sided: false,
                    repeats: 5,
                })?
            );
            Ok(())
        }
        BenchKind::Surface(args) => bench_surface::run(args),
        BenchKind::Fuzz(args) => bench_fuzz::run(args),
        BenchKind::Lights(args) => bench_lights::run(args),
    }
}
