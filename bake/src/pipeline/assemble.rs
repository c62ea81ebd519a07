//! The assemble stage: the asset's per-probe records and sections, in probe order, and its
//! header, out of what the earlier stages of [`super::bake_in_pool`] traced and encoded.

use std::path::Path;

use glam::Vec3;
use prt_format::{
    BakeSettingsRecord, BakeStats, Header, Probe, SurfelPrecision, NO_SLOT, PROBE_DILATED,
    PROBE_OFFSET, PROBE_VALID,
};
use prt_scene::Scene;

use super::{inside, Loaded};
use crate::tables::encode;
use crate::{trace, BakeSettings};

/// Per probe, in probe order: its record, and the sky mask and sky transfer it carries with
/// its factor table (`carried`). A dilated probe reads its source's table (its run is the
/// source's, format 12) and carries copies of its sky and ray counts (the record describes the
/// data it reads); only its position is its own. An invalid probe that is not dilated, like a
/// grid point the placement left out, carries nothing: no table, flags or slot in the sky and
/// visibility sections ([`prt_format::Probe::slot`]).
pub(super) fn assemble_probes(
    traced: &[trace::ProbeRays],
    positions: &[(Vec3, bool)],
    carried: encode::Carried,
) -> Assembled {
    let mut probes = Vec::with_capacity(traced.len());
    let placed = carried.from.iter().filter(|f| f.is_some()).count();
    let mut sky_records: Vec<&[u32]> = Vec::with_capacity(placed);
    let mut sky_transfer = Vec::with_capacity(placed);
    let mut first_factor = 0u32;
    let mut slot = 0u32;
    for (p, &(pos, moved)) in positions.iter().enumerate() {
        // Left out by the placement, or invalid with nothing to copy: never gathered, weighed
        // 0 by every lookup, so its sky and visibility data would never be read.
        let (flags, from) = match carried.from[p] {
            Some(q) if q == p => (PROBE_VALID, p),
            Some(q) => (PROBE_VALID | PROBE_DILATED, q),
            None => {
                probes.push(Probe {
                    position: pos.to_array(),
                    flags: if moved { PROBE_OFFSET } else { 0 },
                    slot: NO_SLOT,
                    first_factor,
                    ..Probe::default()
                });
                continue;
            }
        };
        // A dilated probe has no table of its own (`carried.lens` 0): its run is set to its
        // source's below, once every source has its place.
        let len = carried.lens[p] as u32;
        probes.push(Probe {
            position: pos.to_array(),
            flags: flags | if moved { PROBE_OFFSET } else { 0 },
            first_factor,
            factor_count: len,
            sky_rays: traced[from].sky_rays,
            slot,
        });
        // At most 2^32 - 1 factor slots in all (checked once the tables were encoded), and as
        // many placed probes as grid points.
        first_factor += len;
        slot += 1;
        sky_records.push(&traced[from].sky_mask);
        sky_transfer.push(traced[from].sky_transfer);
    }
    for (p, from) in carried.from.iter().enumerate() {
        if let Some(q) = from.filter(|&q| q != p) {
            (probes[p].first_factor, probes[p].factor_count) =
                (probes[q].first_factor, probes[q].factor_count);
        }
    }
    Assembled {
        probes,
        sky_mask: prt_format::sky_mask::with_index(sky_records.into_iter()),
        sky_transfer,
    }
}

/// The per-probe sections of the asset, before encoding.
pub(super) struct Assembled {
    pub probes: Vec<Probe>,
    pub sky_mask: Vec<u32>,
    pub sky_transfer: Vec<[f32; prt_format::sh::SH_COUNT]>,
}

/// The asset's header: what was baked (`scene_path`, as `loaded`) on which `grid`, how
/// (`settings`, cells of `cell_size`), and the counts of the `traced` rays.
pub(super) fn header(
    scene_path: &Path,
    loaded: &Loaded,
    grid: prt_format::Grid,
    settings: &BakeSettings,
    cell_size: f32,
    traced: &[trace::ProbeRays],
) -> Header {
    Header {
        generator: format!("prt-bake {}", env!("CARGO_PKG_VERSION")),
        source_name: prt_scene::source_name(scene_path),
        source_hash: loaded.source_hash,
        ray_count: settings.rays,
        settings: settings_record(settings, grid.spacing, cell_size),
        stats: stats(&loaded.scene, traced, settings),
        grid,
    }
}

/// The settings as the asset records them.
fn settings_record(settings: &BakeSettings, spacing: f32, cell_size: f32) -> BakeSettingsRecord {
    BakeSettingsRecord {
        spacing,
        bounds: settings.bounds,
        cell_size,
        merge_distance: cell_size,
        merge_normal_cos: settings.merge_normal_cos,
        double_sided_override: settings.double_sided,
        invalid_backface_fraction: settings.invalid_backface_fraction,
        transfer_precision: settings.transfer_precision,
        surfel_precision: SurfelPrecision::for_transfer(settings.transfer_precision),
        far_ratio: if cell_size > 0.0 {
            settings.far_ratio
        } else {
            0.0
        },
    }
}

/// The bake's counts for the asset's header: `traced` probes of `settings.rays` rays each over
/// `scene`. Hits of probes inside geometry make no surfels (`stream::fold_block`), so the
/// unmerged surfels are the other probes' hits.
fn stats(scene: &Scene, traced: &[trace::ProbeRays], settings: &BakeSettings) -> BakeStats {
    let n = settings.rays;
    let traced = || traced.iter().filter(|r| r.placed);
    // Every ray hits a surface or the sky.
    let hits_of = |r: &trace::ProbeRays| u64::from(n - r.sky_rays);
    let hits: u64 = traced().map(hits_of).sum();
    BakeStats {
        triangles: scene.triangles.len() as u64,
        degenerate_triangles_skipped: scene.degenerate_skipped,
        rays: traced().count() as u64 * u64::from(n),
        ray_hits: hits,
        backface_hits: traced().map(|r| u64::from(r.backface_rays)).sum(),
        surfels_unmerged: traced().filter(|r| !inside(settings, r)).map(hits_of).sum(),
    }
}
