//! # prt-bake: from a glTF scene to a PRT GI asset
//!
//! The pipeline, one module per stage:
//!
//! 1. [`scene`]: load the glTF (transforms, primitives, materials, textures, lights).
//! 2. [`bvh`]: one PLOC build gives the 8-wide BVH the probes' ray packets are traced through
//!    ([`bvh8`]) and the BVH2 the asset carries.
//! 3. [`probes`]: a regular grid over the scene bounds or `bounds`.
//! 4. [`trace`]: each probe shoots the N directions of the spherical Fibonacci lattice; hits
//!    become surfel samples (position, normal, albedo, emission, back-face flag), misses set bits
//!    of the probe's sky mask. Probes whose rays mostly hit back faces are inside geometry and
//!    marked invalid.
//! 5. [`bricks`]: hits are folded into normal-keyed bricks and merged into surfels as they
//!    arrive, block by block of probes ([`stream`]), never all held at once.
//! 6. [`factors`]: per probe, (brick, ray count, SH9 transfer) rows from its own rays.
//! 7. The asset is assembled, validated and written atomically (`prt_format::io`).
//!
//! Every stage orders its output by probe, ray, key or index, never by thread timing: the same
//! scene and settings give byte-identical assets whatever the thread count.

// SH and colour maths index several parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

pub mod bricks;
pub mod bvh;
pub mod bvh8;
pub mod depth;
pub mod diagnostics;
pub mod dilate;
pub mod error;
pub mod factors;
pub mod gltf_check;
pub mod offset;
pub mod probes;
pub mod scene;
pub mod stream;
pub mod texture;
pub mod trace;

use std::path::Path;
use std::time::{Duration, Instant};

use glam::Vec3;
use prt_format::{
    directions, Asset, BakeSettingsRecord, BakeStats, Factors, Header, Probe, TransferPrecision,
    PROBE_DILATED, PROBE_OFFSET, PROBE_VALID, U8_MAX_BRICK,
};
use rayon::prelude::*;

pub use error::BakeError;

/// Fraction of shared edges with inconsistent winding above which the bake warns.
const WINDING_WARNING: f64 = 0.01;

/// Bake settings. [`BakeSettings::default`] is the production preset; see the other presets for
/// the trade-offs.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeSettings {
    /// Rays per probe (size of the Fibonacci lattice). The main accuracy lever: error falls
    /// roughly as N^-0.75 on scenes with sharp shadows, at a bake cost linear in N and no runtime
    /// cost once rays are folded into factors.
    pub rays: u32,
    /// Probe spacing in metres; `None` picks about 1,000 probes over the bounds.
    pub spacing: Option<f32>,
    /// Bake bounds `[min x, y, z, max x, y, z]`; `None` uses the scene's bounds.
    pub bounds: Option<[f32; 6]>,
    /// Refuse grids with more probes than this.
    pub max_probes: u64,
    /// Surfel cell size in metres (a brick is 4x4x4 cells); `None` is
    /// `spacing / cells_per_spacing`; 0 switches merging off (exact, one brick per ray hit,
    /// larger assets and more runtime work).
    pub cell_size: Option<f32>,
    /// Surfel cells per probe spacing when `cell_size` is `None`. Larger values mean smaller
    /// bricks: less merging error at the cost of more factors per probe (runtime gather work and
    /// asset size). 12 keeps the Cornell reference within 25% of the unmerged error.
    pub cells_per_spacing: f32,
    /// Hits merge into one surfel only when the cosine between their normals is at least this.
    pub merge_normal_cos: f32,
    /// Treat every material as double-sided (for files with inconsistent winding).
    pub double_sided: bool,
    /// A probe is invalid (inside geometry) when more than this fraction of its rays hit back
    /// faces of single-sided surfaces.
    pub invalid_backface_fraction: f32,
    /// A probe that sees no sky is inside geometry when more than this fraction of its rays hit
    /// the back side of their triangle's winding, whatever the material's sidedness: inside a
    /// closed solid with double-sided materials (thick walls) every hit does, while in a room
    /// with inconsistent winding (Sponza) they stay well below.
    pub inside_facing_away_fraction: f32,
    /// Give probes inside geometry their nearest valid neighbour's data ([`dilate`]).
    pub dilate: bool,
    /// Move probes that lie on a surface (within 2% of a spacing, as the grid's outer layers do
    /// on a room's walls) 5% of a spacing off it before tracing: a probe on a wall sees both of
    /// its sides and mixes the rooms it separates.
    pub surface_offset: bool,
    /// Storage precision of factor transfers.
    pub transfer_precision: TransferPrecision,
    /// Move probes that are inside geometry out of it (virtual offset): through the nearest back
    /// face their rays hit, if it is within half a spacing and the probe is valid there.
    pub virtual_offset: bool,
    /// Worker threads; `None` uses all cores.
    pub threads: Option<usize>,
}

