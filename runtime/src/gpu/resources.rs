//! Every buffer and texture of the GPU runtime, created from one asset: the asset's arrays as
//! they are (factor tables and surfel arrays split into chunks that fit one storage binding
//! each), the runtime's own state (light masks, shadow-ray cache, brick radiance, probe SH,
//! counters) and the SH volume. Sizes are checked against the device's limits before anything
//! is allocated.

use std::mem::size_of;

use prt_format::Asset;

use super::{GpuError, RuntimeSettings};
use crate::contract::*;
use crate::lights::brick_normal_bounds;

mod alloc;
mod chunks;

pub use alloc::buffer_with;
use alloc::Alloc;
use chunks::{factor_buffers, surfel_buffers};
pub use chunks::{factor_chunks, surfel_chunks};

/// Every GPU object of one asset's runtime, named after the WGSL variables that bind them
/// (`bindings.rs` binds them by those names).
pub struct Resources {
    /// The asset's arrays that fit one binding each, uploaded as they are.
    pub asset: AssetBuffers,
    /// Factor tables split over bindings: whole probes each.
    pub chunks: Vec<FactorChunk>,
    /// Per factor chunk, its factors.
    pub chunk_factors: Vec<wgpu::Buffer>,
    /// Per factor chunk, its `FactorChunk` uniform.
    pub chunk_uniforms: Vec<wgpu::Buffer>,
    /// Surfel arrays split over bindings: whole bricks each.
    pub surfel_chunks: Vec<SurfelChunk>,
    /// Per surfel chunk: its surfels, their direct radiance, their bounce radiance (one word
    /// without bounces) and its `SurfelChunk` uniform.
    pub chunk_surfels: Vec<[wgpu::Buffer; 4]>,
    /// The runtime's own state.
    pub state: StateBuffers,
    /// The seven SH volume textures.
    pub textures: Vec<wgpu::Texture>,
    /// Views of `textures` (storage in the gather, sampled by the snippet).
    pub views: Vec<wgpu::TextureView>,
    pub sampler: wgpu::Sampler,
    /// The sampling snippet's uniform (`PrtVolumeInfo`) and its contents.
    pub volume_info: wgpu::Buffer,
    pub info: VolumeInfo,
    /// Words per brick light mask, `ceil(max_lights / 32)`.
    pub mask_stride: u32,
}

/// The asset's arrays the stages and the sampling snippet read whole.
pub struct AssetBuffers {
    pub probes: wgpu::Buffer,
    pub bricks: wgpu::Buffer,
    pub normal_bounds: wgpu::Buffer,
    pub bvh_nodes: wgpu::Buffer,
    pub triangles: wgpu::Buffer,
    pub sky_transfer: wgpu::Buffer,
    pub sky_mask: wgpu::Buffer,
    /// The depth moments of the probes with data, in slot order (`Asset::probe_depth`,
    /// `prt_format::depth`).
    pub depth_moments: wgpu::Buffer,
    /// Per grid point, where its probe's rays started (xyz) and its slot (w), as u32 words.
    pub probe_positions: wgpu::Buffer,
    /// The valid probes' indices in grid order: what the gather's round robin visits (at least
    /// one word, so that the buffer binds; `gather_count` of them count).
    pub gather_list: wgpu::Buffer,
    pub gather_count: u32,
    /// The grid points the coarse levels fill, in grid order (`prt_format::tier`; at least one
    /// word, `fill_count` of them count).
    pub fill_list: wgpu::Buffer,
    pub fill_count: u32,
    /// The surface lookup's tables, one array of words ([`SurfaceLayout`]).
    pub surface: wgpu::Buffer,
    /// Brick count, then per brick its first near group and group count, then per group its
    /// first surfel and surfel count (`brick_radiance` computes each group's radiance).
    pub surface_groups: wgpu::Buffer,
    /// Group count, then per group its near field (first entry, count), then the entries
    /// (`prt_format::surface::near_entry`).
    pub surface_near: wgpu::Buffer,
    /// The coarse bricks, their bricks and the bricks' moments (`prt_format::coarse`).
    pub coarse_bricks: wgpu::Buffer,
    pub coarse_children: wgpu::Buffer,
    pub brick_moments: wgpu::Buffer,
    /// Per brick, then per coarse brick, the centroid its factors' offsets are measured from
    /// and their multiplier (`prt_format::Asset::factor_frame`): where the gather decodes a
    /// lobe factor's direction (at least one entry, so that the buffer binds).
    pub factor_frames: wgpu::Buffer,
}

