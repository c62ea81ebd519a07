//! Reading a checked glTF 2.0 document into flat world-space triangles with their materials and
//! lights ([`crate::read`]).
//!
//! - The default scene (else the first; else every root node) with nested node transforms (TRS or
//!   matrix). A transform with a negative determinant flips triangle winding, so front faces stay
//!   the faces the author saw as front (glTF 2.0 spec, 3.7.4 "Transformations").
//! - TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN primitives, indexed or not; points and lines are
//!   skipped with a warning.
//! - Per material: base colour factor, base colour texture with its UV set and sampler, COLOR_0,
//!   doubleSided, emissive factor x texture x KHR_materials_emissive_strength. A primitive without
//!   material gets the glTF default (white, single-sided, no emission).
//! - KHR_lights_punctual lights, placed by their nodes (light looks along the node's -Z).
//!
//! Bad input the document checks cannot see (buffers that changed since, indices past the
//! vertices, non-finite positions) is a [`SceneError`] naming the file, item and value;
//! degenerate (zero-area) triangles are skipped and counted.

use std::path::Path;

use glam::{Mat4, Vec3};
use gltf::mesh::Mode;
use prt_format::{Light, LightKind};
use rayon::prelude::*;

use crate::check::{self, Findings};
use crate::error::SceneError;
use crate::files;
use crate::scene::{Camera, Material, Scene, TriangleAttributes};
use crate::texture::{self, is_nearest, TextureRef};

mod accessors;

use accessors::{
    triangulate, vertex_attributes, vertex_indices, world_positions, VertexAttributes,
};

struct Loader<'a> {
    path: &'a Path,
    buffers: Vec<gltf::buffer::Data>,
    scene: Scene,
    /// Index of the default material in `scene.materials`.
    default_material: u32,
}

/// The nodes the scene is read from: the default scene's roots (or the first scene's), or
/// without scenes every node that is no other's child.
fn root_nodes(doc: &gltf::Document) -> Vec<gltf::Node<'_>> {
    match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    }
}

/// The scene of the checked document `doc` (its binary chunk `blob`; data and external files
/// as `findings` found them; relative paths resolved against `base`), with the document's
/// warnings.
pub(crate) fn read_scene(
    path: &Path,
    base: &Path,
    doc: &gltf::Document,
    blob: Option<Vec<u8>>,
    findings: Findings,
) -> Result<Scene, SceneError> {
    let json = doc.as_json();
    let buffers = read_buffers(path, base, doc, blob, &findings.files.buffers)?;
    check::check_sparse(path, json, &buffers)?;
    let images = texture::decode_images(path, doc, &findings.files.images, &buffers)?;
    let mut warnings = findings.warnings;

    let mut materials: Vec<Material> = doc.materials().map(|m| material(&m)).collect();
    for (i, m) in materials.iter().enumerate() {
        for tex in [&m.base_texture, &m.emissive_texture].into_iter().flatten() {
            if tex.tex_coord > 1 {
                warnings.push(format!(
                    "material {i}: TEXCOORD_{} is not read; TEXCOORD_1 is used instead",
                    tex.tex_coord
                ));
            }
        }
    }
    let default_material = materials.len() as u32;
    materials.push(Material::default());
    let mut loader = Loader {
        path,
        buffers,
        scene: Scene {
            materials,
            images,
            warnings,
            ..Scene::default()
        },
        default_material,
    };
    for node in root_nodes(doc) {
        loader.visit(&node, Mat4::IDENTITY, 0)?;
    }
    Ok(loader.scene)
}

/// The document's buffers: external ones from the checked `files` ([`files::read_buffer`]),
/// data URIs and the binary chunk `blob` as the gltf crate's importer reads them.
fn read_buffers(
    path: &Path,
    base: &Path,
    doc: &gltf::Document,
    mut blob: Option<Vec<u8>>,
    files: &[Option<std::path::PathBuf>],
) -> Result<Vec<gltf::buffer::Data>, SceneError> {
    doc.buffers()
        .map(
            |b| match (b.source(), files.get(b.index()).and_then(Option::as_ref)) {
                (gltf::buffer::Source::Uri(uri), Some(file)) => {
                    files::read_buffer(path, b.index(), uri, file, b.length())
                }
                (source, _) => {
                    let gltf_err = |e: gltf::Error| SceneError::Gltf {
                        path: path.to_owned(),
                        message: format!("buffers: {e}"),
                    };
                    let data =
                        gltf::buffer::Data::from_source_and_blob(source, Some(base), &mut blob)
                            .map_err(gltf_err)?;
                    if data.len() < b.length() {
                        return Err(gltf_err(gltf::Error::BufferLength {
                            buffer: b.index(),
                            expected: b.length(),
                            actual: data.len(),
                        }));
                    }
                    Ok(data)
                }
            },
        )
        .collect()
}

