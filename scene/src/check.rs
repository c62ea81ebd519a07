//! Checks of a glTF document against what the gltf crate's readers assume, run before any of
//! them reads: the readers panic (`unreachable!`, slice indexing, `unwrap`) or allocate whatever
//! a header says on input the glTF 2.0 specification forbids, and read any path a URI names.
//! Every check names the item and the value (glTF 2.0 spec, sections 3.6 "Binary data storage",
//! 3.7 "Geometry", 3.5 "Nodes"), so that a hostile or broken file ends as one clear error:
//!
//! - `asset.version` must be 2.x;
//! - buffer and image URIs are data URIs or paths to regular files (no schemes, no devices) in
//!   the scene's folder or an allowed one ([`crate::files`]), and a buffer file holds at least
//!   its `byteLength`;
//! - buffer views lie inside their buffers with a legal `byteStride`;
//! - accessors lie inside their buffer views (`byteStride` at least the element size), those
//!   without a view (zeros plus sparse values) stay within [`allocation_budget`] of the input's
//!   size, sparse indices are unsigned and below the count;
//! - meshes reference existing accessors and materials (a triangle list whose count is not a
//!   multiple of 3 is warned about, as the Khronos validator does, and its tail ignored);
//! - nodes do not combine `matrix` with TRS, and instancing (nodes shared by several parents)
//!   produces at most [`MAX_TRIANGLES`] triangles;
//! - materials have finite factors in f32.
//!
//! Images are decoded later, with an allocation limit from their encoded size
//! ([`crate::texture::decode_images`]).

use std::path::{Path, PathBuf};

use gltf::json;

use crate::error::SceneError;
use crate::files::Folders;

/// Most triangles a scene may instance: about 4.5 GB of loaded triangles and attributes.
pub const MAX_TRIANGLES: u64 = 1 << 25;

/// Most node instances a scene may visit (a node reached through several parents counts once per
/// path).
pub const MAX_NODE_VISITS: u64 = 1 << 24;

/// Decoded bytes a file may imply per input byte (images, accessors without a buffer view),
/// above a floor of [`MIN_BUDGET`]: real PNG and JPEG textures compress 2-20x, bombs 1000x.
pub const BUDGET_PER_INPUT_BYTE: u64 = 256;
/// Decoded bytes any file may imply, however small: an 8192 x 8192 RGBA texture.
pub const MIN_BUDGET: u64 = 256 << 20;

/// Decoded bytes allowed for `input_bytes` of input.
pub fn allocation_budget(input_bytes: u64) -> u64 {
    input_bytes
        .saturating_mul(BUDGET_PER_INPUT_BYTE)
        .max(MIN_BUDGET)
}

fn err(path: &Path, message: String) -> SceneError {
    SceneError::Gltf {
        path: path.to_owned(),
        message,
    }
}

/// What [`check_document`] found in a document it accepts.
pub struct Findings {
    /// What the loader will skip or not implement.
    pub warnings: Vec<String>,
    /// The triangles the node graph instances (each instance's, degenerate ones included).
    pub triangles: u64,
    /// The bytes its external buffer files hold (their `byteLength`s, which the files were
    /// found to hold).
    pub external_bytes: u64,
    /// The external files the loader reads, found where they may be ([`Folders::resolve`]).
    pub files: ExternalFiles,
}

/// Per buffer and per image, the canonical file its URI names (`None`: a data URI, the GLB
/// binary chunk or a buffer view): what the loader reads, not the URI again.
#[derive(Default)]
pub struct ExternalFiles {
    pub buffers: Vec<Option<PathBuf>>,
    pub images: Vec<Option<PathBuf>>,
}

