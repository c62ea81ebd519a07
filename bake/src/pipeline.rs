//! The bake's stages in order, from the scene file to the validated asset: load, BVH, trace
//! (merging as it goes, [`crate::stream`]), bricks (numbering them and encoding the factor
//! tables), assemble. [`crate::bake`] runs them in its thread pool, then [`validate`]s the
//! asset; each stage's time goes into the report.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use prt_format::{
    directions, Asset, BakeSettingsRecord, BakeStats, Factors, Header, Probe, TransferPrecision,
    PROBE_DILATED, PROBE_OFFSET, PROBE_VALID, U8_MAX_BRICK,
};

use crate::{
    bricks, bvh, diagnostics, dilate, factors, offset, probes, scene, stream, texture, trace,
    BakeError, BakeReport, BakeSettings, Progress, WINDING_WARNING,
};

/// The bake's stages, in the current thread pool: the asset, not yet validated, and the report.
pub(crate) fn bake_in_pool(
    scene_path: &Path,
    settings: &BakeSettings,
    progress: &dyn Progress,
) -> Result<(Asset, BakeReport), BakeError> {
    let mut report = BakeReport::default();
    let mut t = Instant::now();
    // Ends the stage under way (its bar or spinner, its time) and starts the next, if any.
    let mut lap = |report: &mut BakeReport, stage, next: Option<&str>| {
        progress.finish();
        report.timings.push((stage, t.elapsed()));
        t = Instant::now();
        if let Some(next) = next {
            progress.start(next, 0);
        }
    };
    progress.start("load", 0);
    let Loaded {
        scene,
        source_hash,
        bounds: (min, max),
        winding_warning_at,
    } = load(scene_path, settings, &mut report)?;
    lap(&mut report, "load", Some("bvh"));

    let spacing = settings
        .spacing
        .unwrap_or_else(|| probes::default_spacing(min, max));
    // The grid first: a spacing far too small for the scene is refused before any other work.
    let grid = probes::grid(min, max, spacing, settings.max_probes)?;
    let rays = grid.probe_count().saturating_mul(u64::from(settings.rays));
    // Baked double-sided, the winding changes no hit's shading and needs no hint: it is then
    // counted only for the rare warning that names it (most probes inside geometry), not on
    // every bake (Sponza, 562k edges: about 24 ms of CPU time beside the BVH's collapse).
    let (bvh, winding) =
        bvh::SceneBvh::build_checked(&scene.triangles, bvh::trace_scale(spacing), rays, || {
            (!settings.double_sided).then(|| diagnostics::winding(&scene.triangles))
        })?;
    let winding_hint = match &winding {
        Some(w) if w.inconsistent_fraction() > WINDING_WARNING => {
            let warning = diagnostics::winding_warning(w);
            report.warnings.insert(winding_warning_at, warning);
            true
        }
        _ => false,
    };
    lap(&mut report, "bvh", None);

    let positions = probes::positions(&grid);
    let n = settings.rays;
    let dirs: Vec<Vec3> = directions::fibonacci_directions(n)
        .into_iter()
        .map(Vec3::from)
        .collect();
    let weight = directions::direction_weight(n);
    let order = trace::coherent_order(&dirs);
    let tracer = trace::Tracer {
        scene: &scene,
        bvh: &bvh,
        directions: &dirs,
        basis: dirs
            .iter()
            .map(|d| prt_format::sh::basis(d.to_array()))
            .collect(),
        order: &order,
        weight,
        double_sided: settings.double_sided,
        srgb: texture::srgb_to_linear_table(),
        shading: trace::triangle_shading(&scene),
    };
    progress.start("trace", positions.len() as u64);
    let is_inside = |r: &trace::ProbeRays| {
        r.backface_rays as f32 > settings.invalid_backface_fraction * n as f32
            || (r.sky_rays == 0
                && r.facing_away_rays as f32 > settings.inside_facing_away_fraction * n as f32)
    };
    let [nx, ny, nz] = grid.counts;
    let trace_one = |index: usize| {
        let grid_p = positions[index];
        let (i, j, k) = (
            index as u32 % nx,
            (index as u32 / nx) % ny,
            index as u32 / (nx * ny),
        );
        let ijk = [(i, nx), (j, ny), (k, nz)];
        let outer = ijk.iter().any(|&(c, n)| n > 1 && (c == 0 || c == n - 1));
        let inwards = Vec3::from_array(ijk.map(|(c, n)| if 2 * c > n - 1 { -1.0 } else { 1.0 }));
        let p = if settings.surface_offset {
            let centre = outer.then_some((min + max) * 0.5);
            offset::surface_offset(&tracer, grid_p, spacing, inwards, centre)
        } else {
            grid_p
        };
        let r = tracer.trace_probe(p);
        if settings.virtual_offset && is_inside(&r) {
            if let Some((moved, again)) =
                offset::virtual_offset(&tracer, p, &r, spacing, &is_inside)
            {
                return (moved, again, true);
            }
        }
        (p, r, p != grid_p)
    };
    let cell_size = settings
        .cell_size
        .unwrap_or(spacing / settings.cells_per_spacing);
    // Half a cell off the origin: see `bricks::BrickFolder::new`.
    let folder = bricks::BrickFolder::new(
        cell_size,
        settings.merge_normal_cos,
        Vec3::splat(-0.5 * cell_size),
    );
    let stream::Traced {
        positions,
        rays: traced,
        rows: tables,
        depth: probe_depth,
        folder,
    } = stream::trace_and_fold(
        positions.len(),
        &trace_one,
        &tracer,
        folder,
        &stream::Keep {
            spacing,
            precision: settings.transfer_precision,
            row_memory: settings.row_memory,
            rows_of: &|r| !is_inside(r),
        },
        progress,
    )?;
    report.rows_spilled = tables.spilled_bytes();
    lap(&mut report, "trace", Some("bricks"));

    let valid: Vec<bool> = traced.iter().map(|r| !is_inside(r)).collect();
    let count_winding = || winding.unwrap_or_else(|| diagnostics::winding(&scene.triangles));
    if let Some(w) = diagnostics::inside_warning(&valid, settings, count_winding, winding_hint) {
        report.warnings.push(w);
    }
    let sources = if settings.dilate {
        dilate::sources(&grid, &valid)
    } else {
        vec![None; valid.len()]
    };
    let (from, lens) = carried_layout(&valid, &sources, &tables)?;
    let carried = factors::Carried {
        from: &from,
        lens: &lens,
    };
    let (bricked, factors) = bricks_and_tables(folder, tables, carried, settings, cell_size)?;
    lap(&mut report, "bricks", Some("assemble"));

    let Assembled {
        probes: probes_out,
        sky_mask,
        sky_transfer,
    } = assemble_probes(&traced, &positions, carried);
    // Every ray hits a surface or the sky.
    let hits: u64 = traced.iter().map(|r| u64::from(n - r.sky_rays)).sum();
    let stats = BakeStats {
        triangles: scene.triangles.len() as u64,
        degenerate_triangles_skipped: scene.degenerate_skipped,
        rays: traced.len() as u64 * u64::from(n),
        ray_hits: hits,
        backface_hits: traced.iter().map(|r| u64::from(r.backface_rays)).sum(),
        surfels_unmerged: hits,
    };
    let asset = Asset {
        header: Header {
            generator: format!("prt-bake {}", env!("CARGO_PKG_VERSION")),
            source_name: scene::source_name(scene_path),
            source_hash,
            grid,
            ray_count: n,
            settings: BakeSettingsRecord {
                spacing,
                bounds: settings.bounds,
                cell_size,
                merge_distance: cell_size,
                merge_normal_cos: settings.merge_normal_cos,
                double_sided_override: settings.double_sided,
                invalid_backface_fraction: settings.invalid_backface_fraction,
                transfer_precision: settings.transfer_precision,
            },
            stats,
        },
        probes: probes_out,
        sky_mask,
        sky_transfer,
        probe_depth,
        factors,
        bricks: bricked.bricks,
        surfels: bricked.surfels,
        geometry: bvh.geometry,
        lights: scene.lights,
    };
    lap(&mut report, "assemble", None);
    Ok((asset, report))
}

