//! Buffer creation with the device's limits checked first: a buffer past them is a
//! [`GpuError::Limit`] naming it, never a wgpu validation panic.

use wgpu::util::DeviceExt;

use crate::gpu::GpuError;

/// Smallest buffer the runtime creates: larger than every element type it binds.
const MIN_BUFFER: u64 = 256;

/// A buffer holding `bytes`, refused with [`GpuError::Limit`] beyond `limit` bytes (a device
/// limit: one storage binding, or the largest buffer). wgpu cannot bind empty buffers, nor ones
/// smaller than one element: an empty array gets `MIN_BUFFER` (256) zero bytes.
pub fn buffer_with(
    device: &wgpu::Device,
    label: &'static str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
    limit: u64,
) -> Result<wgpu::Buffer, GpuError> {
    if bytes.len() as u64 > limit {
        return Err(GpuError::Limit {
            what: label,
            needed: bytes.len() as u64,
            limit,
        });
    }
    let padded;
    let contents = if bytes.is_empty() {
        padded = [0u8; MIN_BUFFER as usize];
        &padded[..]
    } else {
        bytes
    };
    Ok(
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        }),
    )
}

/// Creates the runtime's storage buffers, refusing any larger than one storage binding.
pub(super) struct Alloc<'a> {
    pub(super) device: &'a wgpu::Device,
    pub(super) max_binding: u64,
}

impl Alloc<'_> {
    fn check(&self, label: &'static str, size: u64) -> Result<(), GpuError> {
        if size > self.max_binding {
            return Err(GpuError::Limit {
                what: label,
                needed: size,
                limit: self.max_binding,
            });
        }
        Ok(())
    }

    /// A uniform buffer holding `value`.
    pub(super) fn uniform<T: bytemuck::Pod>(&self, label: &'static str, value: &T) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                // Copied to when the lighting changes it (the snippet's sky irradiance).
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Bytes per chunk of a chunked array: the setting's limit, if any, within one binding.
    pub(super) fn chunk_bytes(&self, setting: Option<u64>) -> u64 {
        setting.unwrap_or(self.max_binding).min(self.max_binding)
    }

    /// A storage buffer holding `bytes`.
    pub(super) fn storage(
        &self,
        label: &'static str,
        bytes: &[u8],
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        buffer_with(
            self.device,
            label,
            bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
            self.max_binding,
        )
    }

    /// A zero-initialised storage buffer of `size` bytes.
    pub(super) fn zeroed(
        &self,
        label: &'static str,
        size: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        self.check(label, size)?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(MIN_BUFFER),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
            mapped_at_creation: false,
        }))
    }
}
