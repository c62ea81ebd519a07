//! `prt-bench render`: the Forward+ stage's cost and culling quality, brute force and tiled in
//! the same run. For each light count, a deterministic rig of point and spot lights (a third of
//! them spots) spread through the scene's bounds with ranges of 3-12% of its diagonal; frame
//! time split into depth pre-pass, culling and shading (each stage submitted and waited for on
//! its own, median of a few frames), and lights evaluated per shaded pixel.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use glam::Vec3;
use prt_bake::{BakeSettings, NoProgress};
use prt_cli::options::{camera_of, parse_size, parse_vec3};
use prt_format::{Light, LightKind};
use prt_render::{Camera, Culling, RenderSettings, Renderer, View};
use prt_runtime::gpu::{headless_device, wgpu, PrtRuntime, RuntimeSettings};

use crate::results::Out;

#[derive(clap::Args)]
pub struct RenderArgs {
    scene: PathBuf,
    /// Light counts (point and spot lights scattered through the scene).
    #[arg(long, value_delimiter = ',', default_value = "16,64,256,1024")]
    lights: Vec<usize>,
    /// Tile sizes of the tiled rows.
    #[arg(long, value_delimiter = ',', default_value = "16,64")]
    tiles: Vec<u32>,
    #[arg(long, value_parser = parse_size, default_value = "1280x720")]
    size: (u32, u32),
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<Vec3>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<Vec3>,
    #[arg(long, default_value_t = prt_render::camera::DEFAULT_FOV)]
    fov: f32,
    /// Bake with every material double-sided.
    #[arg(long)]
    double_sided: bool,
    /// Frames per stage (the median is reported).
    #[arg(long, default_value_t = 3)]
    frames: usize,
    #[command(flatten)]
    out: Out,
}

/// `prt-bench render`: the report of [`render`], printed and with `--out` written to
/// `render.md`.
pub fn run(args: RenderArgs) -> Result<()> {
    let bench = RenderBench {
        scene: &args.scene,
        bake: BakeSettings {
            double_sided: args.double_sided,
            ..BakeSettings::default()
        },
        camera: camera_of(args.eye, args.target, Some(args.fov))?,
        lights: args.lights,
        tiles: args.tiles,
        size: args.size,
        frames: args.frames.max(1),
    };
    args.out.report("render", &render(&bench)?)
}

/// What `prt-bench render` runs.
struct RenderBench<'a> {
    scene: &'a Path,
    bake: BakeSettings,
    camera: Option<Camera>,
    lights: Vec<usize>,
    tiles: Vec<u32>,
    size: (u32, u32),
    frames: usize,
}

/// A small deterministic generator (64-bit LCG, Knuth's MMIX constants): light rigs must be the
/// same in every run.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `count` point and spot lights in the box `lo..hi`, ranges 3-12% of its diagonal.
pub fn scattered_lights(count: usize, lo: Vec3, hi: Vec3) -> Vec<Light> {
    let mut rng = Lcg(0x5eed + count as u64);
    let diagonal = (hi - lo).length();
    (0..count)
        .map(|i| {
            let position = lo + (hi - lo) * Vec3::new(rng.next(), rng.next(), rng.next());
            let range = diagonal * (0.03 + 0.09 * rng.next());
            let spot = i % 3 == 2;
            let direction = Vec3::new(rng.next() - 0.5, -rng.next(), rng.next() - 0.5)
                .normalize_or(Vec3::NEG_Y);
            Light {
                kind: if spot {
                    LightKind::Spot
                } else {
                    LightKind::Point
                },
                position: position.to_array(),
                direction: direction.to_array(),
                color: [
                    0.5 + 0.5 * rng.next(),
                    0.5 + 0.5 * rng.next(),
                    0.5 + 0.5 * rng.next(),
                ],
                intensity: 0.05 * range * range,
                range: Some(range),
                inner_cone_angle: 0.2,
                outer_cone_angle: 0.4 + 0.5 * rng.next(),
            }
        })
        .collect()
}