/// What the stages write and read back between updates, and the per-update uploads.
pub struct StateBuffers {
    /// Per brick, `mask_stride` words of light mask, then as many of the previous mask.
    pub brick_lights: wgpu::Buffer,
    pub brick_dirty: wgpu::Buffer,
    /// Per brick, its offsets in the two halves of the shadow-ray cache.
    pub brick_cache: wgpu::Buffer,
    /// Words in each half of the shadow-ray cache.
    pub cache_capacity: u64,
    /// The shadow-ray cache: one bit per (surfel, reaching light) pair, two halves.
    pub shadow_cache: wgpu::Buffer,
    /// Per update: the moved lights' bitset, then the changed lights' indices.
    pub light_changes: wgpu::Buffer,
    pub brick_radiance: wgpu::Buffer,
    /// Per near group: the mean radiance of its surfels (xyz), and what its near field brings.
    pub group_radiance: wgpu::Buffer,
    pub near_radiance: wgpu::Buffer,
    pub probe_dirty: wgpu::Buffer,
    pub probe_sh: wgpu::Buffer,
    pub counters: wgpu::Buffer,
    pub lights: wgpu::Buffer,
    pub sky_directions: wgpu::Buffer,
    pub params: wgpu::Buffer,
}

impl Resources {
    /// Uploads `asset` and allocates every buffer and texture for `settings` (already checked
    /// by the caller), within `device`'s limits: past them a [`GpuError::Limit`] names the
    /// array, its size and the limit. `probe_sh` gets `sh_entry_count` entries
    /// (the probes with data, [`probe_sh_entry`]).
    pub fn new(
        device: &wgpu::Device,
        asset: &Asset,
        settings: &RuntimeSettings,
        mask_stride: u32,
        sh_entry_count: u32,
    ) -> Result<Resources, GpuError> {
        let g = asset.header.grid;
        let max_binding = check_limits(&device.limits(), &g)?;
        let alloc = Alloc {
            device,
            max_binding,
        };
        let (chunks, chunk_factors, chunk_uniforms) = factor_buffers(&alloc, asset, settings)?;
        let (surfel_chunks, chunk_surfels) = surfel_buffers(&alloc, asset, settings)?;
        let asset_buffers = AssetBuffers::new(&alloc, asset, settings.equirect_sky)?;
        let state = StateBuffers::new(&alloc, asset, settings, mask_stride, sh_entry_count)?;
        let (textures, views, sampler) = volume(device, &g, settings);
        let info = volume_info(asset, settings);
        let volume_info = alloc.uniform("prt volume info", &info);
        Ok(Resources {
            asset: asset_buffers,
            chunks,
            chunk_factors,
            chunk_uniforms,
            surfel_chunks,
            chunk_surfels,
            state,
            textures,
            views,
            sampler,
            volume_info,
            info,
            mask_stride,
        })
    }
}