/// Checks the document before its buffers are read, its external files against `folders`.
pub fn check_document(
    path: &Path,
    root: &json::Root,
    folders: &Folders<'_>,
    input_bytes: u64,
) -> Result<Findings, SceneError> {
    let e = |m: String| err(path, m);
    if !root.asset.version.starts_with("2.") {
        return Err(e(format!(
            "asset.version is {:?}; prt reads glTF 2.x",
            root.asset.version
        )));
    }
    let (files, external_bytes) = check_files(path, root, folders)?;
    check_views(path, root)?;
    check_accessors(path, root, allocation_budget(input_bytes))?;
    let mut warnings = Vec::new();
    check_meshes(path, root, &mut warnings)?;
    let triangles = check_nodes(path, root)?;
    check_materials(path, root)?;
    if root
        .extensions_used
        .iter()
        .any(|x| x == "KHR_texture_transform")
    {
        warnings.push(
            "KHR_texture_transform is used but not implemented: textures are sampled untransformed"
                .to_owned(),
        );
    }
    Ok(Findings {
        warnings,
        triangles,
        external_bytes,
        files,
    })
}

/// Finds the external buffer and image files where they may be and checks that buffer files
/// hold their `byteLength`; returns the files and the bytes those buffers declare.
fn check_files(
    path: &Path,
    root: &json::Root,
    folders: &Folders<'_>,
) -> Result<(ExternalFiles, u64), SceneError> {
    let mut files = ExternalFiles::default();
    let mut external_bytes = 0u64;
    for (i, b) in root.buffers.iter().enumerate() {
        let uri = b.uri.as_ref().filter(|u| !u.starts_with("data:"));
        let Some(uri) = uri else {
            files.buffers.push(None);
            continue;
        };
        let fail = |message| SceneError::Buffer {
            path: path.to_owned(),
            index: i,
            uri: uri.clone(),
            message,
        };
        let file = folders.resolve(uri).map_err(fail)?;
        let len = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0);
        let want = b.byte_length.0;
        if len < want {
            return Err(fail(format!(
                "the file has {len} bytes, byteLength says {want}"
            )));
        }
        external_bytes = external_bytes.saturating_add(want);
        files.buffers.push(Some(file));
    }
    for (i, img) in root.images.iter().enumerate() {
        let fail = |uri: &str, message| SceneError::Image {
            path: path.to_owned(),
            index: i,
            uri: uri.to_owned(),
            message,
        };
        files.images.push(match (&img.uri, img.buffer_view) {
            (Some(uri), _) if !uri.starts_with("data:") => {
                Some(folders.resolve(uri).map_err(|m| fail(uri, m))?)
            }
            (None, Some(_)) if img.mime_type.is_none() => {
                let message = "an image in a buffer view must have a mimeType".into();
                return Err(fail("buffer view", message));
            }
            _ => None,
        });
    }
    Ok((files, external_bytes))
}