fn texture_ref(tex: gltf::Texture, tex_coord: u32) -> TextureRef {
    let sampler = tex.sampler();
    TextureRef {
        image: tex.source().index(),
        tex_coord,
        wrap_s: sampler.wrap_s(),
        wrap_t: sampler.wrap_t(),
        nearest: is_nearest(sampler.mag_filter()),
    }
}

fn material(m: &gltf::Material) -> Material {
    let pbr = m.pbr_metallic_roughness();
    let f = pbr.base_color_factor();
    let strength = m.emissive_strength().unwrap_or(1.0);
    Material {
        base_color: [f[0], f[1], f[2]],
        base_texture: pbr
            .base_color_texture()
            .map(|t| texture_ref(t.texture(), t.tex_coord())),
        emissive: m.emissive_factor().map(|e| e * strength),
        emissive_texture: m
            .emissive_texture()
            .map(|t| texture_ref(t.texture(), t.tex_coord())),
        double_sided: m.double_sided(),
    }
}

/// Checks what the gltf crate's readers assume about each attribute it reads (glTF 2.0 spec,
/// 3.7.2.1 "Meshes", attribute table) before they read it: they panic on other formats
/// (`unreachable!`) instead of returning an error.
fn check_accessor_formats(prim: &gltf::Primitive) -> Result<(), String> {
    use gltf::accessor::{DataType, Dimensions};
    let describe = |a: &gltf::Accessor| {
        format!(
            "accessor {} is {:?} {:?}{}",
            a.index(),
            a.dimensions(),
            a.data_type(),
            if a.normalized() { " normalized" } else { "" }
        )
    };
    for (semantic, a) in prim.attributes() {
        let (dims, ty, norm) = (a.dimensions(), a.data_type(), a.normalized());
        let ok = match &semantic {
            gltf::Semantic::Positions => dims == Dimensions::Vec3 && ty == DataType::F32,
            gltf::Semantic::TexCoords(_) => {
                dims == Dimensions::Vec2
                    && (ty == DataType::F32 || (norm && matches!(ty, DataType::U8 | DataType::U16)))
            }
            gltf::Semantic::Colors(_) => {
                matches!(dims, Dimensions::Vec3 | Dimensions::Vec4)
                    && (ty == DataType::F32 || (norm && matches!(ty, DataType::U8 | DataType::U16)))
            }
            _ => true,
        };
        if !ok {
            return Err(format!(
                "attribute {semantic:?}: {} (glTF 2.0 allows {})",
                describe(&a),
                match semantic {
                    gltf::Semantic::Positions => "VEC3 FLOAT",
                    gltf::Semantic::TexCoords(_) =>
                        "VEC2 FLOAT, or normalized UNSIGNED_BYTE/UNSIGNED_SHORT",
                    _ => "VEC3/VEC4 FLOAT, or normalized UNSIGNED_BYTE/UNSIGNED_SHORT",
                }
            ));
        }
    }
    if let Some(a) = prim.indices() {
        if a.dimensions() != Dimensions::Scalar
            || !matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(format!(
                "indices: {} (glTF 2.0 allows SCALAR UNSIGNED_BYTE/SHORT/INT)",
                describe(&a)
            ));
        }
    }
    Ok(())
}

/// Glam matrix of a node's local transform.
fn local_transform(node: &gltf::Node) -> Mat4 {
    Mat4::from_cols_array_2d(&node.transform().matrix())
}

