//! Levels whose surfaces the bake cannot classify (issue 31, bad input): a single plane, a solid
//! with no room around it, and a stack of plates 1 cm apart where every probe sits in a gap far
//! narrower than the spacing. Each bakes, relights and samples (CPU twin and the GPU snippet)
//! without a NaN, a negative value or a black hole under open sky, and the bake says what it
//! could not decide.

use prt_bake::{BakeSettings, NoProgress};
use prt_format::Asset;
use prt_runtime::gpu::{sample_points, wgpu, PrtRuntime, RuntimeSettings};
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, Lighting, LookupSettings};
use prt_tests::{fixture, gpu_device};

/// Bakes a fixture with the default settings; the asset and the bake's warnings.
fn bake(name: &str) -> (Asset, Vec<String>) {
    bake_with(name, &BakeSettings::default())
}

fn bake_with(name: &str, settings: &BakeSettings) -> (Asset, Vec<String>) {
    let (asset, report) = prt_bake::bake(&fixture(name), settings, &NoProgress).unwrap();
    (asset, report.warnings)
}

/// Points that face up from the top of the scene's bounds downwards in a grid, and every 50th
/// surfel: `(position, normal)`.
fn points(asset: &Asset, top: f32) -> Vec<([f32; 3], [f32; 3])> {
    let g = asset.header.grid;
    let extent: [f32; 3] = std::array::from_fn(|a| (g.counts[a] - 1) as f32 * g.step[a]);
    let mut out: Vec<([f32; 3], [f32; 3])> = (0..64)
        .map(|i| {
            let (u, v) = ((i % 8) as f32 / 7.0, (i / 8) as f32 / 7.0);
            (
                [
                    g.origin[0] + (0.05 + 0.9 * u) * extent[0],
                    top,
                    g.origin[2] + (0.05 + 0.9 * v) * extent[2],
                ],
                [0.0, 1.0, 0.0],
            )
        })
        .collect();
    out.extend(
        asset
            .surfels
            .iter()
            .step_by(50)
            .map(|s| (s.position, s.normal)),
    );
    out
}

/// Relights `asset` on the CPU and on the GPU and samples `points` with both: every value
/// finite and non-negative, and each of the first `lit` points (facing open sky) lit.
fn sample_everywhere(
    asset: &Asset,
    lighting: &Lighting,
    points: &[([f32; 3], [f32; 3])],
    lit: usize,
) {
    assert!(points.len() > lit, "{} points", points.len());
    let relit = CpuRelighter::new(asset)
        .unwrap()
        .relight(lighting, 1)
        .unwrap();
    let cpu = SurfaceSampler::for_relit(asset, &relit, &LookupSettings::default());
    let (device, queue) = gpu_device();
    let mut runtime = PrtRuntime::new(&device, &queue, asset, RuntimeSettings::default()).unwrap();
    loop {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let report = runtime.update(&mut encoder, lighting, None).unwrap();
        queue.submit([encoder.finish()]);
        if report.pending_windows == 0 {
            break;
        }
    }
    let gpu = sample_points(&device, &queue, &runtime, points).unwrap();
    for (i, ((p, n), g)) in points.iter().zip(&gpu).enumerate() {
        let c = cpu.sample(*p, *n);
        for (what, e) in [("cpu", c.irradiance), ("gpu", g.irradiance)] {
            assert!(
                e.iter().all(|v| v.is_finite() && *v >= 0.0),
                "{what} at {p:?} {n:?}: {e:?}"
            );
            if i < lit {
                assert!(e.iter().sum::<f32>() > 0.0, "{what}: black at {p:?}");
            }
        }
        assert!(
            g.sh.iter().flatten().all(|v| v.is_finite()),
            "gpu SH at {p:?}"
        );
    }
}

/// A single plane under sun and sky: nothing to classify, and nothing goes dark.
#[test]
fn a_single_plane_bakes_and_samples() {
    let (asset, _) = bake("textured_quad.gltf");
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    let top = asset.header.grid.origin[1];
    sample_everywhere(&asset, &lighting, &points(&asset, top), 64);
}

/// A closed solid with no room around it (its faces seen from outside only): on the uniform
/// grid, most probes inside it, the bake warns of the probes inside geometry; sparse (the
/// default) traces only the layers beside its faces and the coarse levels inside. Every sample
/// of both stays finite.
#[test]
fn a_solid_without_a_room_bakes_and_samples() {
    let uniform = BakeSettings {
        sparse: false,
        ..BakeSettings::default()
    };
    let (asset, warnings) = bake_with("closed_box_outward.gltf", &uniform);
    assert!(
        warnings.iter().any(|w| w.contains("inside geometry")),
        "{warnings:?}"
    );
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    sample_everywhere(&asset, &lighting, &points(&asset, 0.0)[64..], 0);
    let (asset, _) = bake("closed_box_outward.gltf");
    sample_everywhere(&asset, &lighting, &points(&asset, 0.0)[64..], 0);
}

/// 30 plates 1 cm apart (fixtures/pocket_stack.gltf, default spacing 0.17 m): the bake says that
/// the probes between them sit in gaps, and the plates' outer faces under sun and sky stay lit.
#[test]
fn probes_in_gaps_are_reported_and_sample_finite() {
    let (asset, warnings) = bake("pocket_stack.gltf");
    let warned = warnings
        .iter()
        .find(|w| w.contains("sit in gaps"))
        .unwrap_or_else(|| panic!("no gap warning: {warnings:?}"));
    assert!(warned.contains("--spacing"), "{warned}");
    let summary = prt_format::Summary::of(&asset, 0);
    assert!(
        summary.probes_in_gaps * 4 > summary.valid_probe_count,
        "{} of {} probes in gaps",
        summary.probes_in_gaps,
        summary.valid_probe_count
    );
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    // The top plate's upper face, at y = 0.29.
    sample_everywhere(&asset, &lighting, &points(&asset, 0.29), 64);
}
