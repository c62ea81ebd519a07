//! `prt`: the command-line face of prt (docs/conventions.md section 6). Each subcommand turns its
//! options into a settings struct and calls one library function; the benchmarks are the
//! `prt-bench` binary's (bench/).

mod bake;
mod common;
mod inspect;
mod progress;
mod relight;
mod render;
mod sample;

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

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

#[derive(Subcommand)]
enum Command {
    /// Bake a glTF 2.0 scene into a PRT asset.
    Bake(bake::BakeArgs),
    /// Relight an asset once and write every probe's SH9 as JSON.
    Relight(relight::RelightArgs),
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

fn main() {
    prt_cli::process::main(run);
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Bake(args) => bake::run(args),
        Command::Relight(args) => relight::run(args),
        Command::Sample(args) => sample::run(args),
        Command::Render(args) => render::run(args),
        Command::Inspect { asset, json } => inspect::run(&asset, json),
    }
}
