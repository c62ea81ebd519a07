//! The bake's stages in order, from the scene file to the validated asset: load, BVH,
//! placement (sparse bakes), trace (merging as it goes, [`crate::stream`]), bricks (validity,
//! dilation, numbering the bricks and encoding the factor tables, [`bricks`]), surface terms,
//! assemble ([`assemble`]), refine ([`crate::refine`]), sky terms ([`crate::sky_terms`]). [`crate::bake`] runs them in its thread pool, then [`validate`]s
//! the asset; each stage's time goes into the report.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use prt_format::surface::SurfaceTerms;
use prt_format::{directions, Asset};
use prt_scene::Scene;

mod assemble;
mod bricks;

use assemble::Assembled;
use bricks::Bricks;

use crate::accel::bvh;
use crate::merge::{coarse, fold, sides};
use crate::surface_terms;
use crate::tables::encode;
use crate::{
    diagnostics, offset, placement, probes, refine, stream, trace, BakeError, BakeReport,
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
    let shifted = (spacing, settings.grid_shift);
    let grid = probes::grid((min, max), shifted, settings.max_probes)?;
    let built = bvh_stage(&loaded, ploc_memory, &grid, settings, &mut report)?;
    lap(&mut report, "bvh", None);

    let plan = placement_stage(&grid, &loaded.scene.triangles, settings, &mut report);
    // Per grid point, whether it is traced.
    let placed = plan.as_ref().map_or_else(
        || vec![true; grid.probe_count() as usize],
        placement::Plan::traced,
    );
    progress.start("trace", grid.probe_count());
    let cell_size = settings.cell_size_for(spacing);
    let stage = (&grid, &placed[..]);
    let traced = trace_stage(&loaded, &built.bvh, stage, settings, cell_size, progress)?;
    report.rows_spilled = traced.rows.spilled_bytes();
    lap(&mut report, "trace", Some("bricks"));

    let plan_cells = (&grid, plan.as_ref(), &placed[..]);
    let bricks = bricks::bricks_stage(
        traced,
        plan_cells,
        (settings, cell_size),
        (&loaded, &built),
        &mut report,
    )?;
    let Bricks {
        positions,
        rays: traced,
        from,
        lens,
        depth: probe_depth,
        mut bricked,
        coarse,
        factors,
    } = bricks;
    let probe_positions: Vec<Vec3> = positions.iter().map(|&(p, _)| p).collect();
    let carried = encode::Carried {
        from: &from,
        lens: &lens,
        origins: &probe_positions,
    };
    lap(&mut report, "bricks", Some("surface"));

    let probes = (&grid, &probe_positions[..]);
    let geometry = (&built.bvh, &loaded.scene.triangles[..]);
    let merging = (
        settings.surface_terms.then_some(cell_size),
        settings.merge_normal_cos,
    );
    let surface = surface_stage(probes, geometry, merging, &mut bricked, &mut report);
    lap(&mut report, "surface", Some("assemble"));

    let Assembled {
        probes: mut probes_out,
        sky_mask,
        sky_transfer,
    } = assemble::assemble_probes(&traced, &positions, carried);
    if let (Some(plan), Some(sparse)) = (&plan, &mut report.placed) {
        sparse.filled = placement::mark_filled(&grid, &mut probes_out, plan);
    }
    let header = assemble::header(scene_path, &loaded, grid, settings, cell_size, &traced);
    // The surfels as the asset keeps them, so that it equals itself read back.
    let precision = header.settings.surfel_precision;
    for s in &mut bricked.surfels {
        *s = precision.quantize(s, &bricked.bricks);
    }
    let mut asset = Asset {
        header,
        probes: probes_out,
        sky_mask,
        sky_transfer,
        probe_depth,
        factors,
        bricks: bricked.bricks,
        coarse,
        surfels: bricked.surfels,
        // Set once the refine stage has traced through the BVH it belongs to.
        geometry: prt_format::Geometry::default(),
        lights: loaded.scene.lights,
        surface,
    };
    lap(&mut report, "assemble", Some("refine"));
    refine_stage(&mut asset, settings, &built.bvh, &mut report);
    lap(&mut report, "refine", Some("sky"));
    asset.surface.sky = crate::sky_terms::sky_terms(&asset, &built.bvh);
    asset.geometry = built.bvh.geometry;
    report.warnings.extend(diagnostics::gap_warning(&asset));
    lap(&mut report, "sky", None);
    Ok((asset, report))
}

/// The placement stage of a sparse bake (`None` for a uniform one): which grid points of
/// `grid` the `triangles` need traced ([`placement::plan`]), summed up in the report.
fn placement_stage(
    grid: &prt_format::Grid,
    triangles: &[[Vec3; 3]],
    settings: &BakeSettings,
    report: &mut BakeReport,
) -> Option<placement::Plan> {
    let plan = settings.sparse.then(|| placement::plan(grid, triangles))?;
    let (placed, warning) = placement::summary(&plan);
    report.placed = Some(placed);
    report.warnings.extend(warning);
    Some(plan)
}

