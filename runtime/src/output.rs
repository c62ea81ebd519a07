//! The relight JSON of docs/conventions.md section 6: `{"probes": [{"index": i, "position":
//! [x,y,z], "valid": true, "dilated": false, "sh": [[r,g,b] x 9]}, ...]}`. `valid` is what the
//! runtime gathers (it also samples the grid points sparse placement filled, which are not
//! valid, with the SH of the coarse level they are filled from); `dilated` marks the valid
//! probes that read their nearest measured neighbour's data, so that a tool can tell them from
//! measured ones.

use prt_format::sh::ShRgb;
use prt_format::Asset;
use serde_json::{json, Value};

use crate::contract::Counters;
use crate::gpu::Allocation;
use crate::relight::RelightStats;

/// The JSON document for `sh` relit from `asset` by `backend`, with that backend's work counts
/// ([`cpu_stats`], [`gpu_stats`]) under `"stats"`.
pub fn relight_json(asset: &Asset, sh: &[ShRgb], backend: &str, stats: Value) -> Value {
    let probes: Vec<Value> = asset
        .probes
        .iter()
        .zip(sh)
        .enumerate()
        .map(|(i, (p, c))| {
            json!({
                "index": i,
                "position": p.position,
                "valid": p.is_valid(),
                "dilated": p.is_dilated(),
                "sh": c,
            })
        })
        .collect();
    json!({
        "backend": backend,
        "stats": stats,
        "probes": probes,
    })
}

/// What the CPU relight did and skipped.
pub fn cpu_stats(stats: &RelightStats) -> Value {
    json!({
        "bricks": stats.bricks,
        "bricks_skipped_backface": stats.bricks_skipped_backface,
        "light_brick_pairs": stats.light_brick_pairs,
        "culled_dark": stats.culled_dark,
        "culled_range": stats.culled_range,
        "culled_cone": stats.culled_cone,
        "culled_facing": stats.culled_facing,
        "shadow_rays": stats.shadow_rays,
        "probes_gathered": stats.probes_gathered,
        "probes_skipped_invalid": stats.probes_skipped_invalid,
    })
}

/// What the GPU update did (its work counters) and what the runtime allocated for it
/// ([`crate::gpu::PrtRuntime::gpu_memory`]: every buffer and texture group in bytes, largest
/// first, and their sum), so that an engine can budget a level from one relight.
pub fn gpu_stats(counters: &Counters, allocations: &[Allocation]) -> Value {
    let total: u64 = allocations.iter().map(|a| a.bytes).sum();
    let memory: Vec<Value> = allocations
        .iter()
        .map(|a| json!({ "name": a.name, "bytes": a.bytes }))
        .collect();
    json!({
        "bricks_relit": counters.bricks_relit,
        "surfels_relit": counters.surfels_relit,
        "shadow_rays": counters.shadow_rays,
        "probes_gathered": counters.probes_gathered,
        "probes_clamped": counters.probes_clamped,
        "gpu_memory_bytes": total,
        "gpu_memory": memory,
    })
}

/// Reads the `sh` of every probe from a relight or oracle JSON document (the oracle's
/// `probes[i].sh` has the same layout), with positions.
pub fn read_probe_sh(doc: &Value) -> Option<Vec<([f32; 3], ShRgb)>> {
    doc.get("probes")?
        .as_array()?
        .iter()
        .map(|p| {
            let pos = p.get("position")?.as_array()?;
            let position: [f32; 3] = [
                pos.first()?.as_f64()? as f32,
                pos.get(1)?.as_f64()? as f32,
                pos.get(2)?.as_f64()? as f32,
            ];
            let sh = p.get("sh")?.as_array()?;
            let mut c = [[0.0f32; 3]; 9];
            for (k, row) in sh.iter().enumerate().take(9) {
                let row = row.as_array()?;
                for ch in 0..3 {
                    c[k][ch] = row.get(ch)?.as_f64()? as f32;
                }
            }
            Some((position, c))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The GPU stats list every allocation with its bytes, in the order given, and their sum.
    #[test]
    fn gpu_stats_list_the_memory() {
        let allocations = [
            Allocation {
                name: "factors (all chunks)",
                bytes: 300,
            },
            Allocation {
                name: "probes",
                bytes: 20,
            },
        ];
        let doc = gpu_stats(&Counters::default(), &allocations);
        assert_eq!(doc["gpu_memory_bytes"], 320);
        assert_eq!(doc["gpu_memory"][0]["name"], "factors (all chunks)");
        assert_eq!(doc["gpu_memory"][1]["bytes"], 20);
        assert_eq!(doc["gpu_memory"].as_array().map(Vec::len), Some(2));
    }
}
