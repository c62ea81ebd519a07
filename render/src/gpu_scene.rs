//! The scene on the GPU: the scene as the bake loads it (`prt_scene`: the same triangles,
//! materials and textures) as a flat-shaded triangle list, materials and texels in storage
//! buffers (so that the shading pass samples textures exactly as `prt_scene::texture::sample`
//! does for the bake), and the asset's BVH for shadow rays.
//!
//! Single-sided triangles come first and are drawn with back-face culling; double-sided ones
//! follow and are drawn without it (glTF 2.0 spec 3.9.5, docs/conventions.md section 4).

use glam::Vec3;
use gltf::texture::WrappingMode;
use prt_format::Asset;
use prt_scene::{Scene, TextureRef, TriangleAttributes};

use crate::layout::*;
use crate::RenderError;

/// The uploaded scene.
pub struct GpuScene {
    pub vertices: wgpu::Buffer,
    /// Vertices of single-sided triangles (drawn culled); the rest are double-sided.
    pub single_sided_vertices: u32,
    pub vertex_count: u32,
    pub materials: wgpu::Buffer,
    pub images: wgpu::Buffer,
    pub texels: wgpu::Buffer,
    pub bvh_nodes: wgpu::Buffer,
    pub bvh_triangles: wgpu::Buffer,
    /// World bounds of the triangles.
    pub bounds: (Vec3, Vec3),
}

fn wrap_code(w: WrappingMode) -> u32 {
    match w {
        WrappingMode::Repeat => WRAP_REPEAT,
        WrappingMode::ClampToEdge => WRAP_CLAMP,
        WrappingMode::MirroredRepeat => WRAP_MIRROR,
    }
}

fn sampler_bits(t: &TextureRef) -> u32 {
    wrap_code(t.wrap_s)
        | (wrap_code(t.wrap_t) << 2)
        | if t.nearest { SAMPLER_NEAREST } else { 0 }
        | if t.tex_coord >= 1 { SAMPLER_UV1 } else { 0 }
}

/// Vertices in draw order (single-sided first) and how many are single-sided.
fn vertices(scene: &Scene, double_sided_override: bool) -> (Vec<Vertex>, u32) {
    let mut single = Vec::new();
    let mut double = Vec::new();
    for (t, tri) in scene.triangles.iter().enumerate() {
        let material = scene.materials_of_triangles[t];
        let two = double_sided_override || scene.materials[material as usize].double_sided;
        let normal = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
        // Without attributes: UV 0 and white vertex colour (COLOR_0 absent).
        let attr = scene
            .attributes
            .get(t)
            .copied()
            .unwrap_or(TriangleAttributes {
                uv: Default::default(),
                color: [glam::Vec4::ONE; 3],
            });
        let out = if two { &mut double } else { &mut single };
        for (k, corner) in tri.iter().enumerate() {
            out.push(Vertex {
                position: corner.to_array(),
                material,
                normal: normal.to_array(),
                _pad: 0,
                uv0: attr.uv[0][k].to_array(),
                uv1: attr.uv[1][k].to_array(),
                color: attr.color[k].to_array(),
            });
        }
    }
    let n = single.len() as u32;
    single.extend(double);
    (single, n)
}

/// Fails unless the scene has triangles, one attribute record per triangle (or none), and the
/// asset a BVH the shadow-ray traversal can walk.
fn check(scene: &Scene, asset: &Asset) -> Result<(Vec3, Vec3), RenderError> {
    let bounds = scene.bounds().ok_or(RenderError::NoTriangles)?;
    if scene.attributes.len() != scene.triangles.len() && !scene.attributes.is_empty() {
        return Err(RenderError::Scene(format!(
            "{} triangles but {} attribute records",
            scene.triangles.len(),
            scene.attributes.len()
        )));
    }
    let needed = asset.geometry.stack_needed();
    if needed > prt_runtime::contract::MAX_STACK || asset.geometry.nodes.is_empty() {
        return Err(RenderError::Scene(format!(
            "the asset's BVH needs a traversal stack of {needed} entries (at most {}) and at least one node",
            prt_runtime::contract::MAX_STACK
        )));
    }
    Ok(bounds)
}

/// Every image's place in the texel buffer, and the texels (RGBA8, one word each).
fn image_texels(scene: &Scene) -> (Vec<ImageInfo>, Vec<u32>) {
    let mut images = Vec::with_capacity(scene.images.len().max(1));
    let mut texels: Vec<u32> = Vec::new();
    for img in &scene.images {
        images.push(ImageInfo {
            offset: texels.len() as u32,
            width: img.width,
            height: img.height,
            _pad: 0,
        });
        texels.extend(img.texels.iter().map(|t| u32::from_le_bytes(*t)));
    }
    (images, texels)
}

/// The scene's materials as the shading pass reads them.
fn gpu_materials(scene: &Scene) -> Vec<GpuMaterial> {
    let texture = |t: &Option<TextureRef>| {
        t.as_ref()
            .map_or((NO_IMAGE, 0), |t| (t.image as u32, sampler_bits(t)))
    };
    scene
        .materials
        .iter()
        .map(|m| {
            let (base_image, base_sampler) = texture(&m.base_texture);
            let (emissive_image, emissive_sampler) = texture(&m.emissive_texture);
            GpuMaterial {
                base_color: m.base_color,
                flags: u32::from(m.double_sided),
                emissive: m.emissive,
                base_image,
                base_sampler,
                emissive_image,
                emissive_sampler,
                _pad: 0,
            }
        })
        .collect()
}

impl GpuScene {
    /// Uploads `scene` (loaded from the file `asset` was baked from) and the asset's BVH.
    pub fn new(
        device: &wgpu::Device,
        scene: &Scene,
        asset: &Asset,
    ) -> Result<GpuScene, RenderError> {
        let bounds = check(scene, asset)?;
        let (verts, single) = vertices(scene, asset.header.settings.double_sided_override);
        let (images, texels) = image_texels(scene);
        let materials = gpu_materials(scene);
        let limits = device.limits();
        // The vertex buffer is bound as a vertex buffer, the rest as storage bindings.
        let create = |label, bytes: &[u8], usage: wgpu::BufferUsages| {
            let limit = if usage == wgpu::BufferUsages::VERTEX {
                limits.max_buffer_size
            } else {
                limits.max_storage_buffer_binding_size
            };
            prt_runtime::gpu::resources::buffer_with(device, label, bytes, usage, limit)
        };
        let storage = wgpu::BufferUsages::STORAGE;
        Ok(GpuScene {
            vertices: create(
                "prt-render vertices",
                bytemuck::cast_slice(&verts),
                wgpu::BufferUsages::VERTEX,
            )?,
            single_sided_vertices: single,
            vertex_count: verts.len() as u32,
            materials: create(
                "prt-render materials",
                bytemuck::cast_slice(&materials),
                storage,
            )?,
            images: create("prt-render images", bytemuck::cast_slice(&images), storage)?,
            texels: create("prt-render texels", bytemuck::cast_slice(&texels), storage)?,
            bvh_nodes: create(
                "prt-render bvh nodes",
                bytemuck::cast_slice(&asset.geometry.nodes),
                storage,
            )?,
            bvh_triangles: create(
                "prt-render bvh triangles",
                bytemuck::cast_slice(&asset.geometry.triangles),
                storage,
            )?,
            bounds,
        })
    }
}
