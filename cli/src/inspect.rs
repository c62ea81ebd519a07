//! `prt inspect`: an asset's summary, as text or JSON.

use std::path::Path;

use anyhow::{Context, Result};

/// Prints the summary of the asset at `asset` (JSON with `json`).
pub fn run(asset: &Path, json: bool) -> Result<()> {
    let bytes = prt_format::read_regular_file(asset)
        .with_context(|| format!("reading {}", asset.display()))?;
    let loaded =
        prt_format::decode(&bytes).with_context(|| format!("loading {}", asset.display()))?;
    let summary = prt_format::Summary::of(&loaded, bytes.len() as u64);
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(())
}
