//! The renderer's GPU resources of one size and settings: attachments, buffers, and the
//! stand-in volume of frames without GI; and which of them each WGSL variable binds
//! ([`bound`]).

use prt_runtime::contract::{GpuLight, VolumeInfo};
use wgpu::util::DeviceExt;

use crate::bindings::{Resource, StageBindings};
use crate::gpu_scene::GpuScene;
use crate::layout::*;
use crate::raster::{COLOR_FORMAT, DEPTH_FORMAT, TARGETS};
use crate::shaders::VOLUME_GROUP;
use crate::{RenderError, RenderSettings};

/// Render targets of one size.
pub(super) struct Targets {
    pub depth: wgpu::TextureView,
    pub colors: Vec<(wgpu::Texture, wgpu::TextureView)>,
}

pub(super) fn targets(device: &wgpu::Device, width: u32, height: u32) -> Targets {
    let size = wgpu::Extent3d {
        width,
        height,
        depth_or_array_layers: 1,
    };
    let texture = |format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("prt-render target"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let depth = texture(
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    )
    .create_view(&Default::default());
    let colors = (0..TARGETS)
        .map(|_| {
            let t = texture(
                COLOR_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            );
            let v = t.create_view(&Default::default());
            (t, v)
        })
        .collect();
    Targets { depth, colors }
}

/// The renderer's own buffers.
pub(super) struct Buffers {
    pub frame: wgpu::Buffer,
    pub directional: wgpu::Buffer,
    pub others: wgpu::Buffer,
    pub tile_lists: wgpu::Buffer,
    pub stats: wgpu::Buffer,
}

/// Creates the frame uniform, the light buffers at full capacity, the tile lists (refused when
/// beyond one storage binding) and the culling counters.
pub(super) fn buffers(
    device: &wgpu::Device,
    settings: &RenderSettings,
    tiles: (u32, u32),
) -> Result<Buffers, RenderError> {
    let list_bytes =
        u64::from(tiles.0 * tiles.1) * u64::from(tile_list_words(settings.max_lights_per_tile)) * 4;
    let max_binding = device.limits().max_storage_buffer_binding_size;
    if list_bytes > max_binding {
        return Err(RenderError::Limit {
            what: "the tile light lists",
            needed: list_bytes,
            limit: max_binding,
        });
    }
    let buffer = |label, size: u64, usage| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    };
    let copy = wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC;
    let light_size = std::mem::size_of::<GpuLight>() as u64;
    let storage = wgpu::BufferUsages::STORAGE | copy;
    Ok(Buffers {
        frame: buffer(
            "prt-render frame",
            std::mem::size_of::<FrameUniform>() as u64,
            wgpu::BufferUsages::UNIFORM | copy,
        ),
        directional: buffer(
            "prt-render directional lights",
            light_size * MAX_DIRECTIONAL_LIGHTS as u64,
            storage,
        ),
        others: buffer(
            "prt-render lights",
            light_size * MAX_OTHER_LIGHTS as u64,
            storage,
        ),
        tile_lists: buffer("prt-render tile lists", list_bytes, storage),
        stats: buffer(
            "prt-render cull stats",
            std::mem::size_of::<CullStats>() as u64,
            storage,
        ),
    })
}

/// Checks size, tile and list settings against the device.
pub(super) fn check_settings(device: &wgpu::Device, s: &RenderSettings) -> Result<(), RenderError> {
    let max = device.limits().max_texture_dimension_2d;
    if s.width == 0 || s.height == 0 || s.width > max || s.height > max {
        return Err(RenderError::Size {
            width: s.width,
            height: s.height,
            why: format!("each side must be 1 to {max} pixels (the device's 2D texture limit)"),
        });
    }
    if !(16..=256).contains(&s.tile) {
        return Err(RenderError::Tile(s.tile));
    }
    if s.max_lights_per_tile == 0 || s.max_lights_per_tile as usize > MAX_OTHER_LIGHTS {
        return Err(RenderError::MaxPerTile(s.max_lights_per_tile));
    }
    Ok(())
}

/// What each of the renderer's WGSL variables binds to.
pub(super) fn bound<'a>(
    r: Resource,
    buffers: &'a Buffers,
    scene: &'a GpuScene,
    targets: &'a Targets,
) -> wgpu::BindingResource<'a> {
    let b = |buffer: &'a wgpu::Buffer| buffer.as_entire_binding();
    match r {
        Resource::Frame => b(&buffers.frame),
        Resource::DirectionalLights => b(&buffers.directional),
        Resource::Lights => b(&buffers.others),
        Resource::TileLists => b(&buffers.tile_lists),
        Resource::CullStats => b(&buffers.stats),
        Resource::Depth => wgpu::BindingResource::TextureView(&targets.depth),
        Resource::Materials => b(&scene.materials),
        Resource::Images => b(&scene.images),
        Resource::Texels => b(&scene.texels),
        Resource::BvhNodes => b(&scene.bvh_nodes),
        Resource::BvhTriangles => b(&scene.bvh_triangles),
    }
}

/// The runtime snippet's bind group ([`VOLUME_GROUP`]) over an empty volume, for frames
/// without GI: each binding gets a stand-in of its type (a 1x1x1 texture, a sampler, zeroed
/// storage, and a uniform describing a one-probe grid), so every probe has validity 0 and
/// indirect light is zero.
pub(super) fn empty_volume(
    device: &wgpu::Device,
    bindings: &StageBindings,
) -> Result<wgpu::BindGroup, RenderError> {
    let view = device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("prt-render empty volume"),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default());
    let sampler = device.create_sampler(&Default::default());
    let info = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("prt-render empty volume info"),
        contents: bytemuck::bytes_of(&VolumeInfo {
            counts: [1.0; 3],
            spacing: 1.0,
            step: [1.0; 3],
            ..VolumeInfo::default()
        }),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let zeros = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("prt-render empty visibility and positions"),
        contents: &[0u8; 4 * prt_format::DEPTH_WORDS],
        usage: wgpu::BufferUsages::STORAGE,
    });
    bindings.bind_group(device, VOLUME_GROUP, |d| match d.ty {
        wgpu::BindingType::Texture {
            view_dimension: wgpu::TextureViewDimension::D3,
            ..
        } => Ok(wgpu::BindingResource::TextureView(&view)),
        wgpu::BindingType::Sampler(_) => Ok(wgpu::BindingResource::Sampler(&sampler)),
        wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            ..
        } => Ok(info.as_entire_binding()),
        wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { .. },
            ..
        } => Ok(zeros.as_entire_binding()),
        ty => Err(RenderError::Shader {
            label: "prt-render empty volume",
            message: format!("no stand-in for `{}` ({ty:?})", d.name),
        }),
    })
}
