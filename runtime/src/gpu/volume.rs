//! What an engine reads from the runtime: the SH volume (views, sampler, the sampling snippet
//! with its bind group and layout), and readbacks of probe SH, counters and texels for tests
//! and tools.

use prt_format::sh::{ShRgb, SH_COUNT};

use super::bindings::{snippet_bindings, Set};
use super::{shaders, GpuError, PrtRuntime, RuntimeSettings, VolumeFormat};
use crate::contract::{Counters, VolumeInfo};

impl PrtRuntime {
    /// The seven volume texture views (layout in `shaders/gather.wgsl`).
    pub fn volume_views(&self) -> &[wgpu::TextureView] {
        &self.res.views
    }

    /// A trilinear, clamp-to-edge sampler for the volume.
    pub fn sampler(&self) -> &wgpu::Sampler {
        &self.res.sampler
    }

    /// The grid the volume covers (origin, spacing, per-axis step, counts).
    pub fn grid(&self) -> prt_format::Grid {
        self.grid
    }

    /// The contents of the sampling snippet's `PrtVolumeInfo` uniform (binding 8 of its group).
    pub fn volume_info(&self) -> VolumeInfo {
        self.res.info
    }

    /// The settings the runtime was created with.
    pub fn settings(&self) -> &RuntimeSettings {
        &self.settings
    }

    /// The bind group layout entries of the sampling snippet (`wgsl_snippet`), visible to
    /// `stages`, numbered as `shaders/sample_irradiance.wgsl` declares them: seven volume
    /// textures, the sampler, the `PrtVolumeInfo` uniform, the depth moments, the probe
    /// positions, the surface lookup's tables and its near radiance (four storage buffers in
    /// all). The textures are declared filterable: a [`VolumeFormat::F32`] volume needs a
    /// device with `Features::FLOAT32_FILTERABLE` (as its trilinear sampler does anyway).
    pub fn volume_layout_entries(stages: wgpu::ShaderStages) -> Vec<wgpu::BindGroupLayoutEntry> {
        snippet_bindings()
            .into_iter()
            .filter_map(|(binding, b)| {
                Some(wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility: stages,
                    ty: b.snippet_type()?,
                    count: None,
                })
            })
            .collect()
    }

    /// The bind group of the sampling snippet for `layout` (made from
    /// [`PrtRuntime::volume_layout_entries`] or taken from a pipeline built with the snippet).
    pub fn volume_bind_group(&self, layout: &wgpu::BindGroupLayout) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = snippet_bindings()
            .into_iter()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.resource(&self.res, Set::Whole),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("prt volume"),
            layout,
            entries: &entries,
        })
    }

    /// WGSL defining `sample_irradiance(world_pos, normal)` and `prt_sample_sh(world_pos,
    /// normal)` with their bindings at `group`.
    pub fn wgsl_snippet(group: u32) -> String {
        shaders::sample_irradiance_snippet(group)
    }

    /// Blocks until the GPU is done and returns every grid point's SH as last gathered or
    /// filled (zero for a point without data). A filled point's is its corners' interpolation
    /// made here (`crate::fill`, as `fill.wgsl` made its texels: `probe_sh` holds probes with
    /// data only).
    pub fn read_probe_sh(&self) -> Result<Vec<ShRgb>, GpuError> {
        let bytes = read_buffer(
            &self.device,
            &self.queue,
            &self.res.state.probe_sh,
            // At least one entry is allocated, so that the buffer binds.
            4 * u64::from(crate::contract::PROBE_SH_FLOATS) * u64::from(self.sh_entry_count.max(1)),
        )?;
        // `PROBE_SH_FLOATS` an entry, rgb by coefficient (`store_probe.wgsl`).
        let v: &[[f32; 3]] = bytemuck::cast_slice(&bytes);
        let mut sh: Vec<ShRgb> = (self.probes.iter())
            .map(|p| {
                crate::contract::probe_sh_entry(p).map_or([[0.0; 3]; 9], |e| {
                    std::array::from_fn(|k| v[9 * e as usize + k])
                })
            })
            .collect();
        crate::fill::fill_points(&self.grid, &self.probes, &mut sh);
        Ok(sh)
    }

    /// Blocks and returns the work counters of the last submitted update.
    pub fn read_counters(&self) -> Result<Counters, GpuError> {
        let size = std::mem::size_of::<Counters>() as u64;
        let bytes = read_buffer(&self.device, &self.queue, &self.res.state.counters, size)?;
        Ok(*bytemuck::from_bytes(&bytes))
    }

    /// Blocks and returns the 28 channels of every texel (texture-major then texel order x, y,
    /// z), as f32.
    pub fn read_volume(&self) -> Result<Vec<Vec<[f32; 4]>>, GpuError> {
        let [w, h, d] = self.grid.counts;
        let texel = match self.settings.volume_format {
            VolumeFormat::F16 => 8u32,
            VolumeFormat::F32 => 16,
        };
        let row = (w * texel).div_ceil(256) * 256;
        let size = u64::from(row) * u64::from(h) * u64::from(d);
        let mut out = Vec::new();
        for t in &self.res.textures {
            let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("prt volume readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = self.device.create_command_encoder(&Default::default());
            encoder.copy_texture_to_buffer(
                t.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &staging,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(h),
                    },
                },
                t.size(),
            );
            self.queue.submit([encoder.finish()]);
            let bytes = map_read(&self.device, &staging, size)?;
            let mut texels = Vec::with_capacity((w * h * d) as usize);
            for z in 0..d {
                for y in 0..h {
                    let start = (u64::from(row) * u64::from(y + z * h)) as usize;
                    for x in 0..w as usize {
                        let at = start + x * texel as usize;
                        texels.push(match self.settings.volume_format {
                            VolumeFormat::F16 => std::array::from_fn(|c| {
                                prt_format::f16_to_f32(u16::from_le_bytes([
                                    bytes[at + 2 * c],
                                    bytes[at + 2 * c + 1],
                                ]))
                            }),
                            VolumeFormat::F32 => {
                                *bytemuck::from_bytes::<[f32; 4]>(&bytes[at..at + 16])
                            }
                        });
                    }
                }
            }
            out.push(texels);
        }
        Ok(out)
    }
}

/// Blocks until the GPU is done and returns the first `size` bytes of `src` (which needs
/// `COPY_SRC` usage).
pub fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("prt readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(src, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    map_read(device, &staging, size)
}

pub(super) fn map_read(
    device: &wgpu::Device,
    staging: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let slice = staging.slice(..size);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    rx.recv()
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    let data = slice
        .get_mapped_range()
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .to_vec();
    staging.unmap();
    Ok(data)
}

/// Rebuilds SH from the seven texels of one probe (undoing the validity premultiplication);
/// `None` where the texel's validity is 0.
pub fn sh_from_texels(t: [[f32; 4]; 7]) -> Option<ShRgb> {
    let v = t[0][3];
    if v <= 0.0 {
        return None;
    }
    let flat: Vec<f32> = t[1..].iter().flatten().map(|x| x / v).collect();
    let mut c = [[0.0f32; 3]; SH_COUNT];
    c[0] = [t[0][0] / v, t[0][1] / v, t[0][2] / v];
    for k in 1..SH_COUNT {
        c[k] = [
            flat[3 * (k - 1)],
            flat[3 * (k - 1) + 1],
            flat[3 * (k - 1) + 2],
        ];
    }
    Some(c)
}
