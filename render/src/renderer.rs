//! The [`Renderer`]: owns the uploaded scene, the three stages' pipelines, the light buffers, the
//! tile lists and the frame's attachments, and records the stages into the caller's encoder.

use prt_bake::scene::Scene;
use prt_format::{Asset, LightKind};
use prt_runtime::contract::{GpuLight, VolumeInfo};
use prt_runtime::gpu::PrtRuntime;
use prt_runtime::lights::PreparedLight;
use wgpu::util::DeviceExt;

use crate::cull::Cull;
use crate::gpu_scene::GpuScene;
use crate::layout::*;
use crate::raster::{self, PassPipelines, COLOR_FORMAT, DEPTH_FORMAT, TARGETS};
use crate::{Camera, Culling, RenderError, RenderSettings, View};

mod readback;

/// A frame read back: per pixel (row-major, top row first) linear radiance with the number of
/// lights evaluated in alpha, world position (w = 1 where geometry was drawn, 0 for background)
/// and shading normal.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub radiance: Vec<[f32; 4]>,
    pub position: Vec<[f32; 4]>,
    pub normal: Vec<[f32; 4]>,
    pub stats: CullStats,
}

/// Render targets of one size.
struct Targets {
    depth: wgpu::TextureView,
    colors: Vec<(wgpu::Texture, wgpu::TextureView)>,
}

/// The tiled Forward+ renderer.
pub struct Renderer {
    settings: RenderSettings,
    scene: GpuScene,
    cull: Cull,
    depth_pipelines: PassPipelines,
    shade_pipelines: PassPipelines,
    volume_layout: wgpu::BindGroupLayout,
    frame: wgpu::Buffer,
    tile_lists: wgpu::Buffer,
    stats: wgpu::Buffer,
    targets: Targets,
    cull_group: wgpu::BindGroup,
    shade_group: wgpu::BindGroup,
    bvh_group: wgpu::BindGroup,
    directional: wgpu::Buffer,
    others: wgpu::Buffer,
    light_counts: (u32, u32),
    tiles: (u32, u32),
    /// The asset's probe spacing: the scene's length scale for shadow-ray offsets.
    ray_scale: f32,
    /// The volume group of frames without GI: a 1x1x1 volume of validity 0.
    empty_volume: wgpu::BindGroup,
}

fn layout_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty,
        count: None,
    }
}

fn buffer_type(ty: wgpu::BufferBindingType) -> wgpu::BindingType {
    wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    }
}

const RO: wgpu::BufferBindingType = wgpu::BufferBindingType::Storage { read_only: true };

fn bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    resources: Vec<wgpu::BindingResource>,
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = resources
        .into_iter()
        .enumerate()
        .map(|(i, resource)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource,
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout,
        entries: &entries,
    })
}

/// Layouts of the shading pass's groups: 0 frame, lights, tiles, materials; 1 BVH; 2 volume.
fn shade_layouts(device: &wgpu::Device) -> [wgpu::BindGroupLayout; 3] {
    let frag = wgpu::ShaderStages::FRAGMENT;
    let mut g0 = vec![layout_entry(
        0,
        wgpu::ShaderStages::VERTEX | frag,
        buffer_type(wgpu::BufferBindingType::Uniform),
    )];
    g0.extend((1..7).map(|b| layout_entry(b, frag, buffer_type(RO))));
    let g1: Vec<_> = (0..2)
        .map(|b| layout_entry(b, frag, buffer_type(RO)))
        .collect();
    let g2 = PrtRuntime::volume_layout_entries(frag);
    [g0, g1, g2].map(|entries| {
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("prt-render shade"),
            entries: &entries,
        })
    })
}

/// The snippet's bind group over an empty (1x1x1, validity 0) volume, for frames without GI.
fn empty_volume(device: &wgpu::Device, layout: &wgpu::BindGroupLayout) -> wgpu::BindGroup {
    let views: Vec<wgpu::TextureView> = (0..7)
        .map(|_| {
            device
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
                .create_view(&Default::default())
        })
        .collect();
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
    let depth = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("prt-render empty visibility and positions"),
        contents: &[0u8; 4 * prt_format::DEPTH_WORDS],
        usage: wgpu::BufferUsages::STORAGE,
    });
    let mut resources: Vec<wgpu::BindingResource> = views
        .iter()
        .map(wgpu::BindingResource::TextureView)
        .collect();
    resources.push(wgpu::BindingResource::Sampler(&sampler));
    resources.push(info.as_entire_binding());
    resources.push(depth.as_entire_binding());
    resources.push(depth.as_entire_binding());
    bind_group(device, layout, resources)
}

