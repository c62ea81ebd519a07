//! `prt relight` (docs/conventions.md section 6): one relight of an asset on the CPU reference or
//! the GPU, every probe's SH9 written as JSON.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use crate::common::{ensure_not_input, lighting_of, Backend};

#[derive(Args)]
pub struct RelightArgs {
    asset: PathBuf,
    /// Light rig JSON [default: the scene's KHR_lights_punctual lights, black sky].
    #[arg(long)]
    lights: Option<PathBuf>,
    #[arg(long, value_enum, default_value = "cpu")]
    backend: Backend,
    /// Light bounces (1 = direct light at surfels only: the one-bounce contract; more feed
    /// the volume back into the surfels, sampled as the engine samples it).
    #[arg(long, default_value_t = 1)]
    bounces: u32,
    /// Output JSON, written atomically.
    #[arg(long)]
    json: PathBuf,
}

/// Relights as `args` say and writes the JSON atomically (other tools read it: never half
/// written).
pub fn run(args: RelightArgs) -> Result<()> {
    let RelightArgs {
        asset,
        lights,
        backend,
        bounces,
        json,
    } = args;
    let mut inputs = vec![asset.as_path()];
    inputs.extend(lights.as_deref());
    ensure_not_input(&json, &inputs)?;
    let loaded =
        prt_format::read_asset(&asset).with_context(|| format!("loading {}", asset.display()))?;
    let lighting = lighting_of(lights.as_deref(), &loaded)?;
    let start = std::time::Instant::now();
    let (sh, stats, name) = match backend {
        Backend::Cpu => {
            let relit = prt_runtime::CpuRelighter::new(&loaded)?.relight(&lighting, bounces)?;
            println!("{}", relit.stats);
            (
                relit.sh,
                prt_runtime::output::cpu_stats(&relit.stats),
                "cpu",
            )
        }
        Backend::Gpu => {
            let prt_runtime::gpu::Relit {
                sh,
                counters,
                adapter: info,
                memory: (allocations, total),
            } = prt_runtime::gpu::relight_once(
                &loaded,
                &lighting,
                prt_runtime::gpu::RuntimeSettings {
                    bounces: prt_runtime::gpu::Bounces::Fixed(bounces),
                    ..prt_runtime::gpu::RuntimeSettings::default()
                }
                .fitted_to(&lighting),
            )?;
            eprintln!("adapter: {} ({:?})", info.name, info.backend);
            let largest: Vec<String> = (allocations.iter().take(4))
                .map(|a| format!("{} {:.1}", a.name, a.bytes as f64 / 1e6))
                .collect();
            println!(
                "gpu memory: {:.1} MB in all (largest, MB: {})",
                total as f64 / 1e6,
                largest.join(", ")
            );
            println!(
                "gpu work: {} bricks relit, {} surfels relit, {} shadow rays, {} probes gathered",
                counters.bricks_relit,
                counters.surfels_relit,
                counters.shadow_rays,
                counters.probes_gathered
            );
            if counters.probes_clamped > 0 {
                eprintln!(
                    "warning: {} probes exceed the f16 volume's range (+-65504) and are clamped in it (the SH written here are exact)",
                    counters.probes_clamped
                );
            }
            let stats = prt_runtime::output::gpu_stats(&counters, &allocations);
            (sh, stats, "gpu")
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    prt_runtime::relight::check_finite(&sh, &lighting)?;
    let doc = prt_runtime::output::relight_json(&loaded, &sh, name, stats);
    let text = serde_json::to_vec_pretty(&doc)?;
    prt_format::io::write_bytes_atomic(&json, &text)
        .with_context(|| format!("writing {}", json.display()))?;
    println!(
        "relit {} probes ({name}, {bounces} bounce(s)) in {seconds:.3} s",
        sh.len()
    );
    println!("wrote {}", json.display());
    Ok(())
}