impl Default for BakeSettings {
    fn default() -> Self {
        BakeSettings {
            rays: 512,
            spacing: None,
            bounds: None,
            max_probes: 1 << 20,
            cell_size: None,
            cells_per_spacing: 12.0,
            merge_normal_cos: 0.9,
            double_sided: false,
            invalid_backface_fraction: 0.1,
            inside_facing_away_fraction: 0.75,
            dilate: true,
            surface_offset: true,
            transfer_precision: TransferPrecision::U8,
            virtual_offset: false,
            threads: None,
        }
    }
}

impl BakeSettings {
    /// Higher accuracy: 8x the rays and half-size bricks. On the Cornell reference it brings the
    /// mean irradiance error from about 3% to 0.5% (p95 1.2%), at about 5x the factors per probe
    /// (runtime gather work and asset size) and 8x the trace time.
    pub fn high_quality() -> Self {
        BakeSettings {
            rays: 4096,
            cells_per_spacing: 24.0,
            ..Self::default()
        }
    }

    /// The exact one-bounce estimate for accuracy tests: no merging, f32 transfers. Largest
    /// assets and runtime work.
    pub fn exact() -> Self {
        BakeSettings {
            cell_size: Some(0.0),
            transfer_precision: TransferPrecision::F32,
            ..Self::default()
        }
    }

    fn check(&self) -> Result<(), BakeError> {
        let bad = |name, value: String, reason| {
            Err(BakeError::Setting {
                name,
                value,
                reason,
            })
        };
        if self.rays == 0 || self.rays > prt_format::validate::MAX_RAYS {
            return bad("rays", self.rays.to_string(), "must be in 1..=1048576");
        }
        if let Some(s) = self.spacing {
            if !(s.is_finite() && s > 0.0) {
                return bad(
                    "spacing",
                    s.to_string(),
                    "must be a positive number of metres",
                );
            }
        }
        if let Some(b) = self.bounds {
            if b.iter().any(|v| !v.is_finite()) {
                return bad("bounds", format!("{b:?}"), "must be finite");
            }
            if (0..3).any(|a| b[a] > b[a + 3]) {
                return bad(
                    "bounds",
                    format!("{b:?}"),
                    "min is above max (inverted bounds)",
                );
            }
        }
        if let Some(c) = self.cell_size {
            if !(c.is_finite() && c >= 0.0) {
                return bad("cell_size", c.to_string(), "must be >= 0 (0: no merging)");
            }
        }
        if !(self.cells_per_spacing.is_finite() && self.cells_per_spacing > 0.0) {
            return bad(
                "cells_per_spacing",
                self.cells_per_spacing.to_string(),
                "must be positive",
            );
        }
        if !(-1.0..=1.0).contains(&self.merge_normal_cos) {
            return bad(
                "merge_normal_cos",
                self.merge_normal_cos.to_string(),
                "must be in [-1, 1]",
            );
        }
        if !(0.0..=1.0).contains(&self.invalid_backface_fraction) {
            return bad(
                "invalid_backface_fraction",
                self.invalid_backface_fraction.to_string(),
                "must be in [0, 1]",
            );
        }
        if !(0.0..=1.0).contains(&self.inside_facing_away_fraction) {
            return bad(
                "inside_facing_away_fraction",
                self.inside_facing_away_fraction.to_string(),
                "must be in [0, 1]",
            );
        }
        if let Some(t) = self.threads.filter(|&t| t == 0 || t > MAX_THREADS) {
            return bad(
                "threads",
                t.to_string(),
                "must be in 1..=1024 (more threads than cores only add overhead)",
            );
        }
        Ok(())
    }
}

/// Reports progress of long stages (the CLI draws a bar; libraries pass [`NoProgress`]).
pub trait Progress: Sync {
    /// A stage with `total` units of work begins (0: unknown, show that it is running).
    fn start(&self, stage: &str, total: u64);
    /// `n` more units are done.
    fn advance(&self, n: u64);
    /// The stage is over.
    fn finish(&self);
}

