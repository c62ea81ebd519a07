//! The bake's stages in order, from the scene file to the validated asset: load, BVH, trace
//! (merging as it goes, [`crate::stream`]), bricks (numbering them and encoding the factor
//! tables), assemble. [`crate::bake`] runs them in its thread pool, then [`validate`]s the
//! asset; each stage's time goes into the report.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use prt_format::coarse::CoarseBricks;
use prt_format::{
    directions, Asset, BakeSettingsRecord, BakeStats, Factors, Header, Probe, TransferPrecision,
    DEPTH_WORDS, NO_SLOT, PROBE_DILATED, PROBE_OFFSET, PROBE_VALID, U8_MAX_BRICK,
};

use prt_scene::Scene;

use crate::accel::bvh;
use crate::merge::{coarse, fold, snap};
use crate::surface_terms;
use crate::tables::{encode, factors};
use crate::{
    diagnostics, dilate, offset, placement, probes, stream, trace, BakeError, BakeReport,
    BakeSettings, Progress,
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
    let (loaded, ploc_memory) = load(scene_path, settings, &mut report)?;
    lap(&mut report, "load", Some("bvh"));

    let (min, max) = loaded.bounds;
    let spacing = settings
        .spacing
        .unwrap_or_else(|| probes::default_spacing(min, max));
    // The grid first: a spacing far too small for the scene is refused before any other work.
    let grid = probes::grid(min, max, spacing, settings.max_probes)?;
    let built = bvh_stage(&loaded, ploc_memory, &grid, settings, &mut report)?;
    lap(&mut report, "bvh", None);

    let plan = settings
        .sparse
        .then(|| placement::plan(&grid, &loaded.scene.triangles));
    if let Some(plan) = &plan {
        let (placed, warning) = placement::summary(plan);
        report.placed = Some(placed);
        report.warnings.extend(warning);
    }
    let placed = plan.as_ref().map(placement::Plan::traced);
    progress.start("trace", grid.probe_count());
    let cell_size = settings.cell_size_for(spacing);
    let stage = (&grid, placed.as_deref());
    let traced = trace_stage(&loaded, &built.bvh, stage, settings, cell_size, progress)?;
    report.rows_spilled = traced.rows.spilled_bytes();
    lap(&mut report, "trace", Some("bricks"));

    let scene = &loaded.scene;
    let valid = validity(&traced.rays, settings, &built, scene, &mut report);
    let placed: Vec<bool> = traced.rays.iter().map(|r| r.placed).collect();
    // Sparse: holes are filled only in cells a surface passes through.
    let cells = plan
        .as_ref()
        .filter(|_| settings.dilate)
        .map(placement::Plan::surface_cells);
    let layout = (&valid[..], &placed[..], cells);
    let (from, lens) = carried_layout(&grid, layout, settings, &traced.rows)?;
    let carried = encode::Carried {
        from: &from,
        lens: &lens,
    };
    let stream::Traced {
        positions,
        rays: traced,
        rows: tables,
        depth: probe_depth,
        folder,
        far_levels,
    } = traced;
    let probe_depth = with_data(probe_depth, &traced, &from);
    let surfaces = snap::Surfaces {
        bvh: &built.bvh,
        triangles: &loaded.scene.triangles,
        cell_size,
        double_sided: settings.double_sided,
    };
    let (mut bricked, coarse, factors) = bricks_and_tables(
        (folder, tables),
        carried,
        settings,
        (cell_size, &far_levels),
        &surfaces,
    )?;
    lap(&mut report, "bricks", Some("surface"));

    let probe_positions: Vec<Vec3> = positions.iter().map(|&(p, _)| p).collect();
    let inputs = surface_terms::Inputs {
        bricks: &bricked.bricks,
        grid: &grid,
        probes: &probe_positions,
        bvh: &built.bvh,
        triangles: &scene.triangles,
        // No cells: no terms (`surface_terms::surface_terms`).
        cell_size: if settings.surface_terms {
            cell_size
        } else {
            0.0
        },
    };
    let surface = surface_terms::surface_terms(&inputs, &mut bricked.surfels);
    if settings.surface_terms && cell_size > 0.0 && surface.is_empty() && !bricked.bricks.is_empty()
    {
        report.warnings.push(format!(
            "no surface terms: {} bricks and their near groups overflow the lookup's tables \
             (at most {} bricks, {} groups); surfaces are sampled from the probe volume alone",
            bricked.bricks.len(),
            prt_format::surface::MAX_TABLE_BRICKS,
            prt_format::surface::MAX_GROUPS
        ));
    }
    if let Some(w) = diagnostics::blind_warning(&surface) {
        report.warnings.push(w);
    }
    lap(&mut report, "surface", Some("assemble"));

    let Assembled {
        probes: mut probes_out,
        sky_mask,
        sky_transfer,
    } = assemble_probes(&traced, &positions, carried);
    if let (Some(plan), Some(sparse)) = (&plan, &mut report.placed) {
        sparse.filled = placement::mark_filled(&grid, &mut probes_out, plan);
    }
    let header = header(scene_path, &loaded, grid, settings, cell_size, &traced);
    let asset = Asset {
        header,
        probes: probes_out,
        sky_mask,
        sky_transfer,
        probe_depth,
        factors,
        bricks: bricked.bricks,
        coarse,
        surfels: bricked.surfels,
        geometry: built.bvh.geometry,
        lights: loaded.scene.lights,
        surface,
    };
    report.warnings.extend(diagnostics::gap_warning(&asset));
    lap(&mut report, "assemble", None);
    Ok((asset, report))
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

/// Whether a probe was traced and its rays say it lies outside geometry ([`inside`]).
fn valid(settings: &BakeSettings, r: &trace::ProbeRays) -> bool {
    r.placed && !inside(settings, r)
}

/// Whether a probe's rays say it lies inside geometry: too many of them hit back faces, or it
/// sees no sky and too many of its hits face away from it (docs/conventions.md, probe validity).
fn inside(settings: &BakeSettings, r: &trace::ProbeRays) -> bool {
    let n = settings.rays as f32;
    r.backface_rays as f32 > settings.invalid_backface_fraction * n
        || (r.sky_rays == 0 && r.facing_away_rays as f32 > settings.inside_facing_away_fraction * n)
}

/// What the BVH stage gives the bake.
struct Built {
    bvh: bvh::SceneBvh,
    /// The winding check, when it ran beside the BVH (single-sided bakes only).
    winding: Option<diagnostics::Winding>,
    /// Whether the report warns of inconsistent winding (the inside warning then hints at it).
    winding_hint: bool,
}

/// The BVH stage: both BVHs of the `loaded` scene (in `memory` made ready beside the load),
/// built for the rays of `grid`'s probes, with the winding check of a single-sided bake beside
/// them (its warning goes into the report where `loaded` says).
fn bvh_stage(
    loaded: &Loaded,
    memory: Option<bvh::PlocMemory>,
    grid: &prt_format::Grid,
    settings: &BakeSettings,
    report: &mut BakeReport,
) -> Result<Built, BakeError> {
    let scene = &loaded.scene;
    let rays = grid.probe_count().saturating_mul(u64::from(settings.rays));
    let scale = bvh::trace_scale(grid.spacing);
    // Baked double-sided, the winding changes no hit's shading and needs no hint: it is then
    // counted only for the rare warning that names it (most probes inside geometry), not on
    // every bake.
    let (bvh, winding) =
        bvh::SceneBvh::build_checked(&scene.triangles, scale, rays, memory, || {
            (!settings.double_sided).then(|| diagnostics::winding(&scene.triangles))
        })?;
    let winding_hint = match &winding {
        Some(w) if w.inconsistent_fraction() > diagnostics::WINDING_WARNING => {
            let warning = diagnostics::winding_warning(w);
            report.warnings.insert(loaded.winding_warning_at, warning);
            true
        }
        _ => false,
    };
    Ok(Built {
        bvh,
        winding,
        winding_hint,
    })
}

/// A bake's ray lattice: its directions, their weight, and the order they are traced in.
struct Lattice {
    dirs: Vec<Vec3>,
    weight: f32,
    order: Vec<u32>,
}

impl Lattice {
    /// The `n`-direction spherical Fibonacci lattice of docs/conventions.md section 2.
    fn of(n: u32) -> Lattice {
        let dirs: Vec<Vec3> = directions::fibonacci_directions(n)
            .into_iter()
            .map(Vec3::from)
            .collect();
        Lattice {
            weight: directions::direction_weight(n),
            order: trace::coherent_order(&dirs),
            dirs,
        }
    }

    /// The tracer of this lattice's rays through `bvh` over `scene`.
    fn tracer<'a>(
        &'a self,
        scene: &'a Scene,
        bvh: &'a bvh::SceneBvh,
        double_sided: bool,
    ) -> trace::Tracer<'a> {
        trace::Tracer {
            scene,
            bvh,
            directions: &self.dirs,
            basis: self
                .dirs
                .iter()
                .map(|d| prt_format::sh::basis(d.to_array()))
                .collect(),
            order: &self.order,
            weight: self.weight,
            double_sided,
            srgb: prt_scene::texture::srgb_to_linear_table(),
            shading: trace::triangle_shading(scene),
        }
    }
}