/// The refine stage: drops the probes of `asset` that level 1 predicts ([`refine::prune`]: under
/// the threshold on sparse bakes, and past the budget), tracing through `bvh`, and reports it.
fn refine_stage(
    asset: &mut Asset,
    settings: &BakeSettings,
    bvh: &bvh::SceneBvh,
    report: &mut BakeReport,
) {
    let threshold = if settings.sparse {
        settings.prune_error
    } else {
        0.0
    };
    report.refined = refine::prune(asset, (threshold, settings.probe_budget), bvh);
    report
        .warnings
        .extend(report.refined.as_ref().and_then(refine::budget_warning));
}

/// The surface stage: the surface terms of the `bricked` surfels (written into them) against
/// the probes of `grid` at `positions`, traced through `bvh` over `triangles`, with surfel
/// cells of `cell_size` (`None`: no terms, [`surface_terms::surface_terms`]) merged to the
/// normal agreement `merge_normal_cos`; warns when the
/// lookup's tables cannot hold them or when most surfels see none of their probes.
fn surface_stage(
    (grid, positions): (&prt_format::Grid, &[Vec3]),
    (bvh, triangles): (&bvh::SceneBvh, &[[Vec3; 3]]),
    (cell_size, merge_normal_cos): (Option<f32>, f32),
    bricked: &mut fold::Bricked,
    report: &mut BakeReport,
) -> SurfaceTerms {
    let inputs = surface_terms::Inputs {
        bricks: &bricked.bricks,
        grid,
        probes: positions,
        bvh,
        triangles,
        cell_size: cell_size.unwrap_or(0.0),
        merge_normal_cos,
    };
    let surface = surface_terms::surface_terms(&inputs, &mut bricked.surfels);
    if cell_size.is_some_and(|c| c > 0.0) && surface.is_empty() && !bricked.bricks.is_empty() {
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
    surface
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

/// A bake's ray lattice: its directions, their weight, the order they are traced in, and where
/// each ray's bit sits in a sky mask (`prt_format::sky_mask::sky_positions`).
struct Lattice {
    dirs: Vec<Vec3>,
    weight: f32,
    order: Vec<u32>,
    sky_positions: Vec<u32>,
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
            sky_positions: prt_format::sky_mask::sky_positions(n),
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
            sky_positions: &self.sky_positions,
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
    /// Per grid point, whether the placement keeps it ([`placement`]).
    placed: &'a [bool],
    /// The grid points, and how many along each axis.
    positions: &'a [Vec3],
    counts: [u32; 3],
    /// The grid's bounds, whose centre the outer probes move towards off a surface.
    bounds: (Vec3, Vec3),
    spacing: f32,
    /// The surfel cells' lattice (corner, edge), whose walls [`sides::mark_across`] looks
    /// for; edge 0: none (unmerged, or no surface terms).
    cells: (Vec3, f32),
}

impl ProbeTrace<'_> {
    /// Probe `index`: moved off a surface its grid point lies on ([`offset::surface_offset`],
    /// towards the grid's inside), traced, and moved out of geometry it turns out to be inside
    /// ([`offset::virtual_offset`]), as the settings ask; its position, rays (hits marked
    /// across a wall in their cell, [`sides`]), and whether it left its grid point.
    fn trace(&self, index: usize) -> (Vec3, trace::ProbeRays, bool) {
        let (p, mut r, moved) = self.trace_offset(index);
        let (anchor, cell) = self.cells;
        let scene = (self.tracer.bvh, &self.tracer.scene.triangles[..]);
        sides::mark_across(&mut r.hits, scene, anchor, cell);
        (p, r, moved)
    }

    /// [`Self::trace`] before its hits are marked: the probe moved off surfaces and out of
    /// geometry, and traced.
    fn trace_offset(&self, index: usize) -> (Vec3, trace::ProbeRays, bool) {
        let settings = self.settings;
        let grid_p = self.positions[index];
        if !self.placed[index] {
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

/// The trace stage: every probe of `grid` the placement keeps (`placed`) traced
/// through `bvh` over the `loaded` scene and its hits folded into bricks of cells of
/// `cell_size` as they come ([`stream::trace_and_fold`]).
fn trace_stage(
    loaded: &Loaded,
    bvh: &bvh::SceneBvh,
    (grid, placed): (&prt_format::Grid, &[bool]),
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
        // Half a cell off the origin: see `fold::BrickFolder::new`. Walls in cells matter to
        // the surface lookup only: without its terms no hit is tested.
        cells: (
            Vec3::splat(-0.5 * cell_size),
            if settings.surface_terms {
                cell_size
            } else {
                0.0
            },
        ),
    };
    let anchor = probe_trace.cells.0;
    let folder = fold::BrickFolder::new(cell_size, settings.merge_normal_cos, anchor);
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
