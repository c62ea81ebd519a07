//! Forward+ stage 2 (`shaders/render_cull.wgsl`), one compute dispatch of one workgroup per
//! screen tile: the indices of the point and spot lights whose bounding sphere touches the
//! tile's view-space box between its min and max depth; see the shader for the steps.
//! Directional lights are not culled: they reach every tile and the shading pass loops over them
//! directly.
//!
//! The lists are exact, not approximate: lights are listed in rig order (so a pixel sums them in
//! the order brute force does) and every test is conservative (a dropped light contributes
//! exactly zero at every pixel of the tile under the light model's range window and cone,
//! docs/conventions.md section 3), so tiled shading equals [`crate::Culling::None`] bit for bit.
//! A tile with more lights than its list holds keeps the first ones and is counted, never
//! silently truncated.

use crate::bindings::{Resource, StageBindings};
use crate::RenderError;

const LABEL: &str = "prt-render cull";

/// The culling pipeline and its bindings (read from `render_cull.wgsl`, see [`crate::bindings`]).
pub struct Cull {
    pub pipeline: wgpu::ComputePipeline,
    pub bindings: StageBindings,
}

impl Cull {
    pub fn new(device: &wgpu::Device) -> Result<Cull, RenderError> {
        let source = crate::shaders::cull_source();
        let bindings = StageBindings::new(device, LABEL, &source)?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(LABEL),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(LABEL),
            layout: Some(&bindings.pipeline_layout(device, &["main"])),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        Ok(Cull { pipeline, bindings })
    }

    /// The stage's bind groups, each variable bound by name to `resource`.
    pub fn bind_groups<'a>(
        &self,
        device: &wgpu::Device,
        resource: impl Fn(Resource) -> wgpu::BindingResource<'a> + Copy,
    ) -> Result<Vec<wgpu::BindGroup>, RenderError> {
        (0..self.bindings.layouts.len() as u32)
            .map(|g| self.bindings.named_group(device, g, resource))
            .collect()
    }

    /// Records the dispatch: one workgroup of `CULL_GROUP` x `CULL_GROUP` threads per tile.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        groups: &[wgpu::BindGroup],
        tiles: (u32, u32),
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prt-render cull"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        for (g, group) in groups.iter().enumerate() {
            pass.set_bind_group(g as u32, group, &[]);
        }
        pass.dispatch_workgroups(tiles.0, tiles.1, 1);
    }
}