/// Median seconds of `frames` runs of `f`, which submits and waits.
fn median(frames: usize, mut f: impl FnMut() -> Result<f64>) -> Result<f64> {
    let mut t: Vec<f64> = (0..frames).map(|_| f()).collect::<Result<_>>()?;
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

fn submit_wait(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    record: impl FnOnce(&mut wgpu::CommandEncoder),
) -> Result<f64> {
    let start = Instant::now();
    let mut encoder = device.create_command_encoder(&Default::default());
    record(&mut encoder);
    queue.submit([encoder.finish()]);
    device.poll(wgpu::PollType::wait_indefinitely())?;
    Ok(start.elapsed().as_secs_f64() * 1e3)
}

struct Row {
    lights: usize,
    culling: String,
    depth_ms: f64,
    cull_ms: f64,
    shade_ms: f64,
    per_pixel: f64,
    overflow: u32,
}

fn render(b: &RenderBench) -> Result<String> {
    let (asset, _) = prt_bake::bake(b.scene, &b.bake, &NoProgress)?;
    let scene = prt_scene::load(b.scene, &b.bake.allowed)?;
    let (lo, hi) = scene
        .bounds()
        .ok_or_else(|| anyhow::anyhow!("{}: no triangles", b.scene.display()))?;
    let camera = b.camera.unwrap_or_else(|| {
        scene
            .cameras
            .first()
            .map_or(Camera::framing(lo, hi), Camera::from_gltf)
    });
    let (device, queue, info) = headless_device()?;
    let mut rows = Vec::new();
    // (culling, tile, shadows): brute force, each tile size, and the first without shadow rays.
    let mut configs = vec![(Culling::None, 16, true)];
    configs.extend(b.tiles.iter().map(|&t| (Culling::Tiled, t, true)));
    configs.push((
        Culling::Tiled,
        b.tiles.first().copied().unwrap_or(16),
        false,
    ));
    for &count in &b.lights {
        let lights = scattered_lights(count, lo, hi);
        for &(culling, tile, shadows) in &configs {
            let settings = RenderSettings {
                width: b.size.0,
                height: b.size.1,
                tile,
                culling,
                shadows,
                ..RenderSettings::default()
            };
            let mut r = Renderer::new(&device, &scene, &asset, settings)?;
            r.set_lights(&queue, &lights)?;
            r.set_camera(&queue, &camera, View::Direct)?;
            // Warm-up frame: pipelines and memory.
            submit_wait(&device, &queue, |e| r.record(e, None))?;
            let depth_ms = median(b.frames, || {
                submit_wait(&device, &queue, |e| r.record_depth(e))
            })?;
            let cull_ms = median(b.frames, || {
                submit_wait(&device, &queue, |e| r.record_cull(e))
            })?;
            let shade_ms = median(b.frames, || {
                submit_wait(&device, &queue, |e| r.record_shade(e, None))
            })?;
            let frame = r.read_frame(&device, &queue)?;
            let shaded: Vec<f64> = frame
                .radiance
                .iter()
                .zip(&frame.position)
                .filter(|(_, p)| p[3] > 0.0)
                .map(|(c, _)| f64::from(c[3]))
                .collect();
            rows.push(Row {
                lights: count,
                culling: match (culling, shadows) {
                    (Culling::None, _) => "none (brute force)".into(),
                    (Culling::Tiled, true) => format!("tiled {tile} px"),
                    (Culling::Tiled, false) => format!("tiled {tile} px, no shadow rays"),
                },
                depth_ms,
                cull_ms,
                shade_ms,
                per_pixel: shaded.iter().sum::<f64>() / shaded.len().max(1) as f64,
                overflow: frame.stats.dropped,
            });
        }
    }
    let sampling = sampling_cost(&device, &queue, &scene, &asset, &camera, b)?;
    report(b, &info.name, &rows, sampling)
}

/// Shading cost of the indirect lookup: the indirect view with the default lookup (surface
/// terms, depth moments elsewhere), the same without its floor under L2's ringing
/// (`LookupSettings::ringing_floor` 0: what the floor costs), with depth moments alone, with
/// plain trilinear, and with an empty volume (the pass without any lookup work).
fn sampling_cost(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &prt_scene::Scene,
    asset: &prt_format::Asset,
    camera: &Camera,
    b: &RenderBench,
) -> Result<[f64; 5]> {
    let settings = RenderSettings {
        width: b.size.0,
        height: b.size.1,
        ..RenderSettings::default()
    };
    let mut r = Renderer::new(device, scene, asset, settings)?;
    r.set_lights(queue, &[])?;
    r.set_camera(queue, camera, View::Indirect)?;
    let lighting = prt_runtime::Lighting {
        rig: prt_format::LightRig {
            lights: Vec::new(),
            sky: None,
        },
        sky: prt_runtime::SkyModel::Constant([1.0; 3]),
    };
    let mut out = [0.0; 5];
    let floor = prt_runtime::LookupSettings::default().ringing_floor;
    let lookups = [
        (true, true, floor),
        (true, true, 0.0),
        (false, true, floor),
        (false, false, floor),
    ];
    for (k, (surface_terms, depth_moments, ringing_floor)) in lookups.into_iter().enumerate() {
        let runtime = RuntimeSettings {
            lookup: prt_runtime::LookupSettings {
                depth_moments,
                surface_terms,
                ringing_floor,
                ..Default::default()
            },
            ..RuntimeSettings::default()
        };
        let mut gi = PrtRuntime::new(device, queue, asset, runtime)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        gi.update(&mut encoder, &lighting, None)?;
        queue.submit([encoder.finish()]);
        let volume = r.volume_group(&gi);
        submit_wait(device, queue, |e| r.record(e, Some(&volume)))?;
        out[k] = median(b.frames, || {
            submit_wait(device, queue, |e| r.record_shade(e, Some(&volume)))
        })?;
    }
    out[4] = median(b.frames, || {
        submit_wait(device, queue, |e| r.record_shade(e, None))
    })?;
    Ok(out)
}

fn report(b: &RenderBench, adapter: &str, rows: &[Row], sampling: [f64; 5]) -> Result<String> {
    let mut md = String::new();
    writeln!(
        md,
        "Adapter: {adapter}; {}x{} pixels; median of {} frames per stage.\n",
        b.size.0, b.size.1, b.frames
    )?;
    writeln!(md, "| lights | culling | depth ms | cull ms | shade ms | frame ms | lights/pixel | fewer evaluations | frame speed-up | dropped |")?;
    writeln!(md, "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    let mut brute = (0.0, 0.0);
    for r in rows {
        let frame = r.depth_ms + r.cull_ms + r.shade_ms;
        if r.culling.starts_with("none") {
            brute = (frame, r.per_pixel);
        }
        writeln!(
            md,
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1}x | {:.2}x | {} |",
            r.lights,
            r.culling,
            r.depth_ms,
            r.cull_ms,
            r.shade_ms,
            frame,
            r.per_pixel,
            brute.1 / r.per_pixel.max(1e-9),
            brute.0 / frame,
            r.overflow
        )?;
    }
    writeln!(
        md,
        "\nIndirect lookup, shading pass of the indirect view: {:.2} ms default (surface terms \
         where a pixel has a surfel: a hash search of one or two 4-word slots, a cell word, 4 \
         words of terms and 3 of its brick, 8 probes with 56 texel loads and one near value; depth moments \
         elsewhere), {:.2} ms the same without its floor under L2's ringing, {:.2} ms depth moments alone (8 \
         probes, 56 texel loads, 8 visibility words per pixel), {:.2} ms plain trilinear (7 \
         filtered fetches), {:.2} ms with an empty volume (no lookup work).",
        sampling[0], sampling[1], sampling[2], sampling[3], sampling[4]
    )?;
    Ok(md)
}