impl AssetBuffers {
    /// Uploads the asset's arrays (a scene without triangles gets one leaf holding a degenerate
    /// triangle, which no ray hits).
    /// Without `equirect_sky` the probes' sky masks (read only under an equirect sky,
    /// gather.wgsl) are not uploaded: the binding gets the smallest buffer.
    fn new(alloc: &Alloc, asset: &Asset, equirect_sky: bool) -> Result<AssetBuffers, GpuError> {
        let sky_mask: &[u32] = if equirect_sky { &asset.sky_mask } else { &[] };
        let none = wgpu::BufferUsages::empty();
        let upload = |label, bytes: &[u8]| alloc.storage(label, bytes, none);
        let normal_bounds: Vec<GpuNormalBounds> = brick_normal_bounds(asset)
            .iter()
            .map(GpuNormalBounds::from)
            .collect();
        let empty_node = [prt_format::BvhNode {
            min: [f32::MAX; 3],
            max: [f32::MIN; 3],
            count: 1,
            first: 0,
        }];
        let empty_triangle = [prt_format::Triangle::default()];
        let (nodes, tris) = if asset.geometry.nodes.is_empty() {
            (&empty_node[..], &empty_triangle[..])
        } else {
            (&asset.geometry.nodes[..], &asset.geometry.triangles[..])
        };
        // Words, not floats: the slot is not a float (NO_SLOT is a NaN's bits, small slots are
        // subnormals), and WGSL may flush either; the snippet bitcasts xyz instead.
        let positions: Vec<[u32; 4]> = asset
            .probes
            .iter()
            .map(|p| {
                let [x, y, z] = p.position.map(f32::to_bits);
                [x, y, z, p.slot]
            })
            .collect();
        let (gather_list, valid_probes) = probe_list(asset, prt_format::Probe::is_valid);
        let (fill_list, fill_count) = probe_list(asset, prt_format::Probe::is_filled);
        Ok(AssetBuffers {
            probes: upload("prt probes", bytemuck::cast_slice(&asset.probes))?,
            bricks: upload("prt bricks", bytemuck::cast_slice(&asset.bricks))?,
            normal_bounds: upload("prt normal bounds", bytemuck::cast_slice(&normal_bounds))?,
            bvh_nodes: upload("prt bvh nodes", bytemuck::cast_slice(nodes))?,
            triangles: upload("prt triangles", bytemuck::cast_slice(tris))?,
            sky_transfer: upload(
                "prt sky transfer",
                bytemuck::cast_slice(&asset.sky_transfer),
            )?,
            sky_mask: upload("prt sky mask", bytemuck::cast_slice(sky_mask))?,
            depth_moments: upload(
                "prt probe depth moments",
                bytemuck::cast_slice(&asset.probe_depth),
            )?,
            probe_positions: upload("prt probe positions", bytemuck::cast_slice(&positions))?,
            gather_list: upload("prt gather list", bytemuck::cast_slice(&gather_list))?,
            gather_count: valid_probes,
            fill_list: upload("prt fill list", bytemuck::cast_slice(&fill_list))?,
            fill_count,
            surface: upload(
                "prt surface",
                bytemuck::cast_slice(&SurfaceLayout::words(asset)),
            )?,
            surface_groups: upload(
                "prt surface groups",
                bytemuck::cast_slice(&surface_groups(asset)),
            )?,
            surface_near: upload(
                "prt surface near",
                bytemuck::cast_slice(&surface_near(asset)),
            )?,
            coarse_bricks: upload(
                "prt coarse bricks",
                bytemuck::cast_slice(&asset.coarse.bricks),
            )?,
            coarse_children: upload(
                "prt coarse children",
                bytemuck::cast_slice(&asset.coarse.children),
            )?,
            brick_moments: upload(
                "prt brick moments",
                bytemuck::cast_slice(&asset.coarse.moments),
            )?,
            factor_frames: upload(
                "prt factor frames",
                bytemuck::cast_slice(&factor_frames(asset)),
            )?,
        })
    }
}

/// [`AssetBuffers::factor_frames`]: one per brick and coarse brick, at least one.
fn factor_frames(asset: &Asset) -> Vec<[f32; 4]> {
    let bricks = asset.bricks.len() + asset.coarse.bricks.len();
    let mut frames: Vec<[f32; 4]> = (0..bricks).map(|b| asset.factor_frame(b)).collect();
    if frames.is_empty() {
        frames.push([0.0; 4]);
    }
    frames
}

