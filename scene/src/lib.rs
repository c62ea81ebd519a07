//! # prt-scene: glTF 2.0 scenes, checked then read
//!
//! What the bake traces and the renderer draws, from the same file and by the same code:
//! world-space triangles (front faces counter-clockwise), their materials and vertex attributes,
//! the textures they sample, KHR_lights_punctual lights and perspective cameras ([`Scene`]).
//! No GPU and no BVH: `prt-bake` and `prt-render` both load scenes here and neither depends on
//! the other.
//!
//! Loading is two plain calls ([`load`] makes both):
//!
//! 1. [`check`] parses the JSON and checks what the gltf crate's readers assume before any of
//!    them runs: the version, every index, the byte ranges of views and accessors, the memory a
//!    header implies against the file's size, instancing, finite material factors, and where
//!    the external files lie: each buffer and image URI must resolve, after canonicalisation
//!    (`..` and symlinks), inside the scene file's folder or a folder the caller allows
//!    ([`Allowed`]). The readers panic, allocate what a header says or open any path a URI
//!    names on input the specification forbids; a hostile file ends here, as one error naming
//!    the file, the item and the value ([`SceneError`]).
//! 2. [`read`] reads what was checked: the external files the check found (not the URIs
//!    again), then the node graph into triangles, materials, images, lights and cameras.
//!
//! Between the two the caller knows what the document declares ([`Checked`]): the bake makes
//! its BVH build's memory ready beside the read, on threads the read leaves idle
//! ([`Checked::declared_triangles`]), with no callback into the loader.
//!
//! A panic of the gltf crate on input the checks do not cover ends as [`SceneError::Gltf`]
//! ([`catch_panic`]). Whether its report is printed is the binary's decision (its panic
//! hook), never this library's.

mod check;
mod error;
mod files;
mod read;
mod scene;
pub mod texture;

use std::panic::{AssertUnwindSafe, UnwindSafe};
use std::path::{Path, PathBuf};

pub use check::{allocation_budget, MAX_NODE_VISITS, MAX_TRIANGLES};
pub use error::SceneError;
pub use files::Allowed;
pub use scene::{Camera, Material, Scene, TriangleAttributes};
pub use texture::{Image, TextureRef};

/// A glTF document that passed [`check`]: parsed, with what the check found (its warnings,
/// the triangles it instances, its external files), ready for [`read`].
pub struct Checked {
    path: PathBuf,
    /// Where relative URIs resolve from: the scene file's folder as given.
    base: PathBuf,
    document: gltf::Document,
    /// The GLB binary chunk.
    blob: Option<Vec<u8>>,
    findings: check::Findings,
    /// Bytes of the scene file.
    input_bytes: u64,
}

impl Checked {
    /// The triangles the node graph instances (degenerate ones included), but at most a third
    /// of the bytes the file and its external buffers hold: what a caller may make room for
    /// before [`read`]. The cap keeps a small file that declares buffers it does not hold from
    /// costing that memory; for instanced meshes, and strips and fans of 8-bit indices (about
    /// a byte a triangle), it undercounts.
    pub fn declared_triangles(&self) -> usize {
        let held = self
            .input_bytes
            .saturating_add(self.findings.external_bytes)
            / 3;
        usize::try_from(self.findings.triangles.min(held)).unwrap_or(usize::MAX)
    }

    /// What the loader will skip or not implement (also in [`Scene::warnings`] once read).
    pub fn warnings(&self) -> &[String] {
        &self.findings.warnings
    }

    /// The bytes the external buffer files hold (their `byteLength`s).
    pub fn external_bytes(&self) -> u64 {
        self.findings.external_bytes
    }
}

/// Checks the glTF or GLB `bytes` of the scene file `path` (which names it in errors and
/// whose folder its URIs resolve from; external files may also lie in `allowed`'s folders),
/// before anything is read from its buffers.
pub fn check(path: &Path, bytes: &[u8], allowed: &Allowed) -> Result<Checked, SceneError> {
    catch_panic(|| check_unwinding(path, bytes, allowed))
        .unwrap_or_else(|message| Err(reader_failed(path, message)))
}

fn check_unwinding(path: &Path, bytes: &[u8], allowed: &Allowed) -> Result<Checked, SceneError> {
    let gltf_err = |message: String| SceneError::Gltf {
        path: path.to_owned(),
        message,
    };
    // Parsed without the crate's validation first: it indexes some references unchecked (an
    // attribute's accessor), so prt's own checks run before it.
    let gltf =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_err(e.to_string()))?;
    let folders = files::Folders::of(path, allowed);
    let json = gltf.document.as_json();
    let declared_bytes = json
        .buffers
        .iter()
        .fold(0u64, |a, b| a.saturating_add(b.byte_length.0));
    let input_bytes = bytes.len() as u64;
    let budget_input = declared_bytes.saturating_add(input_bytes);
    let findings = check::check_document(path, json, &folders, budget_input)?;
    let document = gltf::Document::from_json(gltf.document.into_json())
        .map_err(|e| gltf_err(e.to_string()))?;
    Ok(Checked {
        path: path.to_owned(),
        base: folders.base().to_owned(),
        document,
        blob: gltf.blob,
        findings,
        input_bytes,
    })
}

/// Reads the scene of a [`check`]ed document.
pub fn read(checked: Checked) -> Result<Scene, SceneError> {
    let path = checked.path.clone();
    // Unwind safe: `checked` is consumed, nothing it held is seen after a panic.
    let read = AssertUnwindSafe(move || {
        let Checked {
            path,
            base,
            document,
            blob,
            findings,
            ..
        } = checked;
        read::read_scene(&path, &base, &document, blob, findings)
    });
    catch_panic(read).unwrap_or_else(|message| Err(reader_failed(&path, message)))
}

/// Loads the scene file `path` (.gltf with embedded or external buffers, or .glb): [`check`],
/// then [`read`].
pub fn load(path: &Path, allowed: &Allowed) -> Result<Scene, SceneError> {
    let bytes = prt_format::read_regular_file(path).map_err(|error| SceneError::Io {
        path: path.to_owned(),
        error,
    })?;
    load_bytes(path, &bytes, allowed)
}

/// [`load`] of the file's bytes, already read (`path` resolves external buffers and images and
/// names the file in errors): callers that also hash the file read it once.
pub fn load_bytes(path: &Path, bytes: &[u8], allowed: &Allowed) -> Result<Scene, SceneError> {
    read(check(path, bytes, allowed)?)
}

/// The scene file's name without directories, for the asset header.
pub fn source_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn reader_failed(path: &Path, message: String) -> SceneError {
    SceneError::Gltf {
        path: path.to_owned(),
        message: format!("the glTF reader failed on this file ({message})"),
    }
}

/// Runs `f`, turning a panic into its message: how a library ends a dependency's panic on
/// hostile input (the gltf crate's readers here, obvhs in the bake) as an error naming the
/// input instead of a crash. It leaves the process's panic hook alone: whether the panic's
/// report is printed is for the binary to decide (`prt` keeps it quiet while it runs such a
/// call, see its `panics` module).
pub fn catch_panic<T>(f: impl FnOnce() -> T + UnwindSafe) -> Result<T, String> {
    std::panic::catch_unwind(f).map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into())
    })
}
