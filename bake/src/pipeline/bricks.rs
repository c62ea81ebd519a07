//! The bricks stage: which traced probes are valid and whose factor table each carries
//! (dilation into holes), then the bricks numbered, their surfels finished and the factor
//! tables encoded.

use glam::Vec3;
use prt_format::coarse::CoarseBricks;
use prt_format::{Factors, TransferPrecision, DEPTH_WORDS, U8_MAX_BRICK};
use prt_scene::Scene;

use super::{valid, Built, Loaded};
use crate::accel::bvh::SceneBvh;
use crate::merge::{coarse, fold, links, snap, split};
use crate::tables::{encode, factors};
use crate::{diagnostics, dilate, placement, stream, trace, BakeError, BakeReport, BakeSettings};

/// What the bricks stage gives the bake.
pub(super) struct Bricks {
    /// Per grid point, where its probe's rays started and whether it left its grid point.
    pub(super) positions: Vec<(Vec3, bool)>,
    /// Per grid point, what its rays saw ([`trace::ProbeRays::not_placed`] where not traced).
    pub(super) rays: Vec<trace::ProbeRays>,
    /// Per grid point, whose factor table it carries ([`carried_layout`]), and how many
    /// factors (u8 slots) that is once encoded.
    pub(super) from: Vec<Option<usize>>,
    pub(super) lens: Vec<usize>,
    /// The visibility maps of the probes with data, in slot order.
    pub(super) depth: Vec<u32>,
    pub(super) bricked: fold::Bricked,
    pub(super) coarse: CoarseBricks,
    pub(super) factors: Factors,
}

/// The bricks stage over what the trace stage gave (`traced`): which probes are valid
/// ([`validity`]) and whose table each carries ([`carried_layout`]: on a sparse bake, of
/// `plan`, holes are filled only in cells a surface passes through), then the bricks and the
/// encoded factor tables ([`bricks_and_tables`]).
pub(super) fn bricks_stage(
    traced: stream::Traced,
    (grid, plan, placed): (&prt_format::Grid, Option<&placement::Plan>, &[bool]),
    (settings, cell_size): (&BakeSettings, f32),
    (loaded, built): (&Loaded, &Built),
    report: &mut BakeReport,
) -> Result<Bricks, BakeError> {
    let valid = validity(&traced.rays, settings, built, &loaded.scene, report);
    let cells = plan
        .filter(|_| settings.dilate)
        .map(placement::Plan::surface_cells);
    let layout = (&valid[..], placed, cells);
    let (from, lens) = carried_layout(grid, layout, settings, &traced.rows)?;
    let stream::Traced {
        positions,
        rays,
        rows: tables,
        depth,
        folder,
        far_levels,
    } = traced;
    let depth = with_data(depth, &rays, &from);
    let surfaces = snap::Surfaces {
        bvh: &built.bvh,
        triangles: &loaded.scene.triangles,
        cell_size,
        double_sided: settings.double_sided,
    };
    let origins: Vec<Vec3> = positions.iter().map(|&(origin, _)| origin).collect();
    let carried = encode::Carried {
        from: &from,
        lens: &lens,
        origins: &origins,
    };
    let (bricked, coarse, (factors, lens), split) = bricks_and_tables(
        (folder, tables),
        carried,
        settings,
        (cell_size, &far_levels),
        (&surfaces, &built.bvh),
    )?;
    report.split = split;
    Ok(Bricks {
        positions,
        rays,
        from,
        lens,
        depth,
        bricked,
        coarse,
        factors,
    })
}

/// The encoded factor table and each probe's factor count (u8 slots).
type Tables = (Factors, Vec<usize>);

