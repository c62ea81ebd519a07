//! # prt-bake: from a glTF scene to a PRT GI asset
//!
//! The pipeline, one module per stage:
//!
//! 1. [`scene`]: load the glTF (transforms, primitives, materials, textures, lights).
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

// SH and colour maths index several parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

pub mod accel;
pub mod depth;
pub mod diagnostics;
pub mod dilate;
pub mod error;
pub mod gltf_check;
mod memory;
pub mod merge;
pub mod offset;
mod pipeline;
pub mod probes;
pub mod scene;
pub mod stream;
pub mod tables;
pub mod texture;
pub mod trace;

use std::path::Path;
use std::time::{Duration, Instant};

use prt_format::{Asset, TransferPrecision};

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
    /// Bytes of factor rows held in memory between the trace and the table encoding (whole
    /// chunks of 64 KiB to 64 MiB, at least one, and two more while rows are written); past
    /// it the oldest rows wait in a temporary file in [`std::env::temp_dir`] (`TMPDIR`), and
    /// the asset does not change ([`tables::row_store`]). The rows are what grows with the probe count: 28 bytes a factor at u8,
    /// 52 at f16 and f32 (Sponza at 1.0 m: 143 MB; at 105k probes 1.0 GB).
    pub row_memory: usize,
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
            row_memory: 256 << 20,
        }
    }
}

impl BakeSettings {
    /// The surfel cell size of a bake at `spacing` ([`BakeSettings::cell_size`]).
    pub fn cell_size_for(&self, spacing: f32) -> f32 {
        self.cell_size.unwrap_or(spacing / self.cells_per_spacing)
    }

    /// Higher accuracy: 8x the rays and half-size bricks. On the Cornell reference (27 probes at
    /// 0.6 m) it brings the mean irradiance error from 4.0% to 0.5% (p95 1.3%), at 5.6x the
    /// factors per probe (runtime gather work and asset size) and 8x the trace time.
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
    /// Bytes of factor rows that went through the temporary file
    /// ([`BakeSettings::row_memory`]).
    pub rows_spilled: u64,
}

/// `items` cut into consecutive runs of `lens` items (summing to at most `items.len()`), each
/// with the index of its first item: a table filled run by run in parallel.
pub(crate) fn split_runs<'a, T>(
    mut items: &'a mut [T],
    lens: &[usize],
) -> Vec<(usize, &'a mut [T])> {
    let mut runs = Vec::with_capacity(lens.len());
    let mut start = 0;
    for &len in lens {
        let (run, rest) = std::mem::take(&mut items).split_at_mut(len);
        runs.push((start, run));
        items = rest;
        start += len;
    }
    runs
}

/// Most worker threads a bake starts.
pub const MAX_THREADS: usize = 1024;

/// Runs `f`, turning a panic inside a dependency (the gltf crate's readers, obvhs) into its
/// message, for an error that names the input instead of a crash. The default report of a panic
/// is suppressed while any such call runs: the panic hook is process-wide (a panic elsewhere in
/// the process meanwhile still unwinds, unreported), so it is wrapped once and told by a count
/// of the calls under way. No lock is held while `f` runs: `f` runs rayon jobs, and a worker
/// waiting for them can steal another bake's call to this function; a lock held across `f`
/// (the hook swapped under a mutex) deadlocked two bakes running at once in the test suite.
pub(crate) fn catch_quietly<T>(
    f: impl FnOnce() -> T + std::panic::UnwindSafe,
) -> Result<T, String> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static QUIET: AtomicUsize = AtomicUsize::new(0);
    static WRAP: std::sync::Once = std::sync::Once::new();
    WRAP.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if QUIET.load(Ordering::SeqCst) == 0 {
                previous(info);
            }
        }));
    });
    QUIET.fetch_add(1, Ordering::SeqCst);
    let result = std::panic::catch_unwind(f);
    QUIET.fetch_sub(1, Ordering::SeqCst);
    result.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into())
    })
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
        if let Some((_, assemble)) = report.timings.last_mut() {
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
/// removed). Sponza at 1.0 m: validation takes 0.08 s, the write 0.13-0.15 s. The report's
/// "write" stage is both; [`bake`] counts validation in "assemble".
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

#[cfg(test)]
mod tests {
    /// A call inside a call, on the same thread, as when a rayon worker waiting inside one
    /// bake's BVH build steals another bake's: it finishes (a lock held across `f` hung here),
    /// and a panic inside comes back as its message.
    #[test]
    fn catch_quietly_nests() {
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let inner = super::catch_quietly(|| {
                super::catch_quietly(|| -> u32 { panic!("inner failure") })
            });
            send.send(inner).ok();
        });
        let got = receive
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("catch_quietly inside catch_quietly did not finish: deadlock");
        assert_eq!(got, Ok(Err("inner failure".to_string())));
    }
}