/// How each probe of the grid is traced ([`stream::TraceProbe`]).
struct ProbeTrace<'a> {
    tracer: &'a trace::Tracer<'a>,
    settings: &'a BakeSettings,
    /// Per grid point, whether the placement keeps it ([`placement`]); `None`: every one.
    placed: Option<&'a [bool]>,
    /// The grid points, and how many along each axis.
    positions: &'a [Vec3],
    counts: [u32; 3],
    /// The grid's bounds, whose centre the outer probes move towards off a surface.
    bounds: (Vec3, Vec3),
    spacing: f32,
}

impl ProbeTrace<'_> {
    /// Probe `index`: moved off a surface its grid point lies on ([`offset::surface_offset`],
    /// towards the grid's inside), traced, and moved out of geometry it turns out to be inside
    /// ([`offset::virtual_offset`]), as the settings ask; its position, rays, and whether it
    /// left its grid point.
    fn trace(&self, index: usize) -> (Vec3, trace::ProbeRays, bool) {
        let settings = self.settings;
        let grid_p = self.positions[index];
        if self.placed.is_some_and(|placed| !placed[index]) {
            return (grid_p, trace::ProbeRays::not_placed(), false);
        }
        let [nx, ny, nz] = self.counts;
        let (i, j, k) = (
            index as u32 % nx,
            (index as u32 / nx) % ny,
            index as u32 / (nx * ny),
        );
        let ijk = [(i, nx), (j, ny), (k, nz)];
        let outer = ijk.iter().any(|&(c, n)| n > 1 && (c == 0 || c == n - 1));
        let inwards = Vec3::from_array(ijk.map(|(c, n)| if 2 * c > n - 1 { -1.0 } else { 1.0 }));
        let p = if settings.surface_offset {
            let (min, max) = self.bounds;
            let centre = outer.then_some((min + max) * 0.5);
            offset::surface_offset(self.tracer, grid_p, self.spacing, inwards, centre)
        } else {
            grid_p
        };
        let r = self.tracer.trace_probe(p);
        let is_inside = |r: &trace::ProbeRays| inside(settings, r);
        if settings.virtual_offset && is_inside(&r) {
            if let Some((moved, again)) =
                offset::virtual_offset(self.tracer, p, &r, self.spacing, &is_inside)
            {
                return (moved, again, true);
            }
        }
        (p, r, p != grid_p)
    }
}

