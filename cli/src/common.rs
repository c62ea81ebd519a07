//! What several `prt` subcommands share: the CPU/GPU choice, refusing to overwrite an input,
//! and the lighting of `--lights`.

use std::path::Path;

use anyhow::Result;
use clap::ValueEnum;

#[derive(Clone, Copy, ValueEnum)]
pub enum Backend {
    Cpu,
    Gpu,
}

/// Fails when `output` is one of the command's input files (it would be replaced).
pub fn ensure_not_input(output: &Path, inputs: &[&Path]) -> Result<()> {
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
pub fn lighting_of(rig: Option<&Path>, asset: &prt_format::Asset) -> Result<prt_runtime::Lighting> {
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
