//! The Forward+ renderer against its references, on lavapipe: tiled culling equals brute force
//! per pixel, direct light equals the runtime's CPU light model, indirect light equals the CPU
//! twin of the volume lookup, and golden images of every view catch real changes.

// Pixels and colour channels index several parallel arrays with one index.
#![allow(clippy::needless_range_loop)]

use std::path::PathBuf;

use glam::Vec3;
use prt_bake::BakeSettings;
use prt_format::Asset;
use prt_render::job::{self, Output, RenderJob};
use prt_render::{Camera, Culling, Frame, RenderSettings, Renderer, View};
use prt_runtime::gpu::{PrtRuntime, RuntimeSettings};
use prt_runtime::lights::PreparedLight;
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, Lighting};
use prt_tests::{bake_ok, fixture, gpu_device, ScratchDir};

use prt_runtime::gpu::wgpu;

fn cornell_scene() -> PathBuf {
    fixture("cornell/cornell.gltf")
}

/// Looks into the Cornell room through its open front.
fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.3, 1.2, 3.2),
        target: Vec3::new(0.0, 0.9, 0.0),
        up: Vec3::Y,
        fov_degrees: 45.0,
    }
}

fn settings(tile: u32, culling: Culling, shadows: bool) -> RenderSettings {
    RenderSettings {
        width: 320,
        height: 180,
        tile,
        culling,
        shadows,
        ..RenderSettings::default()
    }
}

struct Setup {
    device: wgpu::Device,
    queue: wgpu::Queue,
    scene: prt_scene::Scene,
    asset: Asset,
}

fn setup() -> Setup {
    let (device, queue) = gpu_device();
    let scene = prt_scene::load(&cornell_scene(), &Default::default()).unwrap();
    let asset = bake_ok(&cornell_scene(), &BakeSettings::default());
    Setup {
        device,
        queue,
        scene,
        asset,
    }
}

fn render(
    s: &Setup,
    settings: RenderSettings,
    lighting: &Lighting,
    view: View,
    gi: Option<&PrtRuntime>,
) -> (Frame, Vec<u32>) {
    let mut r = Renderer::new(&s.device, &s.scene, &s.asset, settings).unwrap();
    r.set_lights(&s.queue, &lighting.rig.lights).unwrap();
    r.set_camera(&s.queue, &camera(), view).unwrap();
    let mut encoder = s.device.create_command_encoder(&Default::default());
    let volume = gi.map(|g| r.volume_group(g));
    r.record(&mut encoder, volume.as_ref());
    s.queue.submit([encoder.finish()]);
    let frame = r.read_frame(&s.device, &s.queue).unwrap();
    let counts = r.read_tile_counts(&s.device, &s.queue).unwrap();
    (frame, counts)
}

fn peak(frame: &Frame) -> f32 {
    frame
        .radiance
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0.0, f32::max)
}

/// Tiled lists never miss a light: the image equals the brute-force loop per pixel, at tile
/// sizes 16 and 64, on 256 point and spot lights of mixed ranges (plus a sun), with shadows.
#[test]
fn forward_plus_equals_brute_force() {
    let s = setup();
    let lighting = load_rig(&fixture("rigs/cornell_256.json")).unwrap();
    assert_eq!(lighting.rig.lights.len(), 257);
    let (reference, _) = render(
        &s,
        settings(16, Culling::None, true),
        &lighting,
        View::Direct,
        None,
    );
    let top = peak(&reference);
    assert!(top > 0.0);
    let brute: f64 = reference.radiance.iter().map(|p| f64::from(p[3])).sum();
    for tile in [16, 64] {
        let (tiled, counts) = render(
            &s,
            settings(tile, Culling::Tiled, true),
            &lighting,
            View::Direct,
            None,
        );
        assert_eq!(tiled.stats.dropped, 0, "no tile overflowed");
        assert!(counts.iter().any(|&c| c > 0));
        let mut worst = 0.0f32;
        for (a, b) in tiled.radiance.iter().zip(&reference.radiance) {
            for c in 0..3 {
                let err = (a[c] - b[c]).abs() / b[c].abs().max(1e-6 * top);
                worst = worst.max(err);
            }
        }
        assert!(
            worst <= 1e-4,
            "tile {tile}: worst relative difference {worst}"
        );
        let listed: f64 = tiled.radiance.iter().map(|p| f64::from(p[3])).sum();
        let gain = if tile == 16 { 4.0 } else { 1.0 };
        assert!(
            listed * gain < brute,
            "tile {tile}: {listed} evaluations vs {brute} brute force"
        );
    }
}

