//! Typed errors of a bake. Each names the file, the item and the offending value.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("{path}: cannot read: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The scene file could not be loaded (the messages are prt-scene's).
    #[error(transparent)]
    Scene(#[from] prt_scene::SceneError),
    #[error("{path}: the scene has no triangles{} (give --bounds to bake an all-sky volume)", match degenerate { 0 => String::new(), n => format!(": all {n} were degenerate (zero area) and skipped") })]
    NoTriangles { path: PathBuf, degenerate: u64 },
    #[error("building the BVH failed ({message}); coordinates up to {extent:e} m, traced in units of {unit:e} m")]
    Bvh {
        message: String,
        extent: f32,
        unit: f32,
    },
    #[error("invalid setting {name} = {value}: {reason}")]
    Setting {
        name: &'static str,
        value: String,
        reason: &'static str,
    },
    #[error("the probe grid {counts:?} at spacing {spacing} m has {} probes, more than --max-probes {max}; raise --spacing or --max-probes, or give smaller --bounds", if *count == u64::MAX { "more than 2^64".to_string() } else { count.to_string() })]
    TooManyProbes {
        counts: [u64; 3],
        spacing: f32,
        count: u64,
        max: u64,
    },
    #[error("{path}: {error}")]
    Format {
        path: PathBuf,
        error: prt_format::FormatError,
    },
    #[error("{path}: cannot keep factor rows in this temporary file: {error} (factor rows past the memory budget, --row-memory or BakeSettings::row_memory, wait there: point TMPDIR at a disk with room, or raise the budget)")]
    Spill {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("cannot start the thread pool: {0}")]
    ThreadPool(String),
}
