//! Checks of a glTF document against what the gltf crate's readers assume, run before any of
//! them reads: the readers panic (`unreachable!`, slice indexing, `unwrap`) or allocate whatever
//! a header says on input the glTF 2.0 specification forbids, and read any path a URI names.
//! Every check names the item and the value (glTF 2.0 spec, sections 3.6 "Binary data storage",
//! 3.7 "Geometry", 3.5 "Nodes"), so that a hostile or broken file ends as one clear error:
//!
//! - `asset.version` must be 2.x;
//! - buffer and image URIs are data URIs or relative paths to regular files (no absolute paths,
//!   no schemes, no devices), and a buffer file holds at least its `byteLength`;
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
//! Images are decoded here too ([`decode_images`]), with the image crate's allocation limit set
//! from the encoded size, instead of by `gltf::import_images` (which decodes whatever dimensions
//! a header claims, up to the image crate's 512 MiB default).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use gltf::json;

use crate::error::BakeError;
use crate::texture::Image;

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

fn err(path: &Path, message: String) -> BakeError {
    BakeError::Gltf {
        path: path.to_owned(),
        message,
    }
}

/// A relative path (resolved against `base`; `..` allowed, as shared texture folders need it) to a
/// regular file, or why `uri` is refused.
pub fn external_file(base: &Path, uri: &str) -> Result<PathBuf, String> {
    let decoded = percent_decode(uri);
    // A colon is a scheme (`file:`, `http:`) or a drive letter; a leading slash is absolute.
    if decoded.starts_with(['/', '\\']) || decoded.contains(':') {
        return Err(format!(
            "URI {uri:?} is absolute or has a scheme; only data URIs and relative paths are read"
        ));
    }
    let file = base.join(&decoded);
    match std::fs::metadata(&file) {
        Ok(m) if m.is_file() => Ok(file),
        Ok(_) => Err(format!("{} is not a regular file", file.display())),
        Err(e) => Err(format!("file {} not found ({e})", file.display())),
    }
}

/// `%XX` escapes decoded (glTF URIs are RFC 3986 references); invalid escapes stay as they are.
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// What [`check_document`] found in a document it accepts.
pub struct Checked {
    /// What the loader will skip or not implement.
    pub warnings: Vec<String>,
    /// The triangles the node graph instances (each instance's, degenerate ones included).
    pub triangles: u64,
    /// The bytes its external buffer files hold (their `byteLength`s, which the files were
    /// found to hold).
    pub external_bytes: u64,
}

/// Checks the document before its buffers are read.
pub fn check_document(
    path: &Path,
    root: &json::Root,
    base: &Path,
    input_bytes: u64,
) -> Result<Checked, BakeError> {
    let e = |m: String| err(path, m);
    if !root.asset.version.starts_with("2.") {
        return Err(e(format!(
            "asset.version is {:?}; prt reads glTF 2.x",
            root.asset.version
        )));
    }
    let external_bytes = check_buffers(path, root, base)?;
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
    Ok(Checked {
        warnings,
        triangles,
        external_bytes,
    })
}

/// Checks that external buffer and image files exist and that buffer files hold their
/// `byteLength`; returns the bytes those buffers declare.
fn check_buffers(path: &Path, root: &json::Root, base: &Path) -> Result<u64, BakeError> {
    let mut external_bytes = 0u64;
    for (i, b) in root.buffers.iter().enumerate() {
        let Some(uri) = &b.uri else { continue };
        if uri.starts_with("data:") {
            continue;
        }
        let file = external_file(base, uri).map_err(|message| BakeError::Buffer {
            path: path.to_owned(),
            index: i,
            uri: uri.clone(),
            message,
        })?;
        let len = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0);
        let want = b.byte_length.0;
        if len < want {
            return Err(BakeError::Buffer {
                path: path.to_owned(),
                index: i,
                uri: uri.clone(),
                message: format!("the file has {len} bytes, byteLength says {want}"),
            });
        }
        external_bytes = external_bytes.saturating_add(want);
    }
    for (i, img) in root.images.iter().enumerate() {
        match (&img.uri, img.buffer_view) {
            (Some(uri), _) if !uri.starts_with("data:") => {
                external_file(base, uri).map_err(|message| BakeError::Image {
                    path: path.to_owned(),
                    index: i,
                    uri: uri.clone(),
                    message,
                })?;
            }
            (None, Some(_)) if img.mime_type.is_none() => {
                return Err(BakeError::Image {
                    path: path.to_owned(),
                    index: i,
                    uri: "buffer view".into(),
                    message: "an image in a buffer view must have a mimeType".into(),
                })
            }
            _ => {}
        }
    }
    Ok(external_bytes)
}