/// The bricks stage: numbers the bricks and finishes their surfels (those behind their
/// surface put back on it, [`snap`]; bricks split where a wall stands on them, [`split`]),
/// then encodes the factor tables the probes carry into the asset's table
/// ([`encode::encode_tables`]), freeing the rows as it goes, with each probe's factor count
/// and how many bricks were split into how many parts; fails when u8 factors cannot address
/// the bricks or their slots pass 2^32.
fn bricks_and_tables(
    (folder, tables): (fold::BrickFolder, factors::Rows),
    carried: encode::Carried,
    settings: &BakeSettings,
    (cell_size, far_levels): (f32, &[u8]),
    (surfaces, bvh): (&snap::Surfaces, &SceneBvh),
) -> Result<(fold::Bricked, CoarseBricks, Tables, (usize, usize)), BakeError> {
    let (bricked, remap) = folder.finish_placed(&|s, cell| surfaces.place(s, cell));
    let (bricked, parts) = match settings.split_bricks {
        true => split::split(bricked, cell_size, bvh),
        false => (bricked, split::FineParts::default()),
    };
    let mut used = vec![0u8; bricked.bricks.len()];
    for (&b, &l) in remap.iter().zip(far_levels) {
        for p in parts.parts(b) {
            used[p as usize] |= l;
        }
    }
    // Links only where a coarse brick will be made (some row is far), lifted a brick size (four
    // cells) off the surface: a quarter of a cell split Sponza's columns' cells needlessly.
    let linked = match used.iter().any(|&bits| bits > 1) {
        true => links::Links {
            pairs: links::links(&bricked.keys, &bricked.fits, 4.0 * cell_size, bvh),
            bounds: (bricked.bricks.iter())
                .map(|b| [Vec3::from(b.min), Vec3::from(b.max)])
                .collect(),
            margin: cell_size,
        },
        false => links::Links::default(),
    };
    let (coarse, placement) = coarse::build(&bricked.keys, &bricked.fits, &used, &linked);
    let u8_rows = settings.transfer_precision == TransferPrecision::U8;
    let all = bricked.bricks.len() + coarse.bricks.len();
    if u8_rows && all > U8_MAX_BRICK as usize + 1 {
        return Err(BakeError::Setting {
            name: "precision",
            value: format!(
                "u8 with {} bricks and {} coarse bricks",
                bricked.bricks.len(),
                coarse.bricks.len()
            ),
            reason: "the 8-bit factor encoding addresses at most 16,777,216 bricks; use f16",
        });
    }
    let encoding = (settings.transfer_precision, 4.0 * cell_size);
    let numbering = (&remap[..], &bricked.bricks[..], (&placement, &parts));
    let (factors, lens) = encode::encode_tables(tables, carried, numbering, encoding)?;
    if factors.len() > u32::MAX as usize {
        return Err(BakeError::Setting {
            name: "spacing",
            value: format!("{} factor slots", factors.len()),
            reason:
                "more than 2^32 factor slots (a factor takes one or two): use fewer probes or rays",
        });
    }
    Ok((bricked, coarse, (factors, lens), parts.split_count()))
}

/// Per probe, whether it is valid (placed and not inside geometry, [`valid`]); warns when most
/// placed probes are not, with the winding hint when the BVH stage found inconsistent winding
/// (counting it now if it did not run then).
fn validity(
    rays: &[trace::ProbeRays],
    settings: &BakeSettings,
    built: &Built,
    scene: &Scene,
    report: &mut BakeReport,
) -> Vec<bool> {
    let valid: Vec<bool> = rays.iter().map(|r| valid(settings, r)).collect();
    let placed: Vec<bool> = (rays.iter().zip(&valid))
        .filter(|(r, _)| r.placed)
        .map(|(_, &v)| v)
        .collect();
    let count_winding = || {
        built
            .winding
            .unwrap_or_else(|| diagnostics::winding(&scene.triangles))
    };
    let hint = built.winding_hint;
    if let Some(w) = diagnostics::inside_warning(&placed, settings, count_winding, hint) {
        report.warnings.push(w);
    }
    valid
}

/// Per probe of `grid`: whose factor table it reads (its own when valid, else, placed, its
/// dilation source's when the settings dilate, into holes of `cells` if given, else none) and
/// how many factors that is; fails when they pass 2^32 in all.
fn carried_layout(
    grid: &prt_format::Grid,
    (valid, placed, cells): (&[bool], &[bool], Option<&[bool]>),
    settings: &BakeSettings,
    tables: &factors::Rows,
) -> Result<(Vec<Option<usize>>, Vec<usize>), BakeError> {
    let sources = if settings.dilate {
        dilate::sources(grid, valid, cells)
    } else {
        vec![None; valid.len()]
    };
    let from: Vec<Option<usize>> = valid
        .iter()
        .zip(&sources)
        .enumerate()
        .map(|(p, (&valid, &source))| match valid {
            true => Some(p),
            false => source.filter(|_| placed[p]),
        })
        .collect();
    let lens: Vec<usize> = from
        .iter()
        .map(|f| f.map_or(0, |q| tables.len(q)))
        .collect();
    // Dilated probes read their sources' tables: only the probes' own count.
    let factor_count: u64 = encode::own(&from, &lens).map(|len| len as u64).sum();
    if factor_count > u64::from(u32::MAX) {
        return Err(BakeError::Setting {
            name: "spacing",
            value: format!("{factor_count} factors"),
            reason: "more than 2^32 factors: use fewer probes or rays",
        });
    }
    Ok((from, lens))
}

/// The visibility maps of the probes with data (those that carry a table, `from`) out of
/// `depth`, one map per traced probe of `traced`.
fn with_data(mut depth: Vec<u32>, traced: &[trace::ProbeRays], from: &[Option<usize>]) -> Vec<u32> {
    let mut kept = 0;
    let maps = traced.iter().zip(from).filter(|(r, _)| r.placed);
    for (map, (_, from)) in maps.enumerate() {
        if from.is_some() {
            let words = map * DEPTH_WORDS..(map + 1) * DEPTH_WORDS;
            depth.copy_within(words, kept * DEPTH_WORDS);
            kept += 1;
        }
    }
    depth.truncate(kept * DEPTH_WORDS);
    depth.shrink_to_fit();
    depth
}