fn check_views(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    for (i, v) in root.buffer_views.iter().enumerate() {
        let Some(buffer) = root.buffers.get(v.buffer.value()) else {
            return Err(err(
                path,
                format!("bufferView {i}: buffer {} does not exist", v.buffer.value()),
            ));
        };
        let offset = v.byte_offset.map_or(0, |o| o.0);
        let end = offset.saturating_add(v.byte_length.0);
        if end > buffer.byte_length.0 {
            return Err(err(
                path,
                format!(
                    "bufferView {i}: bytes {offset}..{end} run past buffer {} ({} bytes)",
                    v.buffer.value(),
                    buffer.byte_length.0
                ),
            ));
        }
        if let Some(s) = v.byte_stride {
            if !(4..=252).contains(&s.0) || s.0 % 4 != 0 {
                return Err(err(
                    path,
                    format!(
                        "bufferView {i}: byteStride {} (glTF 2.0: 4..=252, a multiple of 4)",
                        s.0
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The value of a checked JSON field (the crate's validation has already refused invalid ones).
fn valid<T: Copy>(c: &json::validation::Checked<T>) -> Option<T> {
    match c {
        json::validation::Checked::Valid(v) => Some(*v),
        json::validation::Checked::Invalid => None,
    }
}

fn element_size(a: &json::Accessor) -> u64 {
    let comps = valid(&a.type_).map_or(1, |t| t.multiplicity()) as u64;
    let size = valid(&a.component_type).map_or(4, |c| c.0.size()) as u64;
    comps * size
}

fn check_accessors(path: &Path, root: &json::Root, budget: u64) -> Result<(), SceneError> {
    for (i, a) in root.accessors.iter().enumerate() {
        let e = |m: String| err(path, format!("accessor {i}: {m}"));
        let elem = element_size(a);
        let count = a.count.0;
        // The glTF reader computes `count - 1` elements past the first (a panic at 0 where
        // overflow is checked).
        if count == 0 {
            return Err(e("count 0 (glTF 2.0: at least 1)".into()));
        }
        check_elements(root, a, elem, budget).map_err(e)?;
        if let Some(s) = &a.sparse {
            check_sparse_ranges(root, s, count, elem).map_err(e)?;
        }
    }
    Ok(())
}

/// An accessor's `count` elements of `elem` bytes lie inside its buffer view (at a stride of at
/// least `elem`), or without a view take at most `budget` bytes.
fn check_elements(
    root: &json::Root,
    a: &json::Accessor,
    elem: u64,
    budget: u64,
) -> Result<(), String> {
    let count = a.count.0;
    let Some(view) = a.buffer_view else {
        let bytes = count.saturating_mul(elem);
        if bytes > budget {
            return Err(format!(
                "{count} elements without a bufferView would take {bytes} bytes, more than {budget} for a file this size"
            ));
        }
        return Ok(());
    };
    let Some(v) = root.buffer_views.get(view.value()) else {
        return Err(format!("bufferView {} does not exist", view.value()));
    };
    let stride = v.byte_stride.map_or(elem, |s| s.0 as u64);
    if stride < elem {
        return Err(format!(
            "bufferView {} has byteStride {stride}, less than the {elem}-byte elements",
            view.value()
        ));
    }
    let offset = a.byte_offset.map_or(0, |o| o.0);
    let need = offset
        .saturating_add(stride.saturating_mul(count - 1))
        .saturating_add(elem);
    if need > v.byte_length.0 {
        return Err(format!(
            "{count} elements of {elem} bytes (stride {stride}, offset {offset}) need {need} bytes; bufferView {} has {}",
            view.value(),
            v.byte_length.0
        ));
    }
    Ok(())
}

/// A sparse accessor's (of `count` elements of `elem` bytes) substitutions: at most `count`,
/// unsigned indices, indices and values inside their buffer views.
fn check_sparse_ranges(
    root: &json::Root,
    s: &json::accessor::sparse::Sparse,
    count: u64,
    elem: u64,
) -> Result<(), String> {
    if s.count.0 > count {
        return Err(format!("sparse count {} exceeds count {count}", s.count.0));
    }
    let Some(json::accessor::IndexComponentType(ty)) = valid(&s.indices.component_type) else {
        return Err("sparse indices have an invalid component type".into());
    };
    if !matches!(
        ty,
        json::accessor::ComponentType::U8
            | json::accessor::ComponentType::U16
            | json::accessor::ComponentType::U32
    ) {
        return Err(format!(
            "sparse indices are {ty:?}; glTF 2.0 allows unsigned"
        ));
    }
    for (what, view, size, offset) in [
        (
            "indices",
            s.indices.buffer_view,
            ty.size() as u64,
            s.indices.byte_offset.0,
        ),
        ("values", s.values.buffer_view, elem, s.values.byte_offset.0),
    ] {
        let Some(v) = root.buffer_views.get(view.value()) else {
            return Err(format!(
                "sparse {what} bufferView {} does not exist",
                view.value()
            ));
        };
        let need = offset.saturating_add(size.saturating_mul(s.count.0));
        if need > v.byte_length.0 {
            return Err(format!(
                "sparse {what} need {need} bytes; bufferView {} has {}",
                view.value(),
                v.byte_length.0
            ));
        }
    }
    Ok(())
}

fn check_meshes(
    path: &Path,
    root: &json::Root,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let e = |message: String| SceneError::Primitive {
                path: path.to_owned(),
                mesh: m.to_string(),
                primitive: p,
                message,
            };
            for (semantic, index) in &prim.attributes {
                if index.value() >= accessors {
                    return Err(e(format!(
                        "attribute {}: accessor {} does not exist ({accessors} accessors)",
                        match semantic {
                            json::validation::Checked::Valid(s) => format!("{s:?}"),
                            json::validation::Checked::Invalid => "(unknown)".into(),
                        },
                        index.value()
                    )));
                }
            }
            if let Some(ix) = prim.indices {
                if ix.value() >= accessors {
                    return Err(e(format!(
                        "indices: accessor {} does not exist ({accessors} accessors)",
                        ix.value()
                    )));
                }
            }
            if let Some(mat) = prim.material {
                if mat.value() >= root.materials.len() {
                    return Err(e(format!("material {} does not exist", mat.value())));
                }
            }
            let triangles = valid(&prim.mode) == Some(json::mesh::Mode::Triangles);
            if let Some(n) = vertex_count(root, prim).filter(|n| triangles && n % 3 != 0) {
                warnings.push(format!(
                    "mesh {m} primitive {p}: a triangle list of {n} {}, not a multiple of 3: the last {} ignored",
                    if prim.indices.is_some() { "indices" } else { "vertices" },
                    n % 3
                ));
            }
        }
    }
    Ok(())
}

/// Vertices a primitive's mode walks: its index count, or its POSITION count without indices
/// (references already checked by [`check_meshes`]).
fn vertex_count(root: &json::Root, prim: &json::mesh::Primitive) -> Option<u64> {
    prim.indices
        .or_else(|| {
            prim.attributes
                .get(&json::validation::Checked::Valid(
                    json::mesh::Semantic::Positions,
                ))
                .copied()
        })
        .map(|a| root.accessors[a.value()].count.0)
}

/// Triangles each mesh adds (before degenerate ones are skipped).
fn mesh_triangles(root: &json::Root, mesh: &json::Mesh) -> u64 {
    mesh.primitives
        .iter()
        .map(|p| {
            let n = vertex_count(root, p).unwrap_or(0);
            match valid(&p.mode) {
                Some(json::mesh::Mode::Triangles) => n / 3,
                Some(json::mesh::Mode::TriangleStrip | json::mesh::Mode::TriangleFan) => {
                    n.saturating_sub(2)
                }
                _ => 0,
            }
        })
        .sum()
}

/// Checks the node graph; returns the triangles it instances.
fn check_nodes(path: &Path, root: &json::Root) -> Result<u64, SceneError> {
    let n = root.nodes.len();
    for (i, node) in root.nodes.iter().enumerate() {
        let trs = node.translation.is_some() || node.rotation.is_some() || node.scale.is_some();
        if node.matrix.is_some() && trs {
            return Err(err(
                path,
                format!("node {i} has both a matrix and translation/rotation/scale (glTF 2.0 allows one)"),
            ));
        }
        if let Some(c) = node.children.iter().flatten().find(|c| c.value() >= n) {
            return Err(err(
                path,
                format!("node {i}: child {} does not exist", c.value()),
            ));
        }
        if let Some(m) = node.mesh.filter(|m| m.value() >= root.meshes.len()) {
            return Err(err(
                path,
                format!("node {i}: mesh {} does not exist", m.value()),
            ));
        }
    }
    let (visits, triangles) = instanced(root);
    if triangles > MAX_TRIANGLES || visits > MAX_NODE_VISITS {
        return Err(err(
            path,
            format!(
                "the node graph instances {visits} nodes and {triangles} triangles (nodes shared by several parents), more than {MAX_NODE_VISITS} nodes or {MAX_TRIANGLES} triangles"
            ),
        ));
    }
    Ok(triangles)
}

/// The node visits and triangles the scene's node graph instances: the default scene's roots
/// (else the first scene's; without scenes every node that is no other's child), as the loader
/// visits them.
fn instanced(root: &json::Root) -> (u64, u64) {
    let n = root.nodes.len();
    // Node visits and triangles per node subtree (memoised; a cycle counts as 0 here and is
    // refused by the loader's depth limit): instancing (nodes shared by several parents)
    // multiplies both, and visiting 2^40 empty nodes hangs as surely as 2^40 triangles.
    let mut memo: Vec<Option<(u64, u64)>> = vec![None; n];
    fn count(
        root: &json::Root,
        i: usize,
        memo: &mut Vec<Option<(u64, u64)>>,
        depth: u32,
    ) -> (u64, u64) {
        if let Some(c) = memo[i] {
            return c;
        }
        if depth > 256 {
            return (0, 0);
        }
        let node = &root.nodes[i];
        let own = node
            .mesh
            .map_or(0, |m| mesh_triangles(root, &root.meshes[m.value()]));
        let total = node.children.iter().flatten().fold((1u64, own), |acc, c| {
            let (v, t) = count(root, c.value(), memo, depth + 1);
            (acc.0.saturating_add(v), acc.1.saturating_add(t))
        });
        memo[i] = Some(total);
        total
    }
    let roots: Vec<usize> = match root
        .scene
        .or_else(|| (!root.scenes.is_empty()).then(|| json::Index::new(0)))
    {
        Some(s) => root
            .scenes
            .get(s.value())
            .map(|s| {
                s.nodes
                    .iter()
                    .map(|n| n.value())
                    .filter(|&i| i < n)
                    .collect()
            })
            .unwrap_or_default(),
        // No scene: the loader visits the nodes no other node lists as a child.
        None => {
            let mut is_child = vec![false; n];
            for c in root.nodes.iter().flat_map(|x| x.children.iter().flatten()) {
                is_child[c.value()] = true;
            }
            (0..n).filter(|&i| !is_child[i]).collect()
        }
    };
    roots.iter().fold((0u64, 0u64), |acc, &r| {
        let (v, t) = count(root, r, &mut memo, 0);
        (acc.0.saturating_add(v), acc.1.saturating_add(t))
    })
}

fn check_materials(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    for (i, m) in root.materials.iter().enumerate() {
        let name = m
            .name
            .as_deref()
            .map(|n| format!(" ({n:?})"))
            .unwrap_or_default();
        let e = |what: &str, v: &[f32]| {
            err(
                path,
                format!("material {i}{name}: {what} {v:?} is not finite"),
            )
        };
        let base = m.pbr_metallic_roughness.base_color_factor.0;
        if !base.iter().all(|c| c.is_finite()) {
            return Err(e("baseColorFactor", &base));
        }
        let emissive = m.emissive_factor.0;
        if !emissive.iter().all(|c| c.is_finite()) {
            return Err(e("emissiveFactor", &emissive));
        }
    }
    Ok(())
}

/// Sparse indices below their accessor's count (the gltf crate writes them unchecked).
pub fn check_sparse(
    path: &Path,
    root: &json::Root,
    buffers: &[gltf::buffer::Data],
) -> Result<(), SceneError> {
    for (i, a) in root.accessors.iter().enumerate() {
        let Some(s) = &a.sparse else { continue };
        let v = &root.buffer_views[s.indices.buffer_view.value()];
        let Some(data) = buffers.get(v.buffer.value()) else {
            continue;
        };
        let start = v.byte_offset.map_or(0, |o| o.0) + s.indices.byte_offset.0;
        let Some(json::accessor::IndexComponentType(ty)) = valid(&s.indices.component_type) else {
            continue;
        };
        let size = ty.size();
        for k in 0..s.count.0 as usize {
            let at = start as usize + k * size;
            let Some(b) = data.0.get(at..at + size) else {
                break;
            };
            let index = b
                .iter()
                .rev()
                .fold(0u64, |acc, &x| (acc << 8) | u64::from(x));
            if index >= a.count.0 {
                return Err(err(
                    path,
                    format!(
                        "accessor {i}: sparse index {k} is {index}, but the accessor has {} elements",
                        a.count.0
                    ),
                ));
            }
        }
    }
    Ok(())
}
