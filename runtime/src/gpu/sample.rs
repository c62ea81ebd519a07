//! Runs the engine-side snippet (`PrtRuntime::wgsl_snippet`) for real, in a compute shader, at
//! arbitrary points: what `prt sample --backend gpu` and the tests use to see exactly what an
//! engine's shader would get from the volume ([`crate::surface::SurfaceSampler`] is its CPU twin).

use wgpu::util::DeviceExt;

use super::volume::map_read;
use super::{dispatch_size, GpuError, PrtRuntime};
use crate::sample::Sample;

/// Threads per workgroup of the sampling kernel.
const SAMPLE_WORKGROUP: u32 = 64;
/// vec4 words written per point: the 9 SH coefficients, then (irradiance, validity).
const WORDS: usize = 10;
/// Points per dispatch: keeps each storage binding at a few MB whatever the input size.
const BATCH: usize = 1 << 16;

/// The kernel: group 0 holds the points and results, group 1 the snippet's volume bindings.
fn kernel() -> String {
    let body = "
@group(0) @binding(0) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> results: array<vec4<f32>>;

@compute @workgroup_size(SAMPLE_WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = id.x + id.y * groups.x * SAMPLE_WORKGROUP;
    if i >= arrayLength(&points) / 2u {
        return;
    }
    let p = points[2u * i].xyz;
    let n = points[2u * i + 1u].xyz;
    let s = prt_sample_surface(p, n);
    for (var k = 0u; k < 9u; k++) {
        results[SAMPLE_WORDS * i + k] = vec4<f32>(s.sh[k], 0.0);
    }
    results[SAMPLE_WORDS * i + 9u] = vec4<f32>(s.irradiance, s.validity);
}
";
    format!(
        "{}const SAMPLE_WORKGROUP = {SAMPLE_WORKGROUP}u;\nconst SAMPLE_WORDS = {WORDS}u;\n{body}",
        PrtRuntime::wgsl_snippet(1)
    )
}

/// Samples `runtime`'s volume as last updated (submit the update first) at each
/// `(position, unit normal)` with the real snippet (`prt_sample_surface`, what
/// `sample_irradiance` returns the irradiance of): SH, validity and irradiance, with the
/// runtime's lookup settings. Blocks until done.
pub fn sample_points(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    runtime: &PrtRuntime,
    points: &[([f32; 3], [f32; 3])],
) -> Result<Vec<Sample>, GpuError> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("prt sample points"),
        source: wgpu::ShaderSource::Wgsl(kernel().into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("prt sample points"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let volume = runtime.volume_bind_group(&pipeline.get_bind_group_layout(1));
    let mut out = Vec::with_capacity(points.len());
    let mut result = Ok(());
    for batch in points.chunks(BATCH) {
        match run_batch(device, queue, &pipeline, &volume, batch) {
            Ok(samples) => out.extend(samples),
            Err(e) => {
                result = Err(e);
                break;
            }
        }
    }
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Device(e.to_string()));
    }
    result.map(|()| out)
}

/// One dispatch over `batch` and its readback.
fn run_batch(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    pipeline: &wgpu::ComputePipeline,
    volume: &wgpu::BindGroup,
    batch: &[([f32; 3], [f32; 3])],
) -> Result<Vec<Sample>, GpuError> {
    let packed: Vec<[f32; 4]> = batch
        .iter()
        .flat_map(|(p, n)| [[p[0], p[1], p[2], 0.0], [n[0], n[1], n[2], 0.0]])
        .collect();
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("prt sample points"),
        contents: bytemuck::cast_slice(&packed),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (16 * WORDS * batch.len()) as u64;
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("prt sample results"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("prt sample readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let io = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("prt sample io"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: results.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &io, &[]);
        pass.set_bind_group(1, volume, &[]);
        let (x, y) = dispatch_size((batch.len() as u32).div_ceil(SAMPLE_WORKGROUP));
        pass.dispatch_workgroups(x, y, 1);
    }
    encoder.copy_buffer_to_buffer(&results, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let bytes = map_read(device, &staging, size)?;
    // Copied rather than cast: the readback bytes need not be 16-byte aligned.
    let words: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
    Ok(words
        .chunks_exact(WORDS)
        .map(|w| Sample {
            sh: std::array::from_fn(|k| [w[k][0], w[k][1], w[k][2]]),
            irradiance: [w[9][0], w[9][1], w[9][2]],
            validity: w[9][3],
        })
        .collect())
}