/// The shaded direct term equals `runtime/src/lights.rs` at the same world positions and normals
/// (shadows off, so that every light counts), within 1e-3 relative.
#[test]
fn direct_light_equals_the_cpu_light_model() {
    let s = setup();
    let lighting = load_rig(&fixture("rigs/cornell_256.json")).unwrap();
    let (direct, _) = render(
        &s,
        settings(16, Culling::Tiled, false),
        &lighting,
        View::Direct,
        None,
    );
    let (albedo, _) = render(
        &s,
        settings(16, Culling::Tiled, false),
        &lighting,
        View::Albedo,
        None,
    );
    let lights: Vec<PreparedLight> = lighting.rig.lights.iter().map(PreparedLight::new).collect();
    let mut checked = 0;
    for i in (0..direct.radiance.len()).step_by(97) {
        if direct.position[i][3] == 0.0 {
            continue;
        }
        let p = Vec3::from_slice(&direct.position[i][..3]);
        let n = Vec3::from_slice(&direct.normal[i][..3]);
        let e: Vec3 = lights.iter().map(|l| l.irradiance(p, n).0).sum();
        let a = Vec3::from_slice(&albedo.radiance[i][..3]);
        let expected = a * e / std::f32::consts::PI;
        let got = Vec3::from_slice(&direct.radiance[i][..3]);
        for c in 0..3 {
            let tol = 1e-3 * expected[c].abs() + 1e-6;
            assert!(
                (got[c] - expected[c]).abs() <= tol,
                "pixel {i} at {p} n {n}: gpu {got} cpu {expected}"
            );
        }
        checked += 1;
    }
    assert!(checked > 100, "{checked} pixels checked");
}

fn gi(s: &Setup, lighting: &Lighting) -> PrtRuntime {
    let mut rt =
        PrtRuntime::new(&s.device, &s.queue, &s.asset, RuntimeSettings::default()).unwrap();
    let mut encoder = s.device.create_command_encoder(&Default::default());
    rt.update(&mut encoder, lighting, None).unwrap();
    s.queue.submit([encoder.finish()]);
    rt.wait().unwrap();
    rt
}

/// The indirect term equals albedo / pi times the CPU twin of the lookup (`SurfaceSampler`: the
/// surface terms where a pixel has a surfel, the volume's depth-moment lookup elsewhere; near
/// fields lit by the CPU relight) at the same points, and lit = direct + indirect.
#[test]
fn indirect_light_equals_the_cpu_lookup() {
    let s = setup();
    let lighting = load_rig(&fixture("cornell/rig.json")).unwrap();
    let rt = gi(&s, &lighting);
    let sh = rt.read_probe_sh().unwrap();
    let relit = CpuRelighter::new(&s.asset)
        .unwrap()
        .relight(&lighting, 1)
        .unwrap();
    let radiance = &relit.surfel_radiance;
    let sampler = SurfaceSampler::new(&s.asset, &sh, radiance, relit.sky, &rt.settings().lookup);
    let st = settings(16, Culling::Tiled, true);
    let (indirect, _) = render(&s, st, &lighting, View::Indirect, Some(&rt));
    let (albedo, _) = render(&s, st, &lighting, View::Albedo, None);
    let (direct, _) = render(&s, st, &lighting, View::Direct, None);
    let (lit, _) = render(&s, st, &lighting, View::Lit, Some(&rt));
    let top = peak(&indirect);
    let mut checked = 0;
    for i in (0..indirect.radiance.len()).step_by(53) {
        if indirect.position[i][3] == 0.0 {
            continue;
        }
        let p: [f32; 3] = std::array::from_fn(|c| indirect.position[i][c]);
        let n: [f32; 3] = std::array::from_fn(|c| indirect.normal[i][c]);
        let e = sampler.sample(p, n).irradiance;
        for c in 0..3 {
            let expected = albedo.radiance[i][c] * e[c] / std::f32::consts::PI;
            let got = indirect.radiance[i][c];
            // Half-float texels and the sampler's fixed-point filter weights.
            let tol = 1e-2 * expected.abs() + 2e-3 * top;
            assert!(
                (got - expected).abs() <= tol,
                "pixel {i} at {p:?} n {n:?}: gpu {got} cpu {expected}"
            );
            let sum = direct.radiance[i][c] + got;
            assert!(
                (lit.radiance[i][c] - sum).abs() <= 1e-5 * sum.abs().max(top),
                "lit = direct + indirect at {i}"
            );
        }
        checked += 1;
    }
    assert!(checked > 100, "{checked} pixels checked");
}

fn read_png(path: &std::path::Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// Mean and 99th percentile of the per-channel 8-bit difference between two images.
fn image_difference(a: &[u8], b: &[u8]) -> (f64, u8) {
    assert_eq!(a.len(), b.len());
    let mut d: Vec<u8> = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).collect();
    let mean = d.iter().map(|&v| f64::from(v)).sum::<f64>() / d.len() as f64;
    d.sort_unstable();
    (mean, d[d.len() * 99 / 100])
}

