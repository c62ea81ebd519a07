//! The WGSL radiance-word encoder (`pack_radiance`, `shaders/types.wgsl`) against its Rust twin
//! (`prt_runtime::radiance_word`), word for word: the CPU reference averages the words the GPU
//! would write only if both sides round every colour the same way.

use prt_runtime::gpu::shaders::light_model_source;
use prt_runtime::gpu::{read_buffer, wgpu};
use prt_runtime::radiance_word::{pack_radiance, unpack_radiance, RADIANCE_MAX};
use prt_tests::gpu_device;
use wgpu::util::DeviceExt;

/// One thread per colour: its word from the shared encoder.
const KERNEL: &str = "
@group(0) @binding(0) var<storage, read> colours: array<f32>;
@group(0) @binding(1) var<storage, read_write> words: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&words) {
        return;
    }
    words[i] = pack_radiance(vec3<f32>(colours[3u * i], colours[3u * i + 1u], colours[3u * i + 2u]));
}
";

/// Colours at every scale a rig may set (2^-110 to 2^127), the largest channel anywhere in its
/// octave, the others from zero to it; plus the edges: black, exact rounding ties (a largest
/// channel of 1 has steps of 2^-7: 2.5 and 3.5 steps round to even, 2 and 4; 0.5 and 1.5 to
/// 0 and 2), a largest channel that carries into the next exponent, channels at and beyond
/// the clamp (f32::MAX; WGSL may assume floats finite, so no infinity), a subnormal colour.
fn colours() -> Vec<[f32; 3]> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let step = 1.0 / 128.0;
    let mut out = vec![
        [0.0; 3],
        [1.0, 0.5, 0.25],
        [1.0, 2.5 * step, 3.5 * step],
        [1.0, 0.5 * step, 1.5 * step],
        [0.9995, 0.0, 0.0],
        [0.9999, 0.9999, 0.9999],
        [RADIANCE_MAX, 1.0, 0.0],
        [f32::MAX, RADIANCE_MAX * 0.5, 1.0],
        [RADIANCE_MAX * 0.999, RADIANCE_MAX * 0.5, 0.0],
        [1e-31, 1e-32, 0.0],
        [1e-39, 0.0, 5e-40],
    ];
    for _ in 0..100_000 {
        let octave = (next() * 237.0) as i32 - 110;
        let largest = (1.0 + next()) * 2f32.powi(octave);
        let mut c = [next() * largest, next() * largest, next() * largest];
        c[(next() * 3.0) as usize % 3] = largest;
        out.push(c);
    }
    out
}

#[test]
fn wgsl_words_equal_the_rust_words() {
    let (device, queue) = gpu_device();
    // The prelude and types.wgsl, as every stage starts (with the light model after them).
    let source = format!("{}{KERNEL}", light_model_source());
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("radiance words"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("radiance words"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let colours = colours();
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("colours"),
        contents: bytemuck::cast_slice(&colours),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = 4 * colours.len() as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("words"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((colours.len() as u32).div_ceil(64), 1, 1);
    }
    queue.submit([encoder.finish()]);
    let bytes = read_buffer(&device, &queue, &output, size).expect("readback");
    let gpu: &[u32] = bytemuck::cast_slice(&bytes);
    let differ: Vec<_> = (colours.iter().zip(gpu))
        .filter(|(c, &w)| pack_radiance(**c) != w)
        .take(5)
        .map(|(c, &w)| (c, w, pack_radiance(*c), unpack_radiance(w)))
        .collect();
    assert!(
        differ.is_empty(),
        "colour, GPU word, Rust word, GPU colour: {differ:?}"
    );
}