impl Loader<'_> {
    fn visit(&mut self, node: &gltf::Node, parent: Mat4, depth: u32) -> Result<(), SceneError> {
        if depth > 256 {
            return Err(SceneError::Gltf {
                path: self.path.to_owned(),
                message: format!("node {} is nested more than 256 deep", node.index()),
            });
        }
        let world = parent * local_transform(node);
        if let Some(mesh) = node.mesh() {
            self.mesh(&mesh, world)?;
        }
        if let Some(light) = node.light() {
            self.light(&light, world);
        }
        let camera = node.camera();
        if let Some(gltf::camera::Projection::Perspective(p)) =
            camera.as_ref().map(|c| c.projection())
        {
            let forward = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
            let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
            if forward != Vec3::ZERO && up != Vec3::ZERO && p.yfov().is_finite() {
                self.scene.cameras.push(Camera {
                    eye: world.transform_point3(Vec3::ZERO),
                    forward,
                    up,
                    yfov: p.yfov(),
                });
            }
        }
        for child in node.children() {
            self.visit(&child, world, depth + 1)?;
        }
        Ok(())
    }

    fn light(&mut self, light: &gltf::khr_lights_punctual::Light, world: Mat4) {
        use gltf::khr_lights_punctual::Kind;
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world
            .transform_vector3(Vec3::NEG_Z)
            .normalize_or(Vec3::NEG_Z);
        let (kind, inner, outer) = match light.kind() {
            Kind::Directional => (LightKind::Directional, 0.0, std::f32::consts::FRAC_PI_4),
            Kind::Point => (LightKind::Point, 0.0, std::f32::consts::FRAC_PI_4),
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => (LightKind::Spot, inner_cone_angle, outer_cone_angle),
        };
        let l = Light {
            kind,
            position: position.to_array(),
            direction: direction.to_array(),
            color: light.color(),
            intensity: light.intensity(),
            range: light.range(),
            inner_cone_angle: inner,
            outer_cone_angle: outer,
        };
        match l.validate(self.scene.lights.len()) {
            Ok(()) => self.scene.lights.push(l),
            Err(e) => self.scene.warnings.push(format!(
                "KHR_lights_punctual light {} skipped: {e}",
                light.index()
            )),
        }
    }

    fn mesh(&mut self, mesh: &gltf::Mesh, world: Mat4) -> Result<(), SceneError> {
        let mesh_name = match mesh.name() {
            Some(n) => format!("{} ({n:?})", mesh.index()),
            None => mesh.index().to_string(),
        };
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                self.scene.warnings.push(format!(
                    "mesh {mesh_name} primitive {}: {mode:?} skipped (only triangles are baked)",
                    prim.index()
                ));
                continue;
            }
            self.primitive(&prim, world)
                .map_err(|message| SceneError::Primitive {
                    path: self.path.to_owned(),
                    mesh: mesh_name.clone(),
                    primitive: prim.index(),
                    message,
                })?;
        }
        Ok(())
    }

    /// Adds the triangles of a primitive of triangles (a list, strip or fan) placed by `world`;
    /// fails with what is wrong with its data.
    fn primitive(&mut self, prim: &gltf::Primitive, world: Mat4) -> Result<(), String> {
        check_accessor_formats(prim)?;
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions = world_positions(prim, &reader, buffers, world)?;
        let vertex_count = positions.len();
        if let Some((v, p)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(format!("vertex {v} has non-finite position {p}"));
        }
        let indices = vertex_indices(prim, &reader, buffers, vertex_count)?;
        let tris = triangulate(prim.mode(), &indices);
        let material = match prim.material().index() {
            Some(m) => m as u32,
            None => self.default_material,
        };
        let textured = self
            .scene
            .materials
            .get(material as usize)
            .is_some_and(|m| m.base_texture.is_some() || m.emissive_texture.is_some());
        let attributes = vertex_attributes(&reader, vertex_count, textured)?;
        self.scene.has_vertex_colors |= attributes.1.is_some();
        // Attributes from the first primitive that needs them on (shading reads them for
        // every triangle once any primitive has COLOR_0), the triangles before it given the
        // defaults (white, no texture coordinates).
        let keep_attributes =
            textured || self.scene.has_vertex_colors || !self.scene.attributes.is_empty();
        if keep_attributes {
            let before = self.scene.triangles.len();
            self.scene
                .attributes
                .resize(before, TriangleAttributes::WHITE);
        }
        let attributes = keep_attributes.then_some(&attributes);
        let flip = world.determinant() < 0.0;
        self.add_triangles(&tris, &positions, flip, material, attributes);
        Ok(())
    }

    /// Appends a primitive's triangles (vertex indices `tris` into `positions`, corners 1 and 2
    /// swapped where `flip`) with their material and, when given, their vertex attributes,
    /// skipping degenerate ones. The corners are gathered in parallel straight into one vector
    /// (an indexed collect), which becomes the scene's when it is the first primitive: pushed
    /// one by one, a large primitive's growing vectors page-fault on one thread while the others
    /// idle (docs/results/bake_notes.md).
    fn add_triangles(
        &mut self,
        tris: &[[u32; 3]],
        positions: &[Vec3],
        flip: bool,
        material: u32,
        attributes: Option<&VertexAttributes>,
    ) {
        let order = |t: [u32; 3]| if flip { [t[0], t[2], t[1]] } else { t };
        let degenerate =
            |v: &[Vec3; 3]| (v[1] - v[0]).cross(v[2] - v[0]).length_squared() <= f32::MIN_POSITIVE;
        let mut corners: Vec<[Vec3; 3]> = tris
            .par_iter()
            .map(|&t| order(t).map(|i| positions[i as usize]))
            .collect();
        if let Some((uvs, colors)) = attributes {
            self.scene.attributes.reserve(corners.len());
            let white = TriangleAttributes::WHITE;
            let kept = tris.iter().zip(&corners).filter(|(_, v)| !degenerate(v));
            self.scene.attributes.extend(kept.map(|(&t, _)| {
                let t = order(t);
                TriangleAttributes {
                    uv: std::array::from_fn(|set| match &uvs[set] {
                        Some(u) => t.map(|i| u[i as usize]),
                        None => white.uv[set],
                    }),
                    color: match colors {
                        Some(c) => t.map(|i| c[i as usize]),
                        None => white.color,
                    },
                }
            }));
        }
        let all = corners.len();
        corners.retain(|v| !degenerate(v));
        self.scene.degenerate_skipped += (all - corners.len()) as u64;
        if self.scene.triangles.is_empty() {
            self.scene.triangles = corners;
        } else {
            self.scene.triangles.extend_from_slice(&corners);
        }
        let count = self.scene.triangles.len();
        self.scene.materials_of_triangles.resize(count, material);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    /// A glTF of two one-triangle primitives, primitive `colored` (if any) with COLOR_0, the
    /// first one's triangle degenerate (collinear corners) when `degenerate`.
    fn two_primitives(colored: Option<usize>, degenerate: bool) -> Vec<u8> {
        let mut buffer: Vec<u8> = Vec::new();
        let first = if degenerate {
            [2.0f32, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let corners = [
            [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], first],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
        ];
        for c in corners.as_flattened() {
            for x in c {
                buffer.extend(x.to_le_bytes());
            }
        }
        for _ in 0..3 {
            for x in [0.25f32, 0.5, 0.75, 1.0] {
                buffer.extend(x.to_le_bytes());
            }
        }
        let color = |p| {
            if colored == Some(p) {
                r#","COLOR_0":2"#
            } else {
                ""
            }
        };
        let (c0, c1) = (color(0), color(1));
        let max0 = if degenerate { "[2,0,0]" } else { "[1,1,0]" };
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0{c0}}}}},
                {{"attributes":{{"POSITION":1{c1}}}}}]}}],
            "buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}],
            "bufferViews":[{{"buffer":0,"byteLength":72}},
                {{"buffer":0,"byteOffset":72,"byteLength":48}}],
            "accessors":[
                {{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                  "min":[0,0,0],"max":{max0}}},
                {{"bufferView":0,"byteOffset":36,"componentType":5126,"count":3,"type":"VEC3",
                  "min":[0,0,1],"max":[1,1,1]}},
                {{"bufferView":1,"componentType":5126,"count":3,"type":"VEC4"}}]}}"#,
            buffer.len(),
            base64::encode(&buffer)
        )
        .into_bytes()
    }

    /// Triangle attributes are kept only when shading reads them, and then for every triangle:
    /// the primitive before the first that needs them gets the defaults (white), and a scene
    /// with COLOR_0 keeps them even when the primitive that has it leaves no triangle.
    #[test]
    fn attributes_are_kept_for_every_triangle_or_none() {
        let path = Path::new("two_primitives.gltf");
        let load = |colored, degenerate| {
            crate::load_bytes(
                path,
                &two_primitives(colored, degenerate),
                &crate::Allowed::default(),
            )
        };
        let plain = load(None, false).unwrap();
        assert_eq!(plain.triangles.len(), 2);
        assert!(plain.attributes.is_empty() && !plain.has_vertex_colors);
        let colored = load(Some(1), false).unwrap();
        assert!(colored.has_vertex_colors);
        let colors: Vec<[Vec4; 3]> = colored.attributes.iter().map(|a| a.color).collect();
        assert_eq!(
            colors,
            [[Vec4::ONE; 3], [Vec4::new(0.25, 0.5, 0.75, 1.0); 3]]
        );
        let lost = load(Some(0), true).unwrap();
        assert_eq!((lost.triangles.len(), lost.degenerate_skipped), (1, 1));
        assert!(lost.has_vertex_colors);
        let colors: Vec<[Vec4; 3]> = lost.attributes.iter().map(|a| a.color).collect();
        assert_eq!(colors, [[Vec4::ONE; 3]]);
    }
}