fn check_views(path: &Path, root: &json::Root) -> Result<(), BakeError> {
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

fn check_accessors(path: &Path, root: &json::Root, budget: u64) -> Result<(), BakeError> {
    for (i, a) in root.accessors.iter().enumerate() {
        let e = |m: String| err(path, format!("accessor {i}: {m}"));
        let elem = element_size(a);
        let count = a.count.0;
        // The glTF reader computes `count - 1` elements past the first (a panic at 0 where
        // overflow is checked).
        if count == 0 {
            return Err(e("count 0 (glTF 2.0: at least 1)".into()));
        }
        match a.buffer_view {
            Some(view) => {
                let Some(v) = root.buffer_views.get(view.value()) else {
                    return Err(e(format!("bufferView {} does not exist", view.value())));
                };
                let stride = v.byte_stride.map_or(elem, |s| s.0 as u64);
                if stride < elem {
                    return Err(e(format!(
                        "bufferView {} has byteStride {stride}, less than the {elem}-byte elements",
                        view.value()
                    )));
                }
                let offset = a.byte_offset.map_or(0, |o| o.0);
                let need = offset
                    .saturating_add(stride.saturating_mul(count - 1))
                    .saturating_add(elem);
                if need > v.byte_length.0 {
                    return Err(e(format!(
                        "{count} elements of {elem} bytes (stride {stride}, offset {offset}) need {need} bytes; bufferView {} has {}",
                        view.value(),
                        v.byte_length.0
                    )));
                }
            }
            None => {
                let bytes = count.saturating_mul(elem);
                if bytes > budget {
                    return Err(e(format!(
                        "{count} elements without a bufferView would take {bytes} bytes, more than {budget} for a file this size"
                    )));
                }
            }
        }
        if let Some(s) = &a.sparse {
            if s.count.0 > count {
                return Err(e(format!(
                    "sparse count {} exceeds count {count}",
                    s.count.0
                )));
            }
            let Some(json::accessor::IndexComponentType(ty)) = valid(&s.indices.component_type)
            else {
                return Err(e("sparse indices have an invalid component type".into()));
            };
            if !matches!(
                ty,
                json::accessor::ComponentType::U8
                    | json::accessor::ComponentType::U16
                    | json::accessor::ComponentType::U32
            ) {
                return Err(e(format!(
                    "sparse indices are {ty:?}; glTF 2.0 allows unsigned"
                )));
            }
            for (what, view, size) in [
                ("indices", s.indices.buffer_view, ty.size() as u64),
                ("values", s.values.buffer_view, elem),
            ] {
                let Some(v) = root.buffer_views.get(view.value()) else {
                    return Err(e(format!(
                        "sparse {what} bufferView {} does not exist",
                        view.value()
                    )));
                };
                let offset = match what {
                    "indices" => s.indices.byte_offset.0,
                    _ => s.values.byte_offset.0,
                };
                let need = offset.saturating_add(size.saturating_mul(s.count.0));
                if need > v.byte_length.0 {
                    return Err(e(format!(
                        "sparse {what} need {need} bytes; bufferView {} has {}",
                        view.value(),
                        v.byte_length.0
                    )));
                }
            }
        }
    }
    Ok(())
}

fn check_meshes(
    path: &Path,
    root: &json::Root,
    warnings: &mut Vec<String>,
) -> Result<(), BakeError> {
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let e = |message: String| BakeError::Primitive {
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
fn check_nodes(path: &Path, root: &json::Root) -> Result<u64, BakeError> {
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
    let (visits, triangles) = roots.iter().fold((0u64, 0u64), |acc, &r| {
        let (v, t) = count(root, r, &mut memo, 0);
        (acc.0.saturating_add(v), acc.1.saturating_add(t))
    });
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

fn check_materials(path: &Path, root: &json::Root) -> Result<(), BakeError> {
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
) -> Result<(), BakeError> {
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

/// Decodes the images materials sample to 8-bit RGBA (16-bit and float channels are converted
/// by the image crate), with its allocation limit set to [`allocation_budget`] of the image's
/// encoded size: a small file that claims a huge image is refused before it is decoded.
pub fn decode_images(
    path: &Path,
    base: &Path,
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
) -> Result<Vec<Image>, BakeError> {
    // Only what the bake samples: base colour and emissive. Normal, occlusion and
    // metallic-roughness maps are never decoded (they could only fail the bake).
    let mut used = vec![false; doc.images().len()];
    for m in doc.materials() {
        let pbr = m.pbr_metallic_roughness();
        let textures = [
            pbr.base_color_texture().map(|t| t.texture()),
            m.emissive_texture().map(|t| t.texture()),
        ];
        for t in textures.into_iter().flatten() {
            if let Some(u) = used.get_mut(t.source().index()) {
                *u = true;
            }
        }
    }
    doc.images()
        .map(|img| {
            if !used[img.index()] {
                return Ok(Image {
                    width: 1,
                    height: 1,
                    texels: vec![[255; 4]],
                });
            }
            let uri = match img.source() {
                gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => uri.to_owned(),
                gltf::image::Source::Uri { .. } => "data URI".to_owned(),
                gltf::image::Source::View { .. } => "buffer view".to_owned(),
            };
            let fail = |message: String| BakeError::Image {
                path: path.to_owned(),
                index: img.index(),
                uri: uri.clone(),
                message,
            };
            let (bytes, mime) = encoded_image(base, &img, buffers).map_err(&fail)?;
            decode(&bytes, mime.as_deref()).map_err(&fail)
        })
        .collect()
}

/// The encoded bytes of `img` and its MIME type, if stated.
fn encoded_image(
    base: &Path,
    img: &gltf::Image,
    buffers: &[gltf::buffer::Data],
) -> Result<(Vec<u8>, Option<String>), String> {
    match img.source() {
        gltf::image::Source::Uri { uri, mime_type } => {
            if let Some(rest) = uri.strip_prefix("data:") {
                let (meta, payload) = rest.split_once(',').ok_or("a data URI without a comma")?;
                let Some(mime) = meta.strip_suffix(";base64") else {
                    return Err("only base64 data URIs are read".into());
                };
                let bytes =
                    base64::decode(payload).map_err(|e| format!("data URI: base64: {e}"))?;
                let mime = Some(mime).filter(|m| !m.is_empty()).or(mime_type);
                Ok((bytes, mime.map(str::to_owned)))
            } else {
                let file = external_file(base, uri)?;
                let bytes = std::fs::read(&file).map_err(|e| format!("{}: {e}", file.display()))?;
                Ok((bytes, mime_type.map(str::to_owned)))
            }
        }
        gltf::image::Source::View { view, mime_type } => {
            let data = buffers
                .get(view.buffer().index())
                .ok_or("its buffer was not loaded")?;
            let bytes = data
                .0
                .get(view.offset()..view.offset() + view.length())
                .ok_or("its buffer view runs past the buffer")?;
            Ok((bytes.to_vec(), Some(mime_type.to_owned())))
        }
    }
}

fn decode(bytes: &[u8], mime: Option<&str>) -> Result<Image, String> {
    use image::ImageFormat;
    let format = match mime {
        Some("image/png") => ImageFormat::Png,
        Some("image/jpeg") => ImageFormat::Jpeg,
        _ => match image::guess_format(bytes) {
            Ok(f @ (ImageFormat::Png | ImageFormat::Jpeg)) => f,
            _ => return Err(format!("not a PNG or JPEG image (MIME type {mime:?})")),
        },
    };
    let budget = allocation_budget(bytes.len() as u64);
    let reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let (w, h) = reader.into_dimensions().map_err(|e| e.to_string())?;
    let decoded = u64::from(w) * u64::from(h) * 4;
    if decoded > budget {
        return Err(format!(
            "{w} x {h} pixels would take {decoded} bytes decoded from {} encoded, more than {budget}",
            bytes.len()
        ));
    }
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(budget);
    reader.limits(limits);
    let rgba = reader.decode().map_err(|e| e.to_string())?.to_rgba8();
    Ok(Image {
        width: w,
        height: h,
        texels: rgba.pixels().map(|p| p.0).collect(),
    })
}
