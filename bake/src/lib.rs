//! # prt-bake: from a glTF scene to a PRT GI asset
//!
//! The pipeline, one module per stage:
//!
//! 1. Load: `prt_scene` checks the glTF, then reads it (transforms, primitives, materials,
//!    textures, lights) while the BVH build's memory is made ready beside it.
//! 2. [`accel`]: one PLOC build gives the 8-wide BVH the probes' ray packets are traced through
//!    ([`accel::bvh8`]) and the BVH2 the asset carries.
//! 3. [`probes`]: a regular grid over the scene bounds or `bounds`.
//! 4. [`trace`]: each probe shoots the N directions of the spherical Fibonacci lattice; hits
//!    become surfel samples (position, normal, albedo, emission, back-face flag), misses set bits
//!    of the probe's sky mask. Probes whose rays mostly hit back faces are inside geometry and
//!    marked invalid.
//! 5. [`merge`]: hits are folded into normal-keyed bricks and merged into surfels as they
//!    arrive, block by block of probes ([`stream`]), never all held at once.
//! 6. [`tables`]: per probe, (brick, ray count, SH9 transfer) rows from its own rays.
//! 7. The asset is assembled, validated and written atomically (`prt_format::io`).
//!
//! Every stage orders its output by probe, ray, key or index, never by thread timing: the same
//! scene and settings give byte-identical assets whatever the thread count.
//!
//! The comments say why each choice was made; the measurements that decided them are in
//! `docs/results/bake_notes.md`.

// SH and colour maths index several parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

pub mod accel;
pub mod bench;
pub mod depth;
pub mod diagnostics;
pub mod dilate;
pub mod error;
mod memory;
pub mod merge;
pub mod offset;
mod pipeline;
pub mod placement;
pub mod probes;
pub mod refine;
mod settings;
pub mod sky_terms;
pub mod stream;
pub mod surface_terms;
pub mod tables;
pub mod trace;

use std::path::Path;
use std::time::{Duration, Instant};

use prt_format::Asset;

pub use error::BakeError;
pub use settings::{BakeSettings, MAX_THREADS};

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
    /// Bytes of factor rows that went through the temporary file
    /// ([`BakeSettings::row_memory`]).
    pub rows_spilled: u64,
    /// With sparse placement ([`BakeSettings::sparse`]): what it placed where.
    pub placed: Option<Placed>,
    /// What the refine stage dropped ([`refine::prune`]): `None` when it had nothing to do (no
    /// threshold, [`BakeSettings::prune_error`], and no budget exceeded,
    /// [`BakeSettings::probe_budget`]).
    pub refined: Option<refine::Refined>,
    /// Bricks split where a wall stands on them ([`merge::split`]), and the parts they made.
    pub split: (usize, usize),
}

/// What sparse placement ([`placement`]) placed, of a grid's points.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Placed {
    /// Grid points.
    pub grid: usize,
    /// Points traced.
    pub traced: usize,
    /// Per level 1..=`prt_format::tier::LEVELS`: its cells a surface passes through.
    pub busy_cells: [usize; prt_format::tier::LEVELS as usize],
    /// Per level: points left out and filled from it at runtime.
    pub filled: [usize; prt_format::tier::LEVELS as usize],
}

/// Bakes `scene_path` into a validated asset (not written).
pub fn bake(
    scene_path: &Path,
    settings: &BakeSettings,
    progress: &dyn Progress,
) -> Result<(Asset, BakeReport), BakeError> {
    in_pool(settings, || {
        let (asset, mut report) = pipeline::bake_in_pool(scene_path, settings, progress)?;
        let t = Instant::now();
        pipeline::validate(&asset, scene_path)?;
        // Validation is the end of assembling.
        if let Some((_, assemble)) = report.timings.iter_mut().find(|(s, _)| *s == "assemble") {
            *assemble += t.elapsed();
        }
        Ok((asset, report))
    })
}

/// Runs `f` in a pool of `settings.threads` workers, or in the global pool (all cores).
fn in_pool<T: Send>(
    settings: &BakeSettings,
    f: impl FnOnce() -> Result<T, BakeError> + Send,
) -> Result<T, BakeError> {
    settings.check()?;
    match settings.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| BakeError::ThreadPool(e.to_string()))?
            .install(f),
        None => f(),
    }
}

/// Bakes and writes the asset atomically to `out`; no partial file is left on failure.
///
/// The asset is validated while it is written (to a temporary file, renamed over `out` only if
/// the asset is valid; an invalid asset, a bug of the bake, is written in full before it is
/// removed), so validation costs no time of its own. The report's "write" stage is both;
/// [`bake`] counts validation in "assemble".
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
    let format_error = |error| BakeError::Format {
        path: out.to_owned(),
        error,
    };
    prt_format::io::check_replaceable(out).map_err(format_error)?;
    in_pool(settings, || {
        let (asset, mut report) = pipeline::bake_in_pool(scene_path, settings, progress)?;
        let t = Instant::now();
        let (valid, staged) = rayon::join(
            || pipeline::validate(&asset, scene_path),
            || prt_format::stage_asset(out, &asset).map_err(format_error),
        );
        // Invalid: the staged file is dropped, so removed.
        valid?;
        let (staged, bytes) = staged?;
        staged.commit().map_err(format_error)?;
        report.file_bytes = bytes;
        report.timings.push(("write", t.elapsed()));
        Ok((asset, report))
    })
}