/// Validates a baked asset (`scene_path` names the scene in the error): a failure here is a bug
/// of the bake, reported rather than written.
pub(crate) fn validate(asset: &Asset, scene_path: &Path) -> Result<(), BakeError> {
    prt_format::validate::validate(asset).map_err(|error| BakeError::Format {
        path: scene_path.to_owned(),
        error,
    })
}

/// What the load stage gives the bake.
struct Loaded {
    scene: scene::Scene,
    /// xxh3 of the scene file's bytes.
    source_hash: u64,
    /// The grid's bounds: the settings' or the scene's.
    bounds: (Vec3, Vec3),
    /// Where in the report's warnings the winding warning goes (it is known only after the BVH
    /// stage, beside which the check runs): after the scene's own.
    winding_warning_at: usize,
}

/// The load stage: reads and parses the scene, warns about what it skipped, and picks the
/// bounds; fails on an unreadable file or a scene with neither triangles nor bounds.
fn load(
    scene_path: &Path,
    settings: &BakeSettings,
    report: &mut BakeReport,
) -> Result<Loaded, BakeError> {
    let source_bytes =
        prt_format::read_regular_file(scene_path).map_err(|error| BakeError::Io {
            path: scene_path.to_owned(),
            error,
        })?;
    let source_hash = xxhash_rust::xxh3::xxh3_64(&source_bytes);
    let scene = scene::load_bytes(scene_path, &source_bytes)?;
    drop(source_bytes);
    report.warnings.extend(scene.warnings.iter().cloned());
    let winding_warning_at = report.warnings.len();
    if scene.degenerate_skipped > 0 {
        report.warnings.push(format!(
            "{} degenerate (zero-area) triangles skipped",
            scene.degenerate_skipped
        ));
    }
    let bounds = match (settings.bounds, scene.bounds()) {
        (Some(b), _) => (Vec3::new(b[0], b[1], b[2]), Vec3::new(b[3], b[4], b[5])),
        (None, Some(b)) => b,
        (None, None) => {
            return Err(BakeError::NoTriangles {
                path: scene_path.to_owned(),
                degenerate: scene.degenerate_skipped,
            })
        }
    };
    if scene.triangles.is_empty() {
        report
            .warnings
            .push("the scene has no triangles: every probe sees only sky".into());
    }
    Ok(Loaded {
        scene,
        source_hash,
        bounds,
        winding_warning_at,
    })
}

