//! `prt-bench scaling`: what a sparse bake costs as a level grows (issue 32: bake seconds per
//! placed probe within +-25% across three sizes of an open level, and the GPU memory
//! `PrtRuntime` allocates for it).
//!
//! Each scene is baked with the default settings at one spacing (sparse placement; with
//! `--prune-error`, that prune error), timed in process from the scene file to the finished
//! asset, `--runs` times (the median is kept: one run swings by 10-20% on a shared machine).
//! A *placed* probe is one with data (traced, or
//! inside geometry reading a neighbour's: `Summary::probes_with_data`); the grid points the
//! runtime fills from coarse levels are not, though they are counted beside it. With `--gpu`,
//! each asset is relit once on the GPU with the rig beside its scene (`NAME_rig.json`, as the
//! level generator writes it) and the runtime's allocations are listed, largest first.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use prt_format::summary::Summary;

use crate::results::Out;
use crate::surface::score::percentile;

#[derive(clap::Args)]
pub struct ScalingArgs {
    /// Scenes, smallest first: one level at several sizes (e.g. `fixtures/levels/generate.py
    /// --kind plaza --seed 40 --size S`).
    #[arg(required = true)]
    scenes: Vec<PathBuf>,
    /// Probe spacing in metres, the same for every scene.
    #[arg(long)]
    spacing: f32,
    /// Bakes per scene; the median time is reported.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=20))]
    runs: u32,
    /// Also relight each asset once on the GPU with the rig beside its scene (`NAME_rig.json`)
    /// and list the GPU memory the runtime allocates.
    #[arg(long)]
    gpu: bool,
    /// Drop probes whose prediction error is below this (`prt bake --prune-error`) [default:
    /// the bake's].
    #[arg(long)]
    prune_error: Option<f32>,
    #[command(flatten)]
    out: Out,
}

/// One scene's figures.
struct Scaled {
    name: String,
    summary: Summary,
    /// Median bake seconds.
    seconds: f64,
    /// Every run's seconds, in order.
    runs: Vec<f64>,
    /// The runtime's allocations (name, bytes), largest first, and their total.
    gpu: Option<(Vec<(String, u64)>, u64)>,
}

/// `prt-bench scaling`: bakes each scene, prints the table and with `--out` writes
/// `scaling.md`.
pub fn run(args: ScalingArgs) -> Result<()> {
    anyhow::ensure!(
        args.spacing.is_finite() && args.spacing > 0.0,
        "--spacing {}: give a positive spacing in metres",
        args.spacing
    );
    // A bad --prune-error is refused by the bake's own check of its settings.
    let settings = settings(&args);
    let mut scaled = Vec::new();
    for scene in &args.scenes {
        let s = measure(scene, &settings, args.runs, args.gpu)?;
        eprintln!(
            "{}: {} probes placed, {:.2} s, {:.3} ms a probe",
            s.name,
            s.summary.probes_with_data,
            s.seconds,
            per_probe_ms(&s)
        );
        scaled.push(s);
    }
    args.out.report("scaling", &markdown(&args, &scaled))
}

/// The bake settings of `args`: the defaults at its spacing (and prune error).
fn settings(args: &ScalingArgs) -> BakeSettings {
    let defaults = BakeSettings::default();
    BakeSettings {
        spacing: Some(args.spacing),
        prune_error: args.prune_error.unwrap_or(defaults.prune_error),
        ..defaults
    }
}

/// Bakes `scene` with `settings` `runs` times (and relights it once with `gpu`).
fn measure(scene: &Path, settings: &BakeSettings, runs: u32, gpu: bool) -> Result<Scaled> {
    let mut times = Vec::new();
    let mut asset = None;
    for _ in 0..runs {
        // The previous run's asset is dropped first: two in memory would not be what a bake
        // costs.
        drop(asset.take());
        let t = Instant::now();
        let (baked, _) = prt_bake::bake(scene, settings, &NoProgress)
            .with_context(|| format!("baking {}", scene.display()))?;
        times.push(t.elapsed().as_secs_f64());
        asset = Some(baked);
    }
    let asset =
        asset.with_context(|| format!("{}: --runs {runs} baked nothing", scene.display()))?;
    let name = scene.file_stem().map_or_else(
        || scene.display().to_string(),
        |s| s.to_string_lossy().into(),
    );
    let gpu = gpu.then(|| gpu_memory(scene, &asset)).transpose()?;
    Ok(Scaled {
        summary: Summary::of(&asset, 0),
        name,
        seconds: percentile(&times, 0.5),
        runs: times,
        gpu,
    })
}

