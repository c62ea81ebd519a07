//! Reading a rendered frame and the tile lists back to the CPU (tests, `prt render`, benchmarks).

use super::{Frame, Renderer};
use crate::layout::{tile_list_words, CullStats};
use crate::raster::TARGETS;
use crate::{Culling, RenderError};

impl Renderer {
    /// Reads the last frame back (blocks until the GPU is done).
    pub fn read_frame(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Frame, RenderError> {
        let (w, h) = (self.settings.width, self.settings.height);
        let row = (w * 16).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let size = u64::from(row) * u64::from(h);
        let mut planes = Vec::with_capacity(TARGETS);
        for (texture, _) in &self.targets.colors {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("prt-render readback"),
                size,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_texture_to_buffer(
                texture.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(h),
                    },
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
            queue.submit([encoder.finish()]);
            let bytes = prt_runtime::gpu::read_buffer(device, queue, &buffer, size)?;
            let mut plane = Vec::with_capacity((w * h) as usize);
            for y in 0..h as usize {
                let start = y * row as usize;
                plane.extend(bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(
                    &bytes[start..start + w as usize * 16],
                ));
            }
            planes.push(plane);
        }
        let stats_bytes = prt_runtime::gpu::read_buffer(
            device,
            queue,
            &self.buffers.stats,
            std::mem::size_of::<CullStats>() as u64,
        )?;
        let normal = planes.pop().unwrap_or_default();
        let position = planes.pop().unwrap_or_default();
        let radiance = planes.pop().unwrap_or_default();
        Ok(Frame {
            width: w,
            height: h,
            radiance,
            position,
            normal,
            stats: bytemuck::pod_read_unaligned(&stats_bytes),
        })
    }

    /// Per tile (row-major), the count word of its list: lights listed in the low bits, with
    /// [`crate::layout::TILE_OVERFLOW`] set when the tile had more lights than its list holds; with
    /// [`Culling::None`], every point and spot light.
    pub fn read_tile_counts(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<u32>, RenderError> {
        let tiles = (self.tiles.0 * self.tiles.1) as usize;
        if self.settings.culling == Culling::None {
            return Ok(vec![self.light_counts.1; tiles]);
        }
        let bytes = prt_runtime::gpu::read_buffer(
            device,
            queue,
            &self.buffers.tile_lists,
            self.buffers.tile_lists.size(),
        )?;
        // The readback need not be 4-byte aligned: copy instead of casting.
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let stride = tile_list_words(self.settings.max_lights_per_tile) as usize;
        Ok((0..tiles).map(|t| words[t * stride]).collect())
    }
}