/// The bricks stage: numbers the bricks and finishes their surfels, then encodes the factor
/// tables the probes carry into the asset's table ([`factors::encode_tables`]), freeing the
/// rows as it goes; fails when u8 factors cannot address the bricks.
fn bricks_and_tables(
    folder: bricks::BrickFolder,
    tables: factors::Rows,
    carried: factors::Carried,
    settings: &BakeSettings,
    cell_size: f32,
) -> Result<(bricks::Bricked, Factors), BakeError> {
    let (bricked, remap) = folder.finish();
    let u8_rows = settings.transfer_precision == TransferPrecision::U8;
    if u8_rows && bricked.bricks.len() > U8_MAX_BRICK as usize + 1 {
        return Err(BakeError::Setting {
            name: "precision",
            value: format!("u8 with {} bricks", bricked.bricks.len()),
            reason: "the 8-bit factor encoding addresses at most 16,777,216 bricks; use f16",
        });
    }
    let encoding = (settings.transfer_precision, 4.0 * cell_size);
    let factors = factors::encode_tables(tables, carried, &remap, &bricked.bricks, encoding)?;
    Ok((bricked, factors))
}

/// Per probe: whose factor table it carries (its own when valid, else its dilation source's,
/// else none) and how many factors that is; fails when they pass 2^32 in all.
fn carried_layout(
    valid: &[bool],
    sources: &[Option<usize>],
    tables: &factors::Rows,
) -> Result<(Vec<Option<usize>>, Vec<usize>), BakeError> {
    let from: Vec<Option<usize>> = valid
        .iter()
        .zip(sources)
        .enumerate()
        .map(|(p, (&valid, &source))| if valid { Some(p) } else { source })
        .collect();
    let lens: Vec<usize> = from
        .iter()
        .map(|f| f.map_or(0, |q| tables.len(q)))
        .collect();
    let factor_count: u64 = lens.iter().map(|&len| len as u64).sum();
    if factor_count > u64::from(u32::MAX) {
        return Err(BakeError::Setting {
            name: "spacing",
            value: format!("{factor_count} factors"),
            reason: "more than 2^32 factors (dilation copies tables into probes inside geometry): use fewer probes or rays, or --no-dilation",
        });
    }
    Ok((from, lens))
}

/// Per probe, in probe order: its record, and the sky mask and sky transfer it carries with
/// its factor table (`carried`). A dilated probe carries its source's table, sky and ray counts
/// (the record describes the data it carries); only its position is its own. An invalid probe
/// is never gathered and carries no table.
fn assemble_probes(
    traced: &[trace::ProbeRays],
    positions: &[(Vec3, bool)],
    carried: factors::Carried,
) -> Assembled {
    let mut probes = Vec::with_capacity(traced.len());
    let mask_words = traced.first().map_or(0, |r| r.sky_mask.len());
    let mut sky_mask = Vec::with_capacity(mask_words * positions.len());
    let mut sky_transfer = Vec::with_capacity(positions.len());
    let mut first_factor = 0u32;
    for (p, &(pos, moved)) in positions.iter().enumerate() {
        let (flags, from) = match carried.from[p] {
            Some(q) if q == p => (PROBE_VALID, p),
            Some(q) => (PROBE_VALID | PROBE_DILATED, q),
            None => (0, p),
        };
        let len = carried.lens[p] as u32;
        probes.push(Probe {
            position: pos.to_array(),
            flags: flags | if moved { PROBE_OFFSET } else { 0 },
            first_factor,
            factor_count: len,
            sky_rays: traced[from].sky_rays,
            backface_rays: traced[from].backface_rays,
        });
        // At most 2^32 - 1 factors in all (checked before the tables were encoded).
        first_factor += len;
        sky_mask.extend_from_slice(&traced[from].sky_mask);
        sky_transfer.push(traced[from].sky_transfer);
    }
    Assembled {
        probes,
        sky_mask,
        sky_transfer,
    }
}

/// The per-probe sections of the asset, before encoding.
struct Assembled {
    probes: Vec<Probe>,
    sky_mask: Vec<u32>,
    sky_transfer: Vec<[f32; prt_format::sh::SH_COUNT]>,
}