/// The GPU memory of `asset` relit once with the rig beside `scene`.
fn gpu_memory(scene: &Path, asset: &prt_format::Asset) -> Result<(Vec<(String, u64)>, u64)> {
    let stem = scene.file_stem().unwrap_or_default().to_string_lossy();
    let rig = scene.with_file_name(format!("{stem}_rig.json"));
    let lighting = prt_runtime::load_rig(&rig)
        .with_context(|| format!("{}: loading the rig {}", stem, rig.display()))?;
    let settings = prt_runtime::gpu::RuntimeSettings::default().fitted_to(&lighting);
    let relit = prt_runtime::gpu::relight_once(asset, &lighting, settings)
        .with_context(|| format!("{stem}: relighting on the GPU"))?;
    let (allocations, total) = relit.memory;
    let named = (allocations.into_iter())
        .map(|a| (a.name.to_owned(), a.bytes))
        .collect();
    Ok((named, total))
}

/// Milliseconds of bake per placed probe (probe with data).
fn per_probe_ms(s: &Scaled) -> f64 {
    1e3 * s.seconds / s.summary.probes_with_data.max(1) as f64
}

/// The report: a row per scene, each one's time per placed probe against the median's.
fn markdown(args: &ScalingArgs, scaled: &[Scaled]) -> String {
    let per: Vec<f64> = scaled.iter().map(per_probe_ms).collect();
    let mid = percentile(&per, 0.5);
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Bake time against level size\n\n`prt-bench scaling {} --spacing {} --runs {}{}{}`: \
         each scene baked with the default settings (sparse placement){}, at {} m, timed in \
         process from the scene file to the asset, median of {} run(s). Placed: probes with \
         data; filled: grid points the runtime fills from coarse levels.\n",
        (args.scenes.iter())
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(" "),
        args.spacing,
        args.runs,
        if args.gpu { " --gpu" } else { "" },
        args.prune_error
            .map_or(String::new(), |e| format!(" --prune-error {e}")),
        args.prune_error
            .map_or(String::new(), |e| format!(", but a prune error of {e}")),
        args.spacing,
        args.runs
    );
    md.push_str(
        "| scene | grid points | placed | filled | surfels | factors | bake s (runs) | ms per placed \
         probe | against the median | grid points per placed probe | GPU MB |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for s in scaled {
        let m = &s.summary;
        let runs: Vec<String> = s.runs.iter().map(|t| format!("{t:.2}")).collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {:.2} ({}) | {:.3} | {:+.1}% | {:.1} | {} |",
            s.name,
            m.probe_count,
            m.probes_with_data,
            m.filled_probe_count,
            m.surfel_count,
            m.factor_count,
            s.seconds,
            runs.join(", "),
            per_probe_ms(s),
            100.0 * (per_probe_ms(s) / mid - 1.0),
            m.probe_count as f64 / m.probes_with_data.max(1) as f64,
            s.gpu.as_ref().map_or("-".into(), |(_, total)| format!(
                "{:.1}",
                *total as f64 / 1e6
            ))
        );
    }
    for s in scaled {
        let Some((allocations, total)) = &s.gpu else {
            continue;
        };
        let _ = writeln!(
            md,
            "\n{}: GPU memory {:.1} MB, largest first (MB):\n",
            s.name,
            *total as f64 / 1e6
        );
        let rows: Vec<String> = (allocations.iter())
            .filter(|(_, bytes)| *bytes >= 1_000_000)
            .map(|(name, bytes)| format!("{name} {:.1}", *bytes as f64 / 1e6))
            .collect();
        let _ = writeln!(md, "{}; the rest under 1 MB each.", rows.join(", "));
    }
    md
}
