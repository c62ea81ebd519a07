//! What the runtime allocates on the GPU, buffer by buffer: an engine budgets its memory with
//! it, and issue 32 bounds a level's by it. The figures are the sizes the runtime asked wgpu
//! for (buffers padded to their minimum binding size, textures at their texel format's bytes);
//! the driver may round them up.

use super::resources::Resources;
use super::PrtRuntime;

/// Bytes of one group of GPU objects.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Allocation {
    /// The WGSL variable (or variables) it is bound as.
    pub name: &'static str,
    pub bytes: u64,
}

impl PrtRuntime {
    /// Every buffer and texture the runtime allocated, largest first, and their total.
    pub fn gpu_memory(&self) -> (Vec<Allocation>, u64) {
        let mut list = self.res.allocations();
        list.sort_by(|a, b| b.bytes.cmp(&a.bytes).then(a.name.cmp(b.name)));
        let total = list.iter().map(|a| a.bytes).sum();
        (list, total)
    }
}

impl Resources {
    /// The allocations of [`PrtRuntime::gpu_memory`], in declaration order.
    fn allocations(&self) -> Vec<Allocation> {
        let a = &self.asset;
        let s = &self.state;
        let all = |name, buffers: &mut dyn Iterator<Item = &wgpu::Buffer>| Allocation {
            name,
            bytes: buffers.map(wgpu::Buffer::size).sum(),
        };
        let one = |name, buffer: &wgpu::Buffer| all(name, &mut std::iter::once(buffer));
        let texels: u64 = self
            .textures
            .iter()
            .map(|t| {
                let e = t.size();
                let texel = u64::from(t.format().block_copy_size(None).unwrap_or(0));
                u64::from(e.width)
                    * u64::from(e.height)
                    * u64::from(e.depth_or_array_layers)
                    * texel
            })
            .sum();
        vec![
            one("probes", &a.probes),
            one("bricks", &a.bricks),
            one("normal_bounds", &a.normal_bounds),
            one("bvh_nodes", &a.bvh_nodes),
            one("triangles", &a.triangles),
            one("sky_transfer", &a.sky_transfer),
            one("sky_mask", &a.sky_mask),
            one("prt_depth_moments", &a.depth_moments),
            one("prt_probe_positions", &a.probe_positions),
            one("gather_list", &a.gather_list),
            one("fill_list", &a.fill_list),
            one("prt_surface", &a.surface),
            one("surface_groups", &a.surface_groups),
            one("surface_near", &a.surface_near),
            one("coarse_bricks", &a.coarse_bricks),
            one("coarse_children", &a.coarse_children),
            one("brick_moments", &a.brick_moments),
            one("factor_frames", &a.factor_frames),
            all("factors (all chunks)", &mut self.chunk_factors.iter()),
            all("factor chunk uniforms", &mut self.chunk_uniforms.iter()),
            all(
                "surfels, their direct and bounce radiance (all chunks)",
                &mut self.chunk_surfels.iter().flatten(),
            ),
            one("brick_lights", &s.brick_lights),
            one("brick_dirty", &s.brick_dirty),
            one("brick_cache", &s.brick_cache),
            one("shadow_cache", &s.shadow_cache),
            one("light_changes", &s.light_changes),
            one("brick_radiance", &s.brick_radiance),
            one("group_radiance", &s.group_radiance),
            one("prt_near", &s.near_radiance),
            one("probe_dirty", &s.probe_dirty),
            one("probe_sh", &s.probe_sh),
            one("counters", &s.counters),
            one("lights", &s.lights),
            one("sky_directions", &s.sky_directions),
            one("params", &s.params),
            one("prt_volume (uniform)", &self.volume_info),
            Allocation {
                name: "prt_volume0..6 (SH volume textures)",
                bytes: texels,
            },
        ]
    }
}