/// The indices of `asset`'s probes that `keep`, in grid order, and how many: at least one word
/// (a zero when none), so that the buffer binds.
fn probe_list(asset: &Asset, keep: fn(&prt_format::Probe) -> bool) -> (Vec<u32>, u32) {
    let mut list: Vec<u32> = (0..asset.probes.len() as u32)
        .filter(|&p| keep(&asset.probes[p as usize]))
        .collect();
    let count = list.len() as u32;
    if list.is_empty() {
        list.push(0);
    }
    (list, count)
}

impl StateBuffers {
    /// Allocates the runtime's state, zeroed (every brick uncached), sized for `asset` and
    /// `settings`, with `sh_entry_count` entries of `probe_sh`.
    fn new(
        alloc: &Alloc,
        asset: &Asset,
        settings: &RuntimeSettings,
        mask_stride: u32,
        sh_entry_count: u32,
    ) -> Result<StateBuffers, GpuError> {
        let none = wgpu::BufferUsages::empty();
        let n_bricks = asset.bricks.len() as u64;
        // Radiance and dirty flags of the coarse bricks follow the bricks'.
        let n_radiance = n_bricks + asset.coarse.bricks.len() as u64;
        let n_probes = asset.probes.len() as u64;
        let n_groups = asset.surface.group_surfels.len() as u64;
        let stride = u64::from(mask_stride);
        let cache_capacity = settings
            .shadow_cache_words
            .unwrap_or(stride.min(2) * asset.surfels.len() as u64)
            .clamp(1, (alloc.max_binding / 8).min(u64::from(u32::MAX / 2)));
        let max_lights = settings.max_lights as u64;
        let copy_src = wgpu::BufferUsages::COPY_SRC;
        Ok(StateBuffers {
            brick_lights: alloc.zeroed("prt brick light masks", 8 * stride * n_bricks, none)?,
            brick_dirty: alloc.zeroed("prt brick dirty", 4 * n_radiance, none)?,
            brick_cache: alloc.storage(
                "prt brick shadow-cache offsets",
                bytemuck::cast_slice(&vec![NO_CACHE; 2 * asset.bricks.len()]),
                none,
            )?,
            cache_capacity,
            shadow_cache: alloc.zeroed("prt shadow-ray cache", 8 * cache_capacity, none)?,
            light_changes: alloc.zeroed(
                "prt light changes",
                4 * (stride + max_lights),
                wgpu::BufferUsages::COPY_DST,
            )?,
            brick_radiance: alloc.zeroed("prt brick radiance", 64 * n_radiance, none)?,
            group_radiance: alloc.zeroed("prt group radiance", 16 * n_groups, none)?,
            near_radiance: alloc.zeroed("prt near radiance", 16 * n_groups, none)?,
            probe_dirty: alloc.zeroed("prt probe dirty", 4 * n_probes, none)?,
            probe_sh: alloc.zeroed(
                "prt probe sh",
                4 * u64::from(PROBE_SH_FLOATS) * u64::from(sh_entry_count.max(1)),
                copy_src,
            )?,
            counters: alloc.zeroed("prt counters", size_of::<Counters>() as u64, copy_src)?,
            lights: alloc.zeroed("prt lights", 64 * max_lights, none)?,
            sky_directions: alloc.zeroed(
                "prt sky directions",
                32 * u64::from(asset.header.ray_count),
                none,
            )?,
            params: alloc.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("prt params"),
                size: size_of::<Params>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        })
    }
}

/// The device limits the runtime needs, checked before anything is allocated; returns the
/// largest storage binding.
fn check_limits(limits: &wgpu::Limits, g: &prt_format::Grid) -> Result<u64, GpuError> {
    let dim = u64::from(g.counts.iter().copied().max().unwrap_or(1));
    if dim > u64::from(limits.max_texture_dimension_3d) {
        return Err(GpuError::Limit {
            what: "the probe grid's largest dimension",
            needed: dim,
            limit: u64::from(limits.max_texture_dimension_3d),
        });
    }
    let max_binding = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    for (what, needed, limit) in [
        (
            "storage buffers per shader stage",
            12,
            limits.max_storage_buffers_per_shader_stage,
        ),
        (
            "storage textures per shader stage",
            7,
            limits.max_storage_textures_per_shader_stage,
        ),
        ("bind groups", 3, limits.max_bind_groups),
    ] {
        if needed > limit {
            return Err(GpuError::Limit {
                what,
                needed: u64::from(needed),
                limit: u64::from(limit),
            });
        }
    }
    Ok(max_binding)
}