fn targets(device: &wgpu::Device, width: u32, height: u32) -> Targets {
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
struct Buffers {
    frame: wgpu::Buffer,
    directional: wgpu::Buffer,
    others: wgpu::Buffer,
    tile_lists: wgpu::Buffer,
    stats: wgpu::Buffer,
}

/// Creates the frame uniform, the light buffers at full capacity, the tile lists (refused when
/// beyond one storage binding) and the culling counters.
fn buffers(
    device: &wgpu::Device,
    settings: &RenderSettings,
    tiles: (u32, u32),
) -> Result<Buffers, RenderError> {
    let list_bytes = u64::from(tiles.0 * tiles.1) * u64::from(settings.max_lights_per_tile + 1) * 4;
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
fn check_settings(device: &wgpu::Device, s: &RenderSettings) -> Result<(), RenderError> {
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

impl Renderer {
    /// Uploads `scene` (the file `asset` was baked from) and creates the stages.
    pub fn new(
        device: &wgpu::Device,
        scene: &Scene,
        asset: &Asset,
        settings: RenderSettings,
    ) -> Result<Renderer, RenderError> {
        check_settings(device, &settings)?;
        let gpu_scene = GpuScene::new(device, scene, asset)?;
        let tiles = (
            settings.width.div_ceil(settings.tile),
            settings.height.div_ceil(settings.tile),
        );
        let Buffers {
            frame,
            directional,
            others,
            tile_lists,
            stats,
        } = buffers(device, &settings, tiles)?;
        let targets = targets(device, settings.width, settings.height);

        let cull = Cull::new(device);
        let cull_group = bind_group(
            device,
            &cull.layout,
            vec![
                frame.as_entire_binding(),
                others.as_entire_binding(),
                wgpu::BindingResource::TextureView(&targets.depth),
                tile_lists.as_entire_binding(),
                stats.as_entire_binding(),
            ],
        );
        let [g0, g1, g2] = shade_layouts(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("prt-render shade"),
            source: wgpu::ShaderSource::Wgsl(crate::shaders::shade_source().into()),
        });
        let pipeline_layout = |groups: &[Option<&wgpu::BindGroupLayout>]| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("prt-render"),
                bind_group_layouts: groups,
                immediate_size: 0,
            })
        };
        let (depth_pipelines, shade_pipelines) = raster::pipelines(
            device,
            &module,
            &pipeline_layout(&[Some(&g0)]),
            &pipeline_layout(&[Some(&g0), Some(&g1), Some(&g2)]),
        );
        let shade_group = bind_group(
            device,
            &g0,
            vec![
                frame.as_entire_binding(),
                directional.as_entire_binding(),
                others.as_entire_binding(),
                tile_lists.as_entire_binding(),
                gpu_scene.materials.as_entire_binding(),
                gpu_scene.images.as_entire_binding(),
                gpu_scene.texels.as_entire_binding(),
            ],
        );
        let bvh_group = bind_group(
            device,
            &g1,
            vec![
                gpu_scene.bvh_nodes.as_entire_binding(),
                gpu_scene.bvh_triangles.as_entire_binding(),
            ],
        );
        let empty_volume = empty_volume(device, &g2);
        Ok(Renderer {
            settings,
            scene: gpu_scene,
            cull,
            depth_pipelines,
            shade_pipelines,
            volume_layout: g2,
            frame,
            tile_lists,
            stats,
            targets,
            cull_group,
            shade_group,
            bvh_group,
            directional,
            others,
            light_counts: (0, 0),
            tiles,
            ray_scale: asset.header.grid.spacing,
            empty_volume,
        })
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Tiles across and down.
    pub fn tiles(&self) -> (u32, u32) {
        self.tiles
    }

    /// World bounds of the scene's triangles.
    pub fn bounds(&self) -> (glam::Vec3, glam::Vec3) {
        self.scene.bounds
    }

    /// Uploads the lights: directional ones to their own buffer, point and spot to the culled one
    /// (in rig order, which is the order every pixel sums them in).
    pub fn set_lights(
        &mut self,
        queue: &wgpu::Queue,
        lights: &[prt_format::Light],
    ) -> Result<(), RenderError> {
        let (dir, other): (Vec<GpuLight>, Vec<GpuLight>) = {
            let prepared: Vec<PreparedLight> = lights.iter().map(PreparedLight::new).collect();
            let dir = prepared
                .iter()
                .filter(|l| l.kind == LightKind::Directional)
                .map(GpuLight::from)
                .collect();
            let other = prepared
                .iter()
                .filter(|l| l.kind != LightKind::Directional)
                .map(GpuLight::from)
                .collect();
            (dir, other)
        };
        for (list, kind, max) in [
            (&dir, "directional", MAX_DIRECTIONAL_LIGHTS),
            (&other, "point and spot", MAX_OTHER_LIGHTS),
        ] {
            if list.len() > max {
                return Err(RenderError::TooManyLights {
                    count: list.len(),
                    kind,
                    max,
                });
            }
        }
        queue.write_buffer(&self.directional, 0, bytemuck::cast_slice(&dir));
        queue.write_buffer(&self.others, 0, bytemuck::cast_slice(&other));
        self.light_counts = (dir.len() as u32, other.len() as u32);
        Ok(())
    }

    /// Sets the camera and view mode of the next frame.
    pub fn set_camera(
        &self,
        queue: &wgpu::Queue,
        camera: &Camera,
        view: View,
    ) -> Result<(), RenderError> {
        camera.validate()?;
        let s = &self.settings;
        let (lo, hi) = self.scene.bounds;
        let proj = camera.projection(s.width as f32 / s.height as f32, lo, hi);
        let view_m = camera.view();
        let mut flags = 0;
        if s.shadows {
            flags |= FLAG_SHADOWS;
        }
        if s.culling == Culling::Tiled {
            flags |= FLAG_TILED;
        }
        let uniform = FrameUniform {
            view_proj: (proj * view_m).to_cols_array_2d(),
            view: view_m.to_cols_array_2d(),
            inv_proj: proj.inverse().to_cols_array_2d(),
            eye: camera.eye.to_array(),
            mode: match view {
                View::Lit => MODE_LIT,
                View::Direct => MODE_DIRECT,
                View::Indirect => MODE_INDIRECT,
                View::Albedo => MODE_ALBEDO,
            },
            width: s.width,
            height: s.height,
            tile: s.tile,
            tiles_x: self.tiles.0,
            tiles_y: self.tiles.1,
            max_per_tile: s.max_lights_per_tile,
            other_count: self.light_counts.1,
            directional_count: self.light_counts.0,
            flags,
            ray_scale: self.ray_scale,
            _pad: [0; 2],
        };
        queue.write_buffer(&self.frame, 0, bytemuck::bytes_of(&uniform));
        Ok(())
    }

    /// The depth buffer as an attachment, cleared (pre-pass) or loaded (shading).
    fn depth_attachment(
        &self,
        load: wgpu::LoadOp<f32>,
    ) -> wgpu::RenderPassDepthStencilAttachment<'_> {
        wgpu::RenderPassDepthStencilAttachment {
            view: &self.targets.depth,
            depth_ops: Some(wgpu::Operations {
                load,
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }
    }

    /// Stage 1: the depth pre-pass.
    pub fn record_depth(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("prt-render depth pre-pass"),
            color_attachments: &[],
            depth_stencil_attachment: Some(self.depth_attachment(wgpu::LoadOp::Clear(1.0))),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.shade_group, &[]);
        pass.set_vertex_buffer(0, self.scene.vertices.slice(..));
        raster::draw(
            &mut pass,
            &self.depth_pipelines,
            self.scene.single_sided_vertices,
            self.scene.vertex_count,
        );
    }

    /// Stage 2: tiled light culling (nothing with [`Culling::None`]).
    pub fn record_cull(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.stats, 0, None);
        if self.settings.culling == Culling::Tiled {
            self.cull.record(encoder, &self.cull_group, self.tiles);
        }
    }

    /// The shading pass's bind group over `gi`'s volume: make it once per runtime and pass it
    /// to [`Renderer::record`] every frame.
    pub fn volume_group(&self, gi: &PrtRuntime) -> wgpu::BindGroup {
        gi.volume_bind_group(&self.volume_layout)
    }

    /// Stage 3: shading, with indirect light from `volume` ([`Renderer::volume_group`]; none:
    /// indirect is zero).
    pub fn record_shade(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        volume: Option<&wgpu::BindGroup>,
    ) {
        let volume_group = volume.unwrap_or(&self.empty_volume);
        let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = self
            .targets
            .colors
            .iter()
            .map(|(_, view)| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            })
            .collect();
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("prt-render shade"),
            color_attachments: &attachments,
            depth_stencil_attachment: Some(self.depth_attachment(wgpu::LoadOp::Load)),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.shade_group, &[]);
        pass.set_bind_group(1, &self.bvh_group, &[]);
        pass.set_bind_group(2, volume_group, &[]);
        pass.set_vertex_buffer(0, self.scene.vertices.slice(..));
        raster::draw(
            &mut pass,
            &self.shade_pipelines,
            self.scene.single_sided_vertices,
            self.scene.vertex_count,
        );
    }

    /// All three stages.
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder, volume: Option<&wgpu::BindGroup>) {
        self.record_depth(encoder);
        self.record_cull(encoder);
        self.record_shade(encoder, volume);
    }

    /// Point and spot lights uploaded.
    pub fn light_counts(&self) -> (u32, u32) {
        self.light_counts
    }
}