/// Reports nothing.
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
    fn finish(&self) {}
}

/// What a bake did, for the summary.
#[derive(Clone, Debug, Default)]
pub struct BakeReport {
    /// Wall time of each stage, in order.
    pub timings: Vec<(&'static str, Duration)>,
    pub warnings: Vec<String>,
    /// Bytes of the written file (0 before writing).
    pub file_bytes: u64,
}

/// Most worker threads a bake starts.
pub const MAX_THREADS: usize = 1024;

/// Runs `f`, turning a panic inside a dependency (the gltf crate's readers, obvhs) into its
/// message, for an error that names the input instead of a crash. The default report of the
/// panic is suppressed meanwhile; the hook is process-wide, so callers swap it one at a time
/// and one never restores another's silent hook for good.
pub(crate) fn catch_quietly<T>(
    f: impl FnOnce() -> T + std::panic::UnwindSafe,
) -> Result<T, String> {
    static HOOK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = HOOK.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(f);
    std::panic::set_hook(previous);
    result.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into())
    })
}

/// Bakes `scene_path` into an asset (not written).
pub fn bake(
    scene_path: &Path,
    settings: &BakeSettings,
    progress: &dyn Progress,
) -> Result<(Asset, BakeReport), BakeError> {
    settings.check()?;
    match settings.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| BakeError::ThreadPool(e.to_string()))?
            .install(|| bake_in_pool(scene_path, settings, progress)),
        None => bake_in_pool(scene_path, settings, progress),
    }
}

/// Bakes and writes the asset atomically to `out`; no partial file is left on failure.
pub fn bake_to_file(
    scene_path: &Path,
    out: &Path,
    settings: &BakeSettings,
    progress: &dyn Progress,
) -> Result<(Asset, BakeReport), BakeError> {
    // Refuse a bad output before the work, not after it.
    if prt_format::io::same_file(scene_path, out) {
        return Err(BakeError::Setting {
            name: "output",
            value: out.display().to_string(),
            reason: "is the input scene; refusing to overwrite it",
        });
    }
    prt_format::io::check_replaceable(out).map_err(|error| BakeError::Format {
        path: out.to_owned(),
        error,
    })?;
    let (asset, mut report) = bake(scene_path, settings, progress)?;
    let t = Instant::now();
    report.file_bytes =
        prt_format::write_asset_atomic(out, &asset).map_err(|error| BakeError::Format {
            path: out.to_owned(),
            error,
        })?;
    report.timings.push(("write", t.elapsed()));
    Ok((asset, report))
}

