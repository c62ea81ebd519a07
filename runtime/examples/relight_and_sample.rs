//! The smallest engine integration of prt's GI, headless: load a baked asset, relight it on the
//! GPU, sample the probe volume in your own shader with `sample_irradiance`, move a light,
//! update, sample again. Writes both samplings side by side to a PNG: the irradiance of an
//! upward-facing surface on a horizontal slice through the middle of the probe grid.
//!
//! ```sh
//! cargo run --release -p prt -- bake fixtures/cornell/cornell.gltf -o cornell.prt
//! cargo run --release -p prt-runtime --example relight_and_sample -- cornell.prt slice.png
//! ```

use std::path::PathBuf;

use prt_format::{Light, LightKind, LightRig, Sky};
use prt_runtime::gpu::{headless_device, wgpu, PrtRuntime, RuntimeSettings};
use prt_runtime::Lighting;
use wgpu::util::DeviceExt;

const SIZE: u32 = 256;

/// Your shader: one thread per pixel of the slice, `sample_irradiance` from the snippet that
/// `PrtRuntime::wgsl_snippet(1)` appends (its bindings at group 1).
const SLICE_WGSL: &str = r#"
struct Slice { lo: vec3<f32>, size: u32, hi: vec3<f32>, y: f32 }
@group(0) @binding(0) var<uniform> slice: Slice;
@group(0) @binding(1) var<storage, read_write> out: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= slice.size || id.y >= slice.size { return; }
    let t = (vec2<f32>(id.xy) + 0.5) / f32(slice.size);
    let p = vec3<f32>(mix(slice.lo.x, slice.hi.x, t.x), slice.y, mix(slice.lo.z, slice.hi.z, t.y));
    out[id.y * slice.size + id.x] = vec4<f32>(sample_irradiance(p, vec3<f32>(0.0, 1.0, 0.0)), 1.0);
}
"#;

/// One function on purpose, over the ~80-line guide: the whole integration an engine programmer
/// copies, read top to bottom (load, relight, sample, move a light, update, sample again).
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [asset, png] = args.as_slice() else {
        return Err("usage: relight_and_sample ASSET.prt OUT.png".into());
    };
    let (device, queue, info) = headless_device()?;
    println!("adapter: {} ({:?})", info.name, info.backend);
    let asset = prt_format::read_asset(asset.as_ref())?;
    let g = asset.header.grid;
    let lo: [f32; 3] = g.origin;
    let hi: [f32; 3] = std::array::from_fn(|a| g.origin[a] + g.step[a] * (g.counts[a] - 1) as f32);
    let centre: [f32; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));

    // 1. The runtime, once per asset.
    let mut gi = PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default())?;

    // 2. Your pipeline, with the snippet at group 1 and the runtime's bind group for it.
    let source = format!("{SLICE_WGSL}\n{}", PrtRuntime::wgsl_snippet(1));
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("slice"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("slice"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let volume_group = gi.volume_bind_group(&pipeline.get_bind_group_layout(1));
    let mut uniform = [0u32; 8];
    for a in 0..3 {
        uniform[a] = lo[a].to_bits();
        uniform[4 + a] = hi[a].to_bits();
    }
    uniform[3] = SIZE;
    uniform[7] = centre[1].to_bits();
    let slice = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("slice"),
        contents: bytemuck::cast_slice(&uniform),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let bytes = u64::from(SIZE * SIZE) * 16;
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("slice out"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("slice"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: slice.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: out.as_entire_binding(),
            },
        ],
    });

    // 3. Every frame: update the GI (records nothing when nothing changed), then draw.
    let mut lighting = Lighting::from_rig(
        LightRig {
            lights: vec![Light {
                kind: LightKind::Point,
                position: centre,
                direction: [0.0, -1.0, 0.0],
                color: [1.0, 0.85, 0.7],
                intensity: 4.0,
                range: None,
                inner_cone_angle: 0.0,
                outer_cone_angle: 0.7,
            }],
            sky: Some(Sky {
                color: Some([0.1, 0.15, 0.25]),
                exr: None,
                intensity: 1.0,
            }),
        },
        ".".as_ref(),
        "example rig".as_ref(),
    )?;
    let mut images = Vec::new();
    for frame in 0..2 {
        if frame == 1 {
            // A light moved: the next update relights only what it reaches.
            lighting.rig.lights[0].position[0] = lo[0] + 0.25 * (hi[0] - lo[0]);
        }
        let start = std::time::Instant::now();
        let mut encoder = device.create_command_encoder(&Default::default());
        let report = gi.update(&mut encoder, &lighting, None)?;
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.set_bind_group(1, &volume_group, &[]);
            pass.dispatch_workgroups(SIZE.div_ceil(8), SIZE.div_ceil(8), 1);
        }
        queue.submit([encoder.finish()]);
        let pixels: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&prt_runtime::gpu::read_buffer(
            &device, &queue, &out, bytes,
        )?);
        let counters = gi.read_counters()?;
        println!(
            "frame {frame}: {} lights changed, {} bricks relit, {} shadow rays, {} probes gathered, {:.1} ms",
            report.changed_lights,
            counters.bricks_relit,
            counters.shadow_rays,
            counters.probes_gathered,
            start.elapsed().as_secs_f64() * 1e3
        );
        images.push(pixels);
    }
    write_png(&PathBuf::from(png), &images)?;
    println!("wrote {png}");
    Ok(())
}

/// The images side by side, exposed so that the brightest 1% saturates, Reinhard, sRGB.
fn write_png(path: &PathBuf, images: &[Vec<[f32; 4]>]) -> Result<(), Box<dyn std::error::Error>> {
    let mut luminance: Vec<f32> = images
        .iter()
        .flatten()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    luminance.sort_by(f32::total_cmp);
    let white = luminance[luminance.len() * 99 / 100].max(1e-6);
    let width = SIZE * images.len() as u32;
    let mut rgb = vec![0u8; (width * SIZE * 3) as usize];
    for (i, image) in images.iter().enumerate() {
        for (k, p) in image.iter().enumerate() {
            let (x, y) = (k as u32 % SIZE + i as u32 * SIZE, k as u32 / SIZE);
            for c in 0..3 {
                let v = p[c] / white;
                let v = (v / (1.0 + v) * 2.0).clamp(0.0, 1.0);
                let s = if v <= 0.0031308 {
                    12.92 * v
                } else {
                    1.055 * v.powf(1.0 / 2.4) - 0.055
                };
                rgb[((y * width + x) * 3 + c as u32) as usize] = (s * 255.0 + 0.5) as u8;
            }
        }
    }
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, SIZE);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(&rgb)?;
    Ok(())
}