/// The trace stage: every probe of `grid` the placement keeps (all of them with `None`) traced
/// through `bvh` over the `loaded` scene and its hits folded into bricks of cells of
/// `cell_size` as they come ([`stream::trace_and_fold`]).
fn trace_stage(
    loaded: &Loaded,
    bvh: &bvh::SceneBvh,
    (grid, placed): (&prt_format::Grid, Option<&[bool]>),
    settings: &BakeSettings,
    cell_size: f32,
    progress: &dyn Progress,
) -> Result<stream::Traced, BakeError> {
    let lattice = Lattice::of(settings.rays);
    let tracer = lattice.tracer(&loaded.scene, bvh, settings.double_sided);
    let probe_trace = ProbeTrace {
        tracer: &tracer,
        settings,
        placed,
        positions: &probes::positions(grid),
        counts: grid.counts,
        bounds: loaded.bounds,
        spacing: grid.spacing,
    };
    // Half a cell off the origin: see `fold::BrickFolder::new`.
    let folder = fold::BrickFolder::new(
        cell_size,
        settings.merge_normal_cos,
        Vec3::splat(-0.5 * cell_size),
    );
    let far = coarse::FarField::of(settings.far_ratio, folder.lattice());
    stream::trace_and_fold(
        probe_trace.positions.len(),
        &|index| probe_trace.trace(index),
        &tracer,
        folder,
        &stream::Keep {
            spacing: grid.spacing,
            precision: settings.transfer_precision,
            row_memory: settings.row_memory,
            rows_of: &|r| valid(settings, r),
            far,
        },
        progress,
    )
}

