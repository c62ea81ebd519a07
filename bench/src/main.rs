//! `prt-bench`: prt's benchmarks and fuzzers, kept out of the `prt` binary. Each benchmark is a
//! module that measures one part against its baseline or reference, prints a Markdown report
//! and, with `--out DIR`, writes it to `DIR/<benchmark>.md` ([`results`]; the published tables
//! live in docs/results). Benchmarks are measurements, never tests: none fails on a number.
//! The fuzzer ([`fuzz`]) fails on a panic or a hang.

mod accuracy;
mod bake;
mod fuzz;
mod gather_lookup;
mod gpu;
mod lights;
mod path_lookup;
mod plot;
mod ray_lookup;
mod render;
mod results;
mod scaling;
mod sky_point_lookup;
mod surface;
mod surfel_lookup;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "prt-bench",
    version,
    about = "Measure prt's speed and accuracy (not tests; the tables are in docs/results), and fuzz its readers"
)]
struct Cli {
    #[command(subcommand)]
    kind: Kind,
}

#[derive(Subcommand)]
enum Kind {
    /// Bake throughput against bare obvhs tracing of the same rays, and bytes per probe.
    Bake(bake::BakeArgs),
    /// Sweep rays, brick size, factor encoding and precision against a reference SH file:
    /// error against bake time, with the Pareto front (and earlier sweeps' with --previous).
    Accuracy(accuracy::AccuracyArgs),
    /// GPU runtime costs: update per probe at several probe counts, the gather alone, vs the
    /// prior art's per-probe surfels, an update when nothing changed, a multi-bounce update, and
    /// cost against light count (1, 32, 256, 1,024 lights).
    Gpu(gpu::GpuArgs),
    /// GPU update cost against light count: every light moved, and one light moved.
    Lights(lights::LightsArgs),
    /// Forward+ cost: frame time split into depth, cull and shade, and lights evaluated per
    /// pixel, brute force against tiled culling, at several light counts.
    Render(render::RenderArgs),
    /// Irradiance at surface points against the oracle's surface references (leaks, holes,
    /// error), at the default spacing and half of it.
    Surface(surface::SurfaceArgs),
    /// Bake seconds and runtime bytes against surface error over probe spacings and ray
    /// counts, on the level family and Sponza: tables and plots with their fronts.
    Frontier(surface::frontier::FrontierArgs),
    /// The coarse levels of sparse placement against the fine grid in open air: at every grid
    /// point a sparse bake fills, the filled SH against a uniform bake's probe there.
    OpenAir(surface::open_air::OpenAirArgs),
    /// Bake seconds per placed probe and GPU memory across sizes of one level (sparse
    /// placement at one spacing).
    Scaling(scaling::ScalingArgs),
    /// Mutation fuzzing of the glTF path or the asset loader for a fixed time (issue 8).
    Fuzz(fuzz::FuzzArgs),
}

fn main() {
    prt_cli::process::main(run);
}

fn run(cli: Cli) -> Result<()> {
    match cli.kind {
        Kind::Bake(args) => bake::run(args),
        Kind::Accuracy(args) => accuracy::run(args),
        Kind::Gpu(args) => gpu::run(args),
        Kind::Lights(args) => lights::run(args),
        Kind::Render(args) => render::run(args),
        Kind::Surface(args) => surface::run(args),
        Kind::Frontier(args) => surface::frontier::run(args),
        Kind::OpenAir(args) => surface::open_air::run(args),
        Kind::Scaling(args) => scaling::run(args),
        Kind::Fuzz(args) => fuzz::run(args),
    }
}