/// Golden thresholds: an image passes when its mean 8-bit difference is at most 0.5 levels and
/// its 99th percentile at most 6 levels (lavapipe runs vary in the last bits of the GI's half
/// floats and of transcendental functions).
const GOLDEN_MEAN: f64 = 0.5;
const GOLDEN_P99: u8 = 6;

fn golden_job(
    dir: &std::path::Path,
    asset: &std::path::Path,
    rig: &std::path::Path,
    output: Output,
    name: &str,
) -> RenderJob {
    RenderJob {
        scene: cornell_scene(),
        asset: asset.to_owned(),
        lights: Some(rig.to_owned()),
        png: dir.join(name),
        exr: None,
        camera: Some(camera()),
        fov: None,
        output,
        exposure_ev: 0.0,
        settings: settings(16, Culling::Tiled, true),
        runtime: RuntimeSettings::default(),
        force: false,
        allowed: Default::default(),
    }
}

/// One golden image per view of the Cornell fixture (tests/golden/, rewritten with
/// PRT_UPDATE_GOLDEN=1), and a moved light fails the comparison.
#[test]
fn golden_images_of_every_view() {
    let dir = ScratchDir::new("golden");
    let asset_path = dir.path().join("cornell.prt");
    prt_bake::bake_to_file(
        &cornell_scene(),
        &asset_path,
        &BakeSettings::default(),
        &prt_bake::NoProgress,
    )
    .unwrap();
    let asset = prt_format::read_asset(&asset_path).unwrap();
    let rig_path = fixture("cornell/rig.json");
    let lighting = load_rig(&rig_path).unwrap();
    let golden_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden");
    let update = std::env::var_os("PRT_UPDATE_GOLDEN").is_some();
    for (output, name) in [
        (Output::Lit, "cornell_lit.png"),
        (Output::Direct, "cornell_direct.png"),
        (Output::Indirect, "cornell_indirect.png"),
        (Output::Albedo, "cornell_albedo.png"),
        (Output::Heatmap, "cornell_heatmap.png"),
    ] {
        let job = golden_job(dir.path(), &asset_path, &rig_path, output, name);
        job::run(&job, &lighting, &asset).unwrap();
        let golden = golden_dir.join(name);
        if update {
            std::fs::create_dir_all(&golden_dir).unwrap();
            std::fs::copy(&job.png, &golden).unwrap();
            continue;
        }
        let (w, h, got) = read_png(&job.png);
        let (gw, gh, want) = read_png(&golden);
        assert_eq!((w, h), (gw, gh), "{name} size");
        let (mean, p99) = image_difference(&got, &want);
        assert!(
            mean <= GOLDEN_MEAN && p99 <= GOLDEN_P99,
            "{name}: mean {mean:.3}, p99 {p99} levels off the golden image"
        );
    }
    // A real change fails: the point light moved by 0.4 m.
    let mut moved = lighting.clone();
    for l in &mut moved.rig.lights {
        if l.kind == prt_format::LightKind::Point {
            l.position[0] += 0.4;
        }
    }
    let moved_rig = dir.path().join("moved.json");
    std::fs::write(&moved_rig, serde_json::to_vec(&moved.rig).unwrap()).unwrap();
    let job = golden_job(
        dir.path(),
        &asset_path,
        &moved_rig,
        Output::Lit,
        "moved.png",
    );
    job::run(&job, &moved, &asset).unwrap();
    let (_, _, got) = read_png(&job.png);
    let (_, _, want) = read_png(&golden_dir.join("cornell_lit.png"));
    let (mean, p99) = image_difference(&got, &want);
    assert!(
        mean > GOLDEN_MEAN || p99 > GOLDEN_P99,
        "a moved light must fail: mean {mean:.3}, p99 {p99}"
    );
}

/// Rendering with a scene other than the asset's source is refused unless forced.
#[test]
fn an_asset_from_another_scene_is_refused() {
    let asset = bake_ok(&cornell_scene(), &BakeSettings::default());
    let other = fixture("lights.gltf");
    let bytes = std::fs::read(&other).unwrap();
    let err =
        job::check_source(&other, &bytes, std::path::Path::new("cornell.prt"), &asset).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("lights.gltf") && msg.contains("--force"),
        "{msg}"
    );
    let own = std::fs::read(cornell_scene()).unwrap();
    job::check_source(
        &cornell_scene(),
        &own,
        std::path::Path::new("cornell.prt"),
        &asset,
    )
    .unwrap();
}