/// The asset's header: what was baked (`scene_path`, as `loaded`) on which `grid`, how
/// (`settings`, cells of `cell_size`), and the counts of the `traced` rays.
fn header(
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
    scene: Scene,
    /// xxh3 of the scene file's bytes.
    source_hash: u64,
    /// The grid's bounds: the settings' or the scene's.
    bounds: (Vec3, Vec3),
    /// Where in the report's warnings the winding warning goes (it is known only after the BVH
    /// stage, beside which the check runs): after the scene's own.
    winding_warning_at: usize,
}

/// The load stage: checks the scene, then reads it while the pool's idle threads make ready the
/// memory of the BVH build for the triangles it declares ([`bvh::PlocMemory`]; `None` for a
/// scene that declares none); warns about what it skipped and picks the bounds; fails on an
/// unreadable or refused file or a scene with neither triangles nor bounds.
fn load(
    scene_path: &Path,
    settings: &BakeSettings,
    report: &mut BakeReport,
) -> Result<(Loaded, Option<bvh::PlocMemory>), BakeError> {
    let source_bytes =
        prt_format::read_regular_file(scene_path).map_err(|error| BakeError::Io {
            path: scene_path.to_owned(),
            error,
        })?;
    let source_hash = xxhash_rust::xxh3::xxh3_64(&source_bytes);
    let checked = prt_scene::check(scene_path, &source_bytes, &settings.allowed)?;
    drop(source_bytes);
    let triangles = checked.declared_triangles();
    let (scene, memory) = rayon::join(
        || prt_scene::read(checked),
        || (triangles > 0).then(|| bvh::PlocMemory::faulted(triangles)),
    );
    let scene = scene?;
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
    let loaded = Loaded {
        scene,
        source_hash,
        bounds,
        winding_warning_at,
    };
    Ok((loaded, memory))
}

/// The bricks stage: numbers the bricks and finishes their surfels (those behind their
/// surface put back on it, [`snap`]), then encodes the factor tables the probes carry into the
/// asset's table ([`encode::encode_tables`]), freeing the rows as it goes; fails when u8
/// factors cannot address the bricks.
fn bricks_and_tables(
    (folder, tables): (fold::BrickFolder, factors::Rows),
    carried: encode::Carried,
    settings: &BakeSettings,
    (cell_size, far_levels): (f32, &[u8]),
    surfaces: &snap::Surfaces,
) -> Result<(fold::Bricked, CoarseBricks, Factors), BakeError> {
    let (bricked, remap) = folder.finish_placed(&|s, cell| surfaces.place(s, cell));
    let mut used = vec![0u8; bricked.bricks.len()];
    for (&b, &l) in remap.iter().zip(far_levels) {
        used[b as usize] |= l;
    }
    let (coarse, placement) = coarse::build(&bricked.keys, &bricked.fits, &used);
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
    let numbering = (&remap[..], &bricked.bricks[..], &placement);
    let factors = encode::encode_tables(tables, carried, numbering, encoding)?;
    Ok((bricked, coarse, factors))
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

/// Per probe of `grid`: whose factor table it carries (its own when valid, else, placed, its
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
/// that is not dilated, like a grid point the placement left out, carries nothing: no table,
/// flags or slot in the sky and visibility sections ([`prt_format::Probe::slot`]).
fn assemble_probes(
    traced: &[trace::ProbeRays],
    positions: &[(Vec3, bool)],
    carried: encode::Carried,
) -> Assembled {
    let mut probes = Vec::with_capacity(traced.len());
    let placed = carried.from.iter().filter(|f| f.is_some()).count();
    let mask_words = traced
        .iter()
        .find(|r| r.placed)
        .map_or(0, |r| r.sky_mask.len());
    let mut sky_mask = Vec::with_capacity(mask_words * placed);
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
        let len = carried.lens[p] as u32;
        probes.push(Probe {
            position: pos.to_array(),
            flags: flags | if moved { PROBE_OFFSET } else { 0 },
            first_factor,
            factor_count: len,
            sky_rays: traced[from].sky_rays,
            slot,
        });
        // At most 2^32 - 1 factors in all (checked before the tables were encoded), and as
        // many placed probes as grid points.
        first_factor += len;
        slot += 1;
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