fn bake_in_pool(
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

    let source_bytes =
        prt_format::read_regular_file(scene_path).map_err(|error| BakeError::Io {
            path: scene_path.to_owned(),
            error,
        })?;
    let source_hash = xxhash_rust::xxh3::xxh3_64(&source_bytes);
    let scene = scene::load_bytes(scene_path, &source_bytes)?;
    drop(source_bytes);
    report.warnings.extend(scene.warnings.iter().cloned());
    // The winding check runs beside the BVH build; its warning goes here, after the scene's.
    let winding_warning_at = report.warnings.len();
    if scene.degenerate_skipped > 0 {
        report.warnings.push(format!(
            "{} degenerate (zero-area) triangles skipped",
            scene.degenerate_skipped
        ));
    }
    let (min, max) = match (settings.bounds, scene.bounds()) {
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
    lap(&mut report, "load", Some("bvh"));

    let spacing = settings
        .spacing
        .unwrap_or_else(|| probes::default_spacing(min, max));
    // The grid first: a spacing far too small for the scene is refused before any other work.
    let grid = probes::grid(min, max, spacing, settings.max_probes)?;
    let (winding, bvh) = rayon::join(
        || diagnostics::winding(&scene.triangles),
        || bvh::SceneBvh::build_checked(&scene.triangles, bvh::trace_scale(spacing)),
    );
    let bvh = bvh?;
    let winding_hint = winding.inconsistent_fraction() > WINDING_WARNING && !settings.double_sided;
    if winding_hint {
        let warning = diagnostics::winding_warning(&winding);
        report.warnings.insert(winding_warning_at, warning);
    }
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
        spacing,
        settings.transfer_precision,
        progress,
    )?;
    lap(&mut report, "trace", Some("bricks"));

    let (bricked, remap) = folder.finish();
    let u8_rows = settings.transfer_precision == TransferPrecision::U8;
    if u8_rows && bricked.bricks.len() > U8_MAX_BRICK as usize + 1 {
        return Err(BakeError::Setting {
            name: "precision",
            value: format!("u8 with {} bricks", bricked.bricks.len()),
            reason: "the 8-bit factor encoding addresses at most 16,777,216 bricks; use f16",
        });
    }
    // Each probe's rows are finished and encoded, and freed, one table at a time.
    let tables: Vec<Factors> = tables
        .into_par_iter()
        .map(|rows| {
            let precision = settings.transfer_precision;
            rows.encode(&remap, &bricked.bricks, precision, n, 4.0 * cell_size)
        })
        .collect();
    drop(remap);
    lap(&mut report, "bricks", Some("assemble"));

    let valid: Vec<bool> = traced.iter().map(|r| !is_inside(r)).collect();
    if let Some(w) = diagnostics::inside_warning(&valid, settings, &winding, winding_hint) {
        report.warnings.push(w);
    }
    let sources = if settings.dilate {
        dilate::sources(&grid, &valid)
    } else {
        vec![None; valid.len()]
    };
    let Assembled {
        probes: probes_out,
        carried,
        factor_count,
        sky_mask,
        sky_transfer,
    } = assemble_probes(&traced, &positions, &tables, &valid, &sources);
    if factor_count > u64::from(u32::MAX) {
        return Err(BakeError::Setting {
            name: "spacing",
            value: format!("{factor_count} factors"),
            reason: "more than 2^32 factors (dilation copies tables into probes inside geometry): use fewer probes or rays, or --no-dilation",
        });
    }
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
    // No probe carrying a table (all invalid): an empty table of the asked precision.
    let factors = match carried.is_empty() {
        true => Factors::build(&[], settings.transfer_precision, n, 4.0 * cell_size),
        false => Factors::concat(&carried),
    };
    drop(carried);
    drop(tables);
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
    prt_format::validate::validate(&asset).map_err(|error| BakeError::Format {
        path: scene_path.to_owned(),
        error,
    })?;
    lap(&mut report, "assemble", None);
    Ok((asset, report))
}

/// Per probe: its record, and the factor table, sky mask and sky transfer it carries, in probe
/// order. A dilated probe carries its source's table, sky and ray counts (the record describes
/// the data it carries); only its position is its own. An invalid probe is never gathered and
/// carries no table.
fn assemble_probes<'a>(
    traced: &[trace::ProbeRays],
    positions: &[(Vec3, bool)],
    tables: &'a [Factors],
    valid: &[bool],
    sources: &[Option<usize>],
) -> Assembled<'a> {
    let mut probes = Vec::with_capacity(traced.len());
    let mut carried: Vec<&Factors> = Vec::with_capacity(traced.len());
    let mask_words = traced.first().map_or(0, |r| r.sky_mask.len());
    let mut sky_mask = Vec::with_capacity(mask_words * positions.len());
    let mut sky_transfer = Vec::with_capacity(positions.len());
    let mut factor_count = 0u64;
    for (p, &(pos, moved)) in positions.iter().enumerate() {
        let (flags, from) = match (valid[p], sources[p]) {
            (true, _) => (PROBE_VALID, p),
            (false, Some(q)) => (PROBE_VALID | PROBE_DILATED, q),
            (false, None) => (0, p),
        };
        let table = (flags != 0).then(|| &tables[from]);
        let len = table.map_or(0, Factors::len);
        probes.push(Probe {
            position: pos.to_array(),
            flags: flags | if moved { PROBE_OFFSET } else { 0 },
            first_factor: factor_count as u32,
            factor_count: len as u32,
            sky_rays: traced[from].sky_rays,
            backface_rays: traced[from].backface_rays,
        });
        factor_count += len as u64;
        carried.extend(table);
        sky_mask.extend_from_slice(&traced[from].sky_mask);
        sky_transfer.push(traced[from].sky_transfer);
    }
    Assembled {
        probes,
        carried,
        factor_count,
        sky_mask,
        sky_transfer,
    }
}

/// The per-probe sections of the asset, before encoding.
struct Assembled<'a> {
    probes: Vec<Probe>,
    /// The factor tables the probes carry, in probe order (a probe's own, its dilation
    /// source's; none for an invalid probe).
    carried: Vec<&'a Factors>,
    factor_count: u64,
    sky_mask: Vec<u32>,
    sky_transfer: Vec<[f32; prt_format::sh::SH_COUNT]>,
}
