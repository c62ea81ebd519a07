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
//!
//! The comments say why each choice was made; the measurements that decided them are in
//! `docs/results/bake_notes.md`.

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
mod settings;
pub mod stream;
pub mod tables;
pub mod texture;
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
}

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
