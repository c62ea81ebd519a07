//! The [`Renderer`]: owns the uploaded scene, the three stages' pipelines, the light buffers, the
//! tile lists and the frame's attachments, and records the stages into the caller's encoder, one
//! pass or dispatch per stage ([`Renderer::record_depth`], [`Renderer::record_cull`],
//! [`Renderer::record_shade`]) so an engine can interleave its own work or time each one.
//!
//! Every resource is created once, at full capacity ([`crate::layout::MAX_OTHER_LIGHTS`] point
//! and spot lights, the tile lists of the frame size): changing lights or the camera is a buffer
//! write, never a reallocation or a new bind group. The GI arrives as a bind group over the runtime's volume
//! ([`Renderer::volume_group`]), made once per runtime; frames without GI bind a stand-in volume
//! whose probes are all invalid, so indirect light is zero with the same pipelines.

use prt_format::{Asset, LightKind};
use prt_runtime::contract::GpuLight;
use prt_runtime::gpu::PrtRuntime;
use prt_runtime::lights::PreparedLight;
use prt_scene::Scene;

use crate::bindings::Resource;
use crate::cull::Cull;
use crate::gpu_scene::GpuScene;
use crate::layout::*;
use crate::raster::{self, Raster};
use crate::shaders::VOLUME_GROUP;
use crate::{Camera, Culling, RenderError, RenderSettings, View};

mod readback;
mod resources;

use resources::{Buffers, Targets};

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

/// The bind groups of both stages, each variable bound by name (see [`crate::bindings`]).
struct BindGroups {
    cull: Vec<wgpu::BindGroup>,
    /// By group number; `None` at [`VOLUME_GROUP`], which the caller's volume fills.
    shade: Vec<Option<wgpu::BindGroup>>,
    /// The volume group of frames without GI: a 1x1x1 volume of validity 0.
    empty_volume: wgpu::BindGroup,
}

impl BindGroups {
    fn new(
        device: &wgpu::Device,
        cull: &Cull,
        raster: &Raster,
        buffers: &Buffers,
        scene: &GpuScene,
        targets: &Targets,
    ) -> Result<BindGroups, RenderError> {
        let bound = |r: Resource| resources::bound(r, buffers, scene, targets);
        let shade = (0..raster.bindings.layouts.len() as u32)
            .map(|g| {
                (g != VOLUME_GROUP)
                    .then(|| raster.bindings.named_group(device, g, bound))
                    .transpose()
            })
            .collect::<Result<_, _>>()?;
        Ok(BindGroups {
            cull: cull.bind_groups(device, bound)?,
            shade,
            empty_volume: resources::empty_volume(device, &raster.bindings)?,
        })
    }
}

/// The tiled Forward+ renderer.
pub struct Renderer {
    settings: RenderSettings,
    scene: GpuScene,
    cull: Cull,
    raster: Raster,
    buffers: Buffers,
    targets: Targets,
    groups: BindGroups,
    light_counts: (u32, u32),
    tiles: (u32, u32),
    /// The asset's probe spacing: the scene's length scale for shadow-ray offsets.
    ray_scale: f32,
}

impl Renderer {
    /// Uploads `scene` (the file `asset` was baked from) and creates the stages.
    pub fn new(
        device: &wgpu::Device,
        scene: &Scene,
        asset: &Asset,
        settings: RenderSettings,
    ) -> Result<Renderer, RenderError> {
        resources::check_settings(device, &settings)?;
        let gpu_scene = GpuScene::new(device, scene, asset)?;
        let tiles = (
            settings.width.div_ceil(settings.tile),
            settings.height.div_ceil(settings.tile),
        );
        let buffers = resources::buffers(device, &settings, tiles)?;
        let targets = resources::targets(device, settings.width, settings.height);
        let cull = Cull::new(device)?;
        let raster = Raster::new(device)?;
        let groups = BindGroups::new(device, &cull, &raster, &buffers, &gpu_scene, &targets)?;
        Ok(Renderer {
            settings,
            scene: gpu_scene,
            cull,
            raster,
            buffers,
            targets,
            groups,
            light_counts: (0, 0),
            tiles,
            ray_scale: asset.header.grid.spacing,
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
        queue.write_buffer(&self.buffers.directional, 0, bytemuck::cast_slice(&dir));
        queue.write_buffer(&self.buffers.others, 0, bytemuck::cast_slice(&other));
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
        queue.write_buffer(&self.buffers.frame, 0, bytemuck::bytes_of(&uniform));
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
        self.set_shade_groups(
            &mut pass,
            self.raster.depth_groups,
            &self.groups.empty_volume,
        );
        pass.set_vertex_buffer(0, self.scene.vertices.slice(..));
        raster::draw(
            &mut pass,
            &self.raster.depth,
            self.scene.single_sided_vertices,
            self.scene.vertex_count,
        );
    }

    /// Stage 2: tiled light culling (nothing with [`Culling::None`]).
    pub fn record_cull(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.buffers.stats, 0, None);
        if self.settings.culling == Culling::Tiled {
            self.cull.record(encoder, &self.groups.cull, self.tiles);
        }
    }

    /// The shading pass's bind group over `gi`'s volume: make it once per runtime and pass it
    /// to [`Renderer::record`] every frame.
    pub fn volume_group(&self, gi: &PrtRuntime) -> wgpu::BindGroup {
        gi.volume_bind_group(&self.raster.bindings.layouts[VOLUME_GROUP as usize])
    }

    /// Stage 3: shading, with indirect light from `volume` ([`Renderer::volume_group`]; none:
    /// indirect is zero).
    pub fn record_shade(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        volume: Option<&wgpu::BindGroup>,
    ) {
        let volume = volume.unwrap_or(&self.groups.empty_volume);
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
        self.set_shade_groups(&mut pass, self.groups.shade.len(), volume);
        pass.set_vertex_buffer(0, self.scene.vertices.slice(..));
        raster::draw(
            &mut pass,
            &self.raster.shade,
            self.scene.single_sided_vertices,
            self.scene.vertex_count,
        );
    }

    /// Sets the raster pipelines' groups 0 to `count` (exclusive), `volume` at [`VOLUME_GROUP`].
    fn set_shade_groups(
        &self,
        pass: &mut wgpu::RenderPass,
        count: usize,
        volume: &wgpu::BindGroup,
    ) {
        for (g, group) in self.groups.shade[..count].iter().enumerate() {
            pass.set_bind_group(g as u32, group.as_ref().unwrap_or(volume), &[]);
        }
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