/// The seven SH volume textures (storage in the gather, sampled by the snippet), their views and
/// the trilinear clamp-to-edge sampler.
fn volume(
    device: &wgpu::Device,
    g: &prt_format::Grid,
    settings: &RuntimeSettings,
) -> (Vec<wgpu::Texture>, Vec<wgpu::TextureView>, wgpu::Sampler) {
    let size = wgpu::Extent3d {
        width: g.counts[0],
        height: g.counts[1],
        depth_or_array_layers: g.counts[2],
    };
    let textures: Vec<wgpu::Texture> = (0..7)
        .map(|i| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(&format!("prt sh volume {i}")),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: settings.volume_format.texture_format(),
                usage: wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        })
        .collect();
    let views: Vec<wgpu::TextureView> = textures
        .iter()
        .map(|t| t.create_view(&wgpu::TextureViewDescriptor::default()))
        .collect();
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("prt sh volume sampler"),
        address_mode_u: wgpu::AddressMode::ClampToEdge,
        address_mode_v: wgpu::AddressMode::ClampToEdge,
        address_mode_w: wgpu::AddressMode::ClampToEdge,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    (textures, views, sampler)
}

/// The sampling snippet's uniform for `grid` and `settings`.
pub fn volume_info(asset: &Asset, settings: &RuntimeSettings) -> VolumeInfo {
    let grid = &asset.header.grid;
    let t = &asset.surface;
    let surface = settings.lookup.surface_terms && !t.is_empty();
    let layout = SurfaceLayout::of(asset);
    let flags = (if settings.lookup.depth_moments {
        VOLUME_DEPTH_MOMENTS
    } else {
        0
    }) | if surface { VOLUME_SURFACE } else { 0 };
    VolumeInfo {
        normal_bias: settings.lookup.normal_bias * grid.spacing,
        surface_bias: settings.lookup.surface_bias * grid.spacing,
        ringing_floor: settings.lookup.ringing_floor,
        flags,
        surface_anchor: t.header.anchor,
        brick_size: t.header.brick_size,
        slot_mask: (t.slots.len() as u32).saturating_sub(1),
        max_probe: t.header.max_probe,
        cells_at: layout.cells_at,
        terms_at: layout.terms_at,
        bricks_at: layout.bricks_at,
        sky_at: layout.sky_at,
        sides_at: layout.sides_at,
        near_rays: t.header.rays.max(1) as f32,
        ..VolumeInfo::from(grid)
    }
}

/// The `surface_groups` words of `asset` ([`AssetBuffers::surface_groups`]).
fn surface_groups(asset: &Asset) -> Vec<u32> {
    let t = &asset.surface;
    let groups = t.group_surfels.len() as u32;
    let mut w = vec![t.groups.len() as u32];
    for (b, &first) in t.groups.iter().enumerate() {
        let next = t.groups.get(b + 1).copied().unwrap_or(groups);
        w.extend([first, next - first]);
    }
    w.extend(t.group_surfels.iter().flatten());
    w
}

/// The `surface_near` words of `asset` ([`AssetBuffers::surface_near`]).
fn surface_near(asset: &Asset) -> Vec<u32> {
    let t = &asset.surface;
    let mut w = vec![t.near_ranges.len() as u32];
    let head = 1 + 2 * t.near_ranges.len() as u32;
    w.extend(
        t.near_ranges
            .iter()
            .flat_map(|&[first, n]| [head + first, n]),
    );
    w.extend(&t.near);
    w
}
