//! The GPU runtime against the CPU reference relight, on lavapipe in CI. A missing adapter is a
//! test failure (`headless_device` errors loudly), never a skip.

use std::path::Path;

use prt_bake::BakeSettings;
use prt_format::sh::ShRgb;
use prt_format::{Asset, Light, LightKind, LightRig, Sky};
use prt_runtime::gpu::{
    sample_points, sh_from_texels, wgpu, PrtRuntime, RuntimeSettings, VolumeFormat,
};
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, Lighting, LookupSettings, SkyModel};
use prt_tests::{bake_ok as bake, fixture, gpu_device};

fn cpu(asset: &Asset, lighting: &Lighting) -> Vec<ShRgb> {
    CpuRelighter::new(asset)
        .unwrap()
        .relight(lighting, 1)
        .unwrap()
        .sh
}

/// Runs updates until the round-robin cycle is done; returns the probes' SH.
fn gpu_update(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    runtime: &mut PrtRuntime,
    lighting: &Lighting,
    budget: Option<u32>,
) -> Vec<ShRgb> {
    loop {
        let mut encoder = device.create_command_encoder(&Default::default());
        let report = runtime.update(&mut encoder, lighting, budget).unwrap();
        queue.submit([encoder.finish()]);
        if report.pending_windows == 0 {
            break;
        }
    }
    runtime.read_probe_sh().unwrap()
}

/// |gpu - cpu| <= 1e-4 |SH0| per coefficient; an absolute floor of 1e-7 of the volume's largest
/// SH0 keeps nearly black probes (where float rounding dominates) from failing on noise.
fn assert_close(label: &str, asset: &Asset, gpu: &[ShRgb], cpu: &[ShRgb], rel: f32) {
    let peak = cpu
        .iter()
        .map(|c| c[0].iter().fold(0.0f32, |m, v| m.max(v.abs())))
        .fold(0.0, f32::max);
    let mut compared = 0;
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        if !asset.probes[i].is_valid() {
            continue;
        }
        compared += 1;
        let dc = c[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        for k in 0..9 {
            for ch in 0..3 {
                let tol = rel * dc + 1e-7 * peak;
                assert!(
                    (g[k][ch] - c[k][ch]).abs() <= tol && g[k][ch].is_finite(),
                    "{label}: probe {i} k {k} ch {ch}: gpu {} cpu {} (tol {tol})",
                    g[k][ch],
                    c[k][ch]
                );
            }
        }
    }
    assert!(compared > 0, "{label}: no valid probe compared");
}

/// Reads the volume back and rebuilds each probe's SH from its seven texels.
fn volume_sh(runtime: &PrtRuntime) -> Vec<Option<ShRgb>> {
    let v = runtime.read_volume().unwrap();
    (0..v[0].len())
        .map(|p| sh_from_texels(std::array::from_fn(|t| v[t][p])))
        .collect()
}

/// GPU equals the CPU reference on the Cornell reference scene (unmerged f32 factors, default
/// merged u8 and f16 factors, far hits in coarse bricks, sparse placement) with point, spot with range,
/// directional and sky; the f32 volume read back equals the probe SH exactly (a filled point's to
/// float rounding: its SH is filled on the CPU when read back), the f16 volume within half-float
/// rounding.
#[test]
fn gpu_equals_cpu_on_cornell() {
    let (device, queue) = gpu_device();
    let scene = fixture("cornell/cornell.gltf");
    let reference_grid = BakeSettings {
        spacing: Some(0.6),
        bounds: Some([-0.6, 0.4, -0.6, 0.6, 1.6, 0.6]),
        ..BakeSettings::exact()
    };
    for (settings, format) in [
        (reference_grid, VolumeFormat::F32),
        (BakeSettings::default(), VolumeFormat::F16),
        (
            BakeSettings {
                transfer_precision: prt_format::TransferPrecision::F16,
                ..BakeSettings::default()
            },
            VolumeFormat::F32,
        ),
        (
            BakeSettings {
                far_ratio: 2.0,
                ..BakeSettings::default()
            },
            VolumeFormat::F32,
        ),
        (
            BakeSettings {
                far_ratio: 2.0,
                transfer_precision: prt_format::TransferPrecision::F16,
                ..BakeSettings::default()
            },
            VolumeFormat::F32,
        ),
        // Sky masks and transfers in slot order, probes left out never gathered but filled
        // from a coarse level (stage 9).
        (
            BakeSettings {
                sparse: true,
                ..BakeSettings::default()
            },
            VolumeFormat::F32,
        ),
        // Probes a budget dropped, filled from level 1 without the corners walls hide from them.
        (
            BakeSettings {
                probe_budget: Some(1000),
                ..BakeSettings::default()
            },
            VolumeFormat::F32,
        ),
    ] {
        let asset = bake(&scene, &settings);
        if settings.probe_budget.is_some() {
            let hidden = asset.probes.iter().filter(|p| p.fill_hidden() != 0).count();
            assert!(hidden > 0, "no filled probe with hidden corners to test");
        }
        assert_eq!(
            asset.coarse.bricks.is_empty(),
            settings.far_ratio == 0.0,
            "coarse bricks exactly when far hits go to them"
        );
        for rig in ["rig.json", "rig_spot.json", "rig_spot_range.json"] {
            let lighting = load_rig(&fixture(&format!("cornell/{rig}"))).unwrap();
            let mut runtime = PrtRuntime::new(
                &device,
                &queue,
                &asset,
                RuntimeSettings {
                    volume_format: format,
                    ..RuntimeSettings::default()
                },
            )
            .unwrap();
            let gpu = gpu_update(&device, &queue, &mut runtime, &lighting, None);
            let reference = cpu(&asset, &lighting);
            assert_close(rig, &asset, &gpu, &reference, 1e-4);
            for (p, texel) in volume_sh(&runtime).iter().enumerate() {
                let Some(t) = texel else {
                    assert!(!asset.probes[p].is_valid(), "valid probe {p} has no texel");
                    continue;
                };
                for k in 0..9 {
                    for ch in 0..3 {
                        let (a, b) = (t[k][ch], gpu[p][k][ch]);
                        match format {
                            // A filled point's texels are the GPU's fill, its SH the CPU's fill
                            // of the read-back corners (`read_probe_sh`): the same sums, in
                            // floats a GPU may contract.
                            VolumeFormat::F32 if asset.probes[p].is_filled() => assert!(
                                (a - b).abs() <= 1e-6 * gpu[p][0][ch].abs() + 1e-9,
                                "filled texel {p} k {k}: {a} vs {b}"
                            ),
                            VolumeFormat::F32 => assert_eq!(a, b, "texel {p} k {k}"),
                            VolumeFormat::F16 => assert!(
                                (a - b).abs() <= b.abs() / 1024.0 + 1e-7,
                                "texel {p} k {k}: {a} vs {b}"
                            ),
                        }
                    }
                }
            }
        }
    }
}

/// GPU equals CPU on every shared scene with a rig of every light type and a sky.
#[test]
fn gpu_equals_cpu_on_shared_scenes() {
    let (device, queue) = gpu_device();
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    for scene in [
        "cornell_box.glb",
        "room.glb",
        "sunshadowTest.glb",
        "sponza_lod4.glb",
    ] {
        // sponza_lod4's surfaces face away from the atrium (fixtures/scenes/README.md): bake it
        // double-sided.
        let settings = BakeSettings {
            rays: 256,
            double_sided: true,
            ..BakeSettings::default()
        };
        let asset = bake(&fixture(&format!("scenes/{scene}")), &settings);
        let mut runtime =
            PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default()).unwrap();
        let gpu = gpu_update(&device, &queue, &mut runtime, &lighting, None);
        assert_close(scene, &asset, &gpu, &cpu(&asset, &lighting), 1e-4);
    }
}

fn rig(intensity: f32, point_x: f32) -> Lighting {
    let rig = LightRig {
        lights: vec![
            Light {
                kind: LightKind::Point,
                position: [point_x, 1.5, 0.0],
                direction: [0.0, -1.0, 0.0],
                color: [1.0, 0.9, 0.8],
                intensity,
                range: Some(4.0),
                inner_cone_angle: 0.0,
                outer_cone_angle: 0.7,
            },
            Light {
                kind: LightKind::Directional,
                position: [0.0; 3],
                direction: [-0.35, -0.55, -0.76],
                color: [1.0; 3],
                intensity: 2.0,
                range: None,
                inner_cone_angle: 0.0,
                outer_cone_angle: 0.7,
            },
        ],
        sky: Some(Sky {
            color: Some([0.2, 0.3, 0.5]),
            exr: None,
            intensity: 1.0,
        }),
    };
    Lighting::from_rig(rig, Path::new("."), Path::new("test rig")).unwrap()
}

/// Amortised updates converge exactly to the full update, a gathered probe's texel never mixes
/// two updates (a filled point's follows its corners as they are gathered), nothing is
/// recomputed when nothing changed, and an intensity change traces no shadow ray.
#[test]
fn amortised_updates_and_skipped_work() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let settings = RuntimeSettings {
        volume_format: VolumeFormat::F32,
        ..RuntimeSettings::default()
    };
    let (a, b) = (rig(3.0, 0.0), rig(6.0, 0.3));
    let mut full = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    gpu_update(&device, &queue, &mut full, &a, None);
    let volume_a = volume_sh(&full);
    let full_b = gpu_update(&device, &queue, &mut full, &b, None);
    let volume_b = volume_sh(&full);

    let mut amortised = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    gpu_update(&device, &queue, &mut amortised, &a, None);
    let budget = 97;
    let mut updates = 0;
    loop {
        let mut encoder = device.create_command_encoder(&Default::default());
        let report = amortised.update(&mut encoder, &b, Some(budget)).unwrap();
        queue.submit([encoder.finish()]);
        updates += 1;
        let texels = volume_sh(&amortised);
        for (p, texel) in texels.iter().enumerate() {
            assert!(
                asset.probes[p].is_filled() || *texel == volume_a[p] || *texel == volume_b[p],
                "update {updates}: probe {p} mixes two updates"
            );
        }
        // A filled point holds the interpolation of its corners as they are now.
        let mut filled: Vec<ShRgb> = texels.iter().map(|t| t.unwrap_or_default()).collect();
        prt_runtime::fill::fill(&asset, &mut filled);
        for (p, _) in asset
            .probes
            .iter()
            .enumerate()
            .filter(|(_, q)| q.is_filled())
        {
            let got = texels[p].unwrap_or_default();
            for k in 0..9 {
                for c in 0..3 {
                    let (a, b) = (got[k][c], filled[p][k][c]);
                    let tol = 1e-6 * filled[p][0][c].abs() + 1e-9;
                    assert!(
                        (a - b).abs() <= tol,
                        "update {updates}: filled {p} k {k}: {a} vs {b}"
                    );
                }
            }
        }
        if report.pending_windows == 0 {
            break;
        }
    }
    // The round robin visits the valid probes only.
    let valid = asset.probes.iter().filter(|p| p.is_valid()).count();
    assert!(valid < asset.probes.len());
    assert_eq!(updates, valid.div_ceil(budget as usize));
    assert_eq!(
        amortised.read_probe_sh().unwrap(),
        full_b,
        "converged to the full update"
    );
    assert_eq!(volume_sh(&amortised), volume_b);

    let mut encoder = device.create_command_encoder(&Default::default());
    let idle = amortised.update(&mut encoder, &b, Some(budget)).unwrap();
    queue.submit([encoder.finish()]);
    assert!(idle.idle, "nothing changed: nothing recorded");

    let brighter = rig(9.0, 0.3);
    let mut encoder = device.create_command_encoder(&Default::default());
    amortised.update(&mut encoder, &brighter, None).unwrap();
    queue.submit([encoder.finish()]);
    let counters = amortised.read_counters().unwrap();
    assert_eq!(
        counters.shadow_rays, 0,
        "shadow ray cached for a light that did not move"
    );
    assert!(counters.bricks_relit > 0 && (counters.bricks_relit as usize) < asset.bricks.len());
    assert_close(
        "after intensity change",
        &asset,
        &amortised.read_probe_sh().unwrap(),
        &cpu(&asset, &brighter),
        1e-4,
    );
}

/// A 4x2 image sky: warm top row, cool bottom row (docs/conventions.md section 3 mapping).
fn warm_over_cool() -> SkyModel {
    SkyModel::Equirect {
        width: 4,
        height: 2,
        texels: [[1.0, 0.8, 0.6]; 4]
            .into_iter()
            .chain([[0.1, 0.2, 0.4]; 4])
            .collect(),
    }
}

/// Hostile values: zero lights, sky only, all probes invalid, intensities from 1e-6 to 1e6
/// (beyond half range: clamped, never infinite), and a long, thin volume at the device's largest
/// 3D texture dimension.
#[test]
fn hostile_values_stay_finite() {
    let (device, queue) = gpu_device();
    let cornell = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let most = cornell
        .probes
        .iter()
        .map(|p| p.factor_count)
        .max()
        .unwrap_or(0);
    assert!(
        most > prt_runtime::contract::GATHER_WORKGROUP,
        "a probe has more factor slots ({most}) than gather threads"
    );
    let no_lights = Lighting {
        rig: LightRig::default(),
        sky: SkyModel::Black,
    };
    let sky_only = load_rig(&fixture("rigs/sky_only.json")).unwrap();
    for (label, lighting) in [
        ("no lights", no_lights),
        ("sky only", sky_only),
        ("1e-6", rig(1e-6, 0.0)),
        ("1e6", rig(1e6, 0.0)),
        (
            "equirect sky",
            Lighting {
                rig: LightRig::default(),
                sky: warm_over_cool(),
            },
        ),
    ] {
        let mut runtime =
            PrtRuntime::new(&device, &queue, &cornell, RuntimeSettings::default()).unwrap();
        let gpu = gpu_update(&device, &queue, &mut runtime, &lighting, None);
        assert_close(label, &cornell, &gpu, &cpu(&cornell, &lighting), 1e-4);
        for texel in volume_sh(&runtime).into_iter().flatten() {
            assert!(
                texel
                    .iter()
                    .flatten()
                    .all(|v| v.is_finite() && v.abs() <= 65504.0),
                "{label}"
            );
        }
    }

    // 100 rays: the sky masks' last word holds 4 rays (`sky_word`'s partial word), full in
    // an empty scene.
    let image_sky = Lighting {
        rig: LightRig::default(),
        sky: warm_over_cool(),
    };
    for (scene, bounds) in [
        ("cornell/cornell.gltf", None),
        ("empty.gltf", Some([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])),
    ] {
        let settings = BakeSettings {
            rays: 100,
            bounds,
            ..BakeSettings::default()
        };
        let asset = bake(&fixture(scene), &settings);
        let mut runtime =
            PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default()).unwrap();
        let gpu = gpu_update(&device, &queue, &mut runtime, &image_sky, None);
        assert_close(scene, &asset, &gpu, &cpu(&asset, &image_sky), 1e-4);
    }

    let inside = BakeSettings {
        spacing: Some(0.5),
        bounds: Some([-0.5, -0.5, -0.5, 0.5, 0.5, 0.5]),
        ..BakeSettings::default()
    };
    let invalid = bake(&fixture("closed_box_outward.gltf"), &inside);
    assert!(invalid.probes.iter().all(|p| !p.is_valid()));
    let mut runtime =
        PrtRuntime::new(&device, &queue, &invalid, RuntimeSettings::default()).unwrap();
    let sh = gpu_update(&device, &queue, &mut runtime, &rig(3.0, 0.0), None);
    assert!(sh.iter().flatten().flatten().all(|v| *v == 0.0));
    assert!(
        volume_sh(&runtime).iter().all(Option::is_none),
        "invalid probes have validity 0"
    );

    let max_dim = device.limits().max_texture_dimension_3d;
    let line = BakeSettings {
        rays: 64,
        spacing: Some(1.0),
        bounds: Some([0.0, 0.0, 0.0, (max_dim - 1) as f32, 0.0, 0.0]),
        max_probes: u64::from(max_dim) + 1,
        ..BakeSettings::default()
    };
    let empty = bake(&fixture("empty.gltf"), &line);
    assert_eq!(empty.header.grid.counts, [max_dim, 1, 1]);
    let mut runtime = PrtRuntime::new(&device, &queue, &empty, RuntimeSettings::default()).unwrap();
    let sky = load_rig(&fixture("rigs/sky_only.json")).unwrap();
    let sh = gpu_update(&device, &queue, &mut runtime, &sky, Some(1000));
    assert!(sh.iter().all(|c| (c[0][0] - 3.5449).abs() < 1e-3));

    let too_long = BakeSettings {
        bounds: Some([0.0, 0.0, 0.0, 2.0 * max_dim as f32, 0.0, 0.0]),
        max_probes: 4 * u64::from(max_dim),
        ..line
    };
    let asset = bake(&fixture("empty.gltf"), &too_long);
    let err = PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default())
        .err()
        .expect("a grid beyond the 3D texture limit is refused");
    assert!(err.to_string().contains(&max_dim.to_string()), "{err}");
}

/// Emissive bricks no light reaches are relit on the first update (GPU furnace: c0 = 4pi Y00 e
/// with no lights at all), and the shadow-ray cache is re-traced whenever a change can light
/// new surfels: a dark light turned on, a longer range.
#[test]
fn emission_and_shadow_cache_follow_every_change() {
    let (device, queue) = gpu_device();
    let settings = BakeSettings {
        spacing: Some(0.6),
        bounds: Some([-0.9, -0.9, -0.9, 0.9, 0.9, 0.9]),
        ..BakeSettings::default()
    };
    let furnace = bake(&fixture("closed_box_inward.gltf"), &settings);
    let no_lights = load_rig(&fixture("rigs/no_lights.json")).unwrap();
    let mut runtime =
        PrtRuntime::new(&device, &queue, &furnace, RuntimeSettings::default()).unwrap();
    let gpu = gpu_update(&device, &queue, &mut runtime, &no_lights, None);
    let expected = 4.0 * std::f32::consts::PI * prt_format::sh::Y00 * 0.5;
    assert!(
        gpu.iter()
            .all(|c| (c[0][0] - expected).abs() < 1e-3 * expected),
        "{:?}",
        gpu[0]
    );
    assert_close("furnace", &furnace, &gpu, &cpu(&furnace, &no_lights), 1e-4);

    let cornell = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let mut runtime =
        PrtRuntime::new(&device, &queue, &cornell, RuntimeSettings::default()).unwrap();
    let mut lighting = rig(0.0, 0.0);
    lighting.rig.lights[0].range = Some(0.5);
    for step in ["dark", "lit", "longer range"] {
        match step {
            "lit" => lighting.rig.lights[0].intensity = 3.0,
            "longer range" => lighting.rig.lights[0].range = Some(4.0),
            _ => {}
        }
        let lighting =
            Lighting::from_rig(lighting.rig.clone(), Path::new("."), Path::new(step)).unwrap();
        let gpu = gpu_update(&device, &queue, &mut runtime, &lighting, None);
        assert_close(step, &cornell, &gpu, &cpu(&cornell, &lighting), 1e-4);
    }
}

/// Factor tables larger than one storage binding are split into chunks of whole probes: a
/// runtime limited to 64 KiB per binding (dozens of chunks) gives exactly the unsplit result,
/// and a probe whose own table exceeds the limit is a typed error.
#[test]
fn chunked_factor_tables_match_the_unsplit_result() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let lighting = load_rig(&fixture("cornell/rig_spot_range.json")).unwrap();
    let bytes = asset.factors.len() * asset.factors.bytes_per_factor();
    assert!(
        bytes > 16 * 64 * 1024,
        "the asset needs many chunks ({bytes} bytes)"
    );
    let mut whole = PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default()).unwrap();
    let expect = gpu_update(&device, &queue, &mut whole, &lighting, None);
    let small = RuntimeSettings {
        max_factor_chunk_bytes: Some(64 * 1024),
        ..RuntimeSettings::default()
    };
    let mut chunked = PrtRuntime::new(&device, &queue, &asset, small).unwrap();
    assert_eq!(
        gpu_update(&device, &queue, &mut chunked, &lighting, Some(300)),
        expect
    );
    let tiny = RuntimeSettings {
        max_factor_chunk_bytes: Some(64),
        ..RuntimeSettings::default()
    };
    let err = PrtRuntime::new(&device, &queue, &asset, tiny)
        .err()
        .expect("a probe exceeds 64 bytes");
    assert!(err.to_string().contains("factor table"), "{err}");
}

/// Surfel arrays larger than one storage binding are split into chunks of whole bricks: a
/// runtime limited to 128 KiB of surfels per binding (dozens of chunks) gives exactly the
/// unsplit result, with two bounces (the bounce stage reads the chunks too), and equals the
/// CPU; a brick whose own surfels exceed the limit is a typed error.
#[test]
fn chunked_surfels_match_the_unsplit_result() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let lighting = load_rig(&fixture("cornell/rig_spot_range.json")).unwrap();
    // As uploaded: packed surfels.
    let bytes = asset.surfels.len() * asset.header.settings.surfel_precision.bytes();
    assert!(
        bytes > 16 * 128 * 1024,
        "the asset needs many chunks ({bytes} bytes)"
    );
    let settings = RuntimeSettings {
        bounces: prt_runtime::gpu::Bounces::Fixed(2),
        volume_format: VolumeFormat::F32,
        ..RuntimeSettings::default()
    };
    let mut whole = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    whole.settle(&lighting).unwrap();
    let expect = whole.read_probe_sh().unwrap();
    let small = RuntimeSettings {
        max_surfel_chunk_bytes: Some(128 * 1024),
        ..settings
    };
    let mut chunked = PrtRuntime::new(&device, &queue, &asset, small).unwrap();
    chunked.settle(&lighting).unwrap();
    let got = chunked.read_probe_sh().unwrap();
    assert_eq!(got, expect, "chunked surfels change nothing");
    let cpu = CpuRelighter::new(&asset)
        .unwrap()
        .relight_with(&lighting, 2, &settings.lookup)
        .unwrap()
        .sh;
    assert_close("chunked surfels, 2 bounces", &asset, &got, &cpu, 1e-4);
    let tiny = RuntimeSettings {
        max_surfel_chunk_bytes: Some(80),
        ..RuntimeSettings::default()
    };
    let err = PrtRuntime::new(&device, &queue, &asset, tiny)
        .err()
        .expect("a brick exceeds 80 bytes");
    assert!(err.to_string().contains("one brick's surfels"), "{err}");
}

/// The engine-side snippet, run for real in a compute shader: at a probe's texel centre,
/// `sample_irradiance` equals the CPU irradiance of that probe's SH (half-float rounding); between
/// a valid probe and an invalid neighbour, hardware trilinear filtering over the
/// validity-premultiplied texels gives the valid probe alone. No normal bias: the points are the
/// texel centres themselves.
#[test]
fn sample_irradiance_snippet_matches_the_cpu() {
    let (device, queue) = gpu_device();
    // Without dilation or the virtual offset, so that probes inside the boxes stay invalid.
    let asset = bake(
        &fixture("cornell/cornell.gltf"),
        &BakeSettings {
            dilate: false,
            virtual_offset: false,
            ..BakeSettings::default()
        },
    );
    let lighting = load_rig(&fixture("cornell/rig.json")).unwrap();
    // The probe volume alone: the surface terms are compared in
    // `sample_points_matches_the_cpu_sampler`.
    let settings = RuntimeSettings {
        lookup: LookupSettings {
            normal_bias: 0.0,
            surface_terms: false,
            ..LookupSettings::default()
        },
        ..RuntimeSettings::default()
    };
    let mut runtime = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    let sh = gpu_update(&device, &queue, &mut runtime, &lighting, None);
    let g = asset.header.grid;
    let normals = [
        [0.0, 1.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.48, -0.6, 0.64],
    ];

    // (position, normal, expected irradiance)
    let mut queries: Vec<([f32; 3], [f32; 3], [f32; 3])> = Vec::new();
    let mut mixed = 0;
    for k in 0..g.counts[2] {
        for j in 0..g.counts[1] {
            for i in 0..g.counts[0] {
                let p = g.index(i, j, k);
                if !asset.probes[p].is_valid() {
                    continue;
                }
                let n = normals[p % normals.len()];
                let e = prt_format::sh::irradiance(&sh[p], n);
                queries.push((g.position(i, j, k), n, e));
                // Midway to a probe that weighs nothing (invalid, not filled): the valid one.
                let next = asset.probes.get(g.index(i + 1, j, k));
                if i + 1 < g.counts[0] && next.is_some_and(|q| q.sample_weight() == 0.0) {
                    let mut mid = g.position(i, j, k);
                    mid[0] += 0.5 * g.step[0];
                    queries.push((mid, n, e));
                    mixed += 1;
                }
            }
        }
    }
    assert!(
        mixed > 0,
        "the grid has a valid probe beside an invalid one"
    );

    let points: Vec<([f32; 3], [f32; 3])> = queries.iter().map(|q| (q.0, q.1)).collect();
    let results = sample_points(&device, &queue, &runtime, &points).unwrap();
    let peak = queries
        .iter()
        .map(|q| q.2[0].max(q.2[1]).max(q.2[2]))
        .fold(0.0, f32::max);
    for (q, r) in queries.iter().zip(&results) {
        for c in 0..3 {
            let tol = 4e-3 * q.2[c].abs() + 1e-4 * peak;
            assert!(
                (r.irradiance[c] - q.2[c]).abs() <= tol,
                "at {:?} n {:?}: gpu {r:?} cpu {:?}",
                q.0,
                q.1,
                q.2
            );
        }
    }
}

/// Deterministic sample points inside `g` (an R3 low-discrepancy sequence) with Fibonacci-lattice
/// normals, plus, for every valid probe with an invalid +x, +y or +z neighbour, points a quarter,
/// half and three quarters of the way to it.
fn sample_queries(asset: &Asset, count: usize) -> Vec<([f32; 3], [f32; 3])> {
    let g = asset.header.grid;
    let extent: [f32; 3] = std::array::from_fn(|a| (g.counts[a] - 1) as f32 * g.step[a]);
    // R3 sequence: fractional parts of i * (1/phi3, 1/phi3^2, 1/phi3^3).
    let phi3 = 1.220_744_1_f64;
    let alpha = [1.0 / phi3, 1.0 / (phi3 * phi3), 1.0 / (phi3 * phi3 * phi3)];
    let normal = |i: usize| {
        let d = prt_format::directions::fibonacci_direction(i as u32 % 97, 97);
        [d[0], d[1], d[2]]
    };
    let mut out: Vec<([f32; 3], [f32; 3])> = (0..count)
        .map(|i| {
            let p = std::array::from_fn(|a| {
                let t = (0.5 + alpha[a] * i as f64).fract() as f32;
                g.origin[a] + t * extent[a]
            });
            (p, normal(i))
        })
        .collect();
    for k in 0..g.counts[2] {
        for j in 0..g.counts[1] {
            for i in 0..g.counts[0] {
                let real = |p: &prt_format::Probe| p.is_valid() && !p.is_dilated();
                if !real(&asset.probes[g.index(i, j, k)]) {
                    continue;
                }
                let here = g.position(i, j, k);
                for (a, next) in [(0, [i + 1, j, k]), (1, [i, j + 1, k]), (2, [i, j, k + 1])] {
                    if next[a] >= g.counts[a]
                        || real(&asset.probes[g.index(next[0], next[1], next[2])])
                    {
                        continue;
                    }
                    for f in [0.25, 0.5, 0.75] {
                        let mut p = here;
                        p[a] += f * g.step[a];
                        let n = out.len();
                        out.push((p, normal(n)));
                    }
                }
            }
        }
    }
    out
}

/// `sample_points` (the real snippet on the GPU, default biases and the two set apart) equals its CPU twin
/// `SurfaceSampler` over the same probe SH at a few hundred points of the Cornell reference bake,
/// including points between valid and invalid probes, and at a few hundred surfels (where the
/// surface terms decide; near fields lit by the CPU relight; the sky terms under the rig's
/// constant sky and under an image sky). The volume is half-float (relative
/// rounding 2^-11 per texel) and the filter weights are the hardware's, so the tolerance is
/// relative to the point's brightness: see the constants.
#[test]
fn sample_points_matches_the_cpu_sampler() {
    let (device, queue) = gpu_device();
    // Without the virtual offset: probes inside the boxes stay there (dilated), beside points.
    let cornell = BakeSettings {
        virtual_offset: false,
        ..BakeSettings::default()
    };
    let asset = bake(&fixture("cornell/cornell.gltf"), &cornell);
    let lighting = load_rig(&fixture("cornell/rig.json")).unwrap();
    // The room's opening: some surfels see more or less sky than their probes.
    assert!(asset.surface.sky.iter().any(|&w| w != 0), "no sky terms");
    for depth_moments in [true, false] {
        let settings = RuntimeSettings {
            lookup: LookupSettings {
                depth_moments,
                ..LookupSettings::default()
            },
            ..RuntimeSettings::default()
        };
        let mixed = compare_samplers(&device, &queue, &asset, &lighting, settings);
        assert!(mixed > 0, "no point beside a probe inside geometry");
    }
    // The surface lookup weighs its probes at its own bias, the volume at the normal bias: set
    // apart (and the other way round from the defaults), the GPU reads each where the CPU does.
    let settings = RuntimeSettings {
        lookup: LookupSettings {
            normal_bias: 0.05,
            surface_bias: 0.3,
            ..LookupSettings::default()
        },
        ..RuntimeSettings::default()
    };
    compare_samplers(&device, &queue, &asset, &lighting, settings);
    // Sparse placement: depth moments in slot order, points beside grid points left out and
    // filled from a coarse level (no depth moments: the facing term alone).
    let sparse = BakeSettings {
        sparse: true,
        ..cornell
    };
    let asset = bake(&fixture("cornell/cornell.gltf"), &sparse);
    assert!(asset.probes.iter().any(|p| p.is_filled()));
    let mixed = compare_samplers(
        &device,
        &queue,
        &asset,
        &lighting,
        RuntimeSettings::default(),
    );
    assert!(mixed > 0, "no point beside a probe left out");
    // An image sky: the surface lookup's sky term takes its mean radiance over the lattice
    // (format 14), on the GPU as on the CPU.
    let image_sky = Lighting {
        rig: lighting.rig.clone(),
        sky: warm_over_cool(),
    };
    let settings = RuntimeSettings {
        equirect_sky: true,
        ..RuntimeSettings::default()
    };
    compare_samplers(&device, &queue, &asset, &image_sky, settings);
    // Without the sky terms (`--no-sky-terms`), on an asset that has them.
    let settings = RuntimeSettings {
        lookup: LookupSettings {
            sky_terms: false,
            ..LookupSettings::default()
        },
        ..RuntimeSettings::default()
    };
    compare_samplers(&device, &queue, &asset, &lighting, settings);
    // Two rooms sharing a thin wall: the depth moments decide most of the weights there, and
    // the wall runs through surfel cells (format 18's sides).
    let rooms = bake(&fixture("two_rooms.gltf"), &BakeSettings::default());
    assert!(!rooms.surface.sides.is_empty(), "no sides");
    let lighting = load_rig(&fixture("rigs/two_rooms.json")).unwrap();
    compare_samplers(
        &device,
        &queue,
        &rooms,
        &lighting,
        RuntimeSettings::default(),
    );
}

/// The floor under L2's ringing (`LookupSettings::ringing_floor`), raised to 1 so that it
/// decides many points of the two rooms (the dark room's probes see the lit one through the
/// door): the snippet floors where its CPU twin does.
#[test]
fn the_snippet_floors_ringing_as_the_cpu_does() {
    let (device, queue) = gpu_device();
    let rooms = bake(&fixture("two_rooms.gltf"), &BakeSettings::default());
    let lighting = load_rig(&fixture("rigs/two_rooms.json")).unwrap();
    let floored = LookupSettings {
        ringing_floor: 1.0,
        ..LookupSettings::default()
    };
    let relit = CpuRelighter::new(&rooms)
        .unwrap()
        .relight(&lighting, 1)
        .unwrap();
    let off = LookupSettings {
        ringing_floor: 0.0,
        ..floored
    };
    let (with, without) = (
        SurfaceSampler::for_relit(&rooms, &relit, &floored),
        SurfaceSampler::for_relit(&rooms, &relit, &off),
    );
    let mut points = sample_queries(&rooms, 384);
    points.extend(rooms.surfels.iter().map(|s| (s.position, s.normal)));
    let lifted = points
        .iter()
        .filter(|(p, n)| with.sample(*p, *n).irradiance != without.sample(*p, *n).irradiance)
        .count();
    assert!(lifted > 10, "the floor lifts {lifted} points");
    let settings = RuntimeSettings {
        lookup: floored,
        ..RuntimeSettings::default()
    };
    compare_samplers(&device, &queue, &rooms, &lighting, settings);
}

/// The snippet's sky irradiance follows the sky (format 14): pi times its mean radiance after
/// an update with the rig's constant sky, 0 under a black sky, and back again, and the snippet
/// then samples what a runtime that only saw the rig's sky samples; always 0 with the sky
/// terms off.
#[test]
fn the_sky_irradiance_follows_the_sky() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let lit = load_rig(&fixture("cornell/rig.json")).unwrap();
    let SkyModel::Constant(sky) = lit.sky else {
        panic!("the Cornell rig's sky is constant");
    };
    let black = Lighting {
        rig: lit.rig.clone(),
        sky: SkyModel::Black,
    };
    let points = sample_queries(&asset, 256);
    let mut fresh = PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default()).unwrap();
    gpu_update(&device, &queue, &mut fresh, &lit, None);
    let want = sample_points(&device, &queue, &fresh, &points).unwrap();
    for sky_terms in [true, false] {
        let settings = RuntimeSettings {
            lookup: LookupSettings {
                sky_terms,
                ..LookupSettings::default()
            },
            ..RuntimeSettings::default()
        };
        let mut runtime = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
        for (lighting, on) in [(&lit, true), (&black, false), (&lit, true)] {
            gpu_update(&device, &queue, &mut runtime, lighting, None);
            let expected = match on && sky_terms {
                true => sky.map(|l| std::f32::consts::PI * l),
                false => [0.0; 3],
            };
            assert_eq!(runtime.volume_info().sky_irradiance, expected);
        }
        if sky_terms {
            let got = sample_points(&device, &queue, &runtime, &points).unwrap();
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(g.irradiance, w.irradiance);
            }
        }
    }
}

fn compare_samplers(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    asset: &Asset,
    lighting: &Lighting,
    settings: RuntimeSettings,
) -> usize {
    let (device, queue) = (device.clone(), queue.clone());
    let mut runtime = PrtRuntime::new(&device, &queue, asset, settings).unwrap();
    let sh = gpu_update(&device, &queue, &mut runtime, lighting, None);
    let relit = CpuRelighter::new(asset)
        .unwrap()
        .relight(lighting, 1)
        .unwrap();
    let cpu = SurfaceSampler::new(
        asset,
        &sh,
        &relit.surfel_radiance,
        relit.sky,
        &settings.lookup,
    );
    let mut points = sample_queries(asset, 384);
    let mixed = points.len() - 384;
    let step = (asset.surfels.len() / 300).max(1);
    points.extend(
        asset
            .surfels
            .iter()
            .step_by(step)
            .map(|s| (s.position, s.normal)),
    );
    points.extend(side_points(asset));
    let on_surfels = points
        .iter()
        .filter(|(p, n)| cpu.surfel(*p, *n).is_some())
        .count();
    let across = points
        .iter()
        .filter(|(p, n)| beyond_a_wall(asset, *p, *n))
        .count();
    if settings.lookup.surface_terms && !asset.surface.sides.is_empty() {
        assert!(across > 0, "no point reads a side's partner");
    }
    if settings.lookup.surface_terms {
        assert!(
            on_surfels > 150,
            "{on_surfels} points take the surface lookup"
        );
    }
    let gpu = sample_points(&device, &queue, &runtime, &points).unwrap();
    assert_eq!(gpu.len(), points.len());
    let (mut worst_sh, mut worst_e, mut worst_v) = (0.0f32, 0.0f32, 0.0f32);
    for (i, ((p, n), gs)) in points.iter().zip(&gpu).enumerate() {
        let cs = cpu.sample(*p, *n);
        let dv = (gs.validity - cs.validity).abs();
        worst_v = worst_v.max(dv);
        assert!(
            dv <= VALIDITY_TOL,
            "point {i} at {p:?}: validity gpu {} cpu {}",
            gs.validity,
            cs.validity
        );
        if cs.validity < 1e-3 {
            continue;
        }
        // Scale: the DC term's share of irradiance (the mean E over all normals).
        let scale = cs.sh[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        for k in 0..9 {
            for ch in 0..3 {
                let d = (gs.sh[k][ch] - cs.sh[k][ch]).abs() / scale;
                worst_sh = worst_sh.max(d);
                assert!(
                    d <= SH_TOL,
                    "point {i} at {p:?} k {k} ch {ch}: gpu {gs:?} cpu {cs:?}"
                );
            }
        }
        let e_scale = std::f32::consts::PI * prt_format::sh::Y00 * scale;
        for ch in 0..3 {
            let d = (gs.irradiance[ch] - cs.irradiance[ch]).abs() / e_scale;
            worst_e = worst_e.max(d);
            assert!(
                d <= SH_TOL,
                "point {i} at {p:?} ch {ch}: gpu {gs:?} cpu {cs:?}"
            );
        }
    }
    eprintln!(
        "depth moments {}: {} points ({mixed} beside probes inside geometry, {on_surfels} on surfels, {across} beyond a wall in their cell): worst |dSH|/SH0 {worst_sh:.2e}, |dE|/E0 {worst_e:.2e}, |dvalidity| {worst_v:.2e}",
        settings.lookup.depth_moments,
        points.len()
    );
    mixed
}

/// Both sides of walls through surfel cells (format 18): up to 50 sides' surfels and their
/// partners, where the table names the first and points at the second read the second.
fn side_points(asset: &Asset) -> Vec<([f32; 3], [f32; 3])> {
    let sides = &asset.surface.sides;
    let step = (sides.len() / 50).max(1);
    let at = |i: u32| {
        let s = &asset.surfels[i as usize];
        (s.position, s.normal)
    };
    (sides.iter().step_by(step))
        .flat_map(|side| [at(side.surfel), at(side.partner)])
        .collect()
}

/// Whether the surface lookup at `p` (normal `n`) reads a side's partner (format 18): the
/// surfel its cell names has a side, and `p` lies beyond its wall.
fn beyond_a_wall(asset: &Asset, p: [f32; 3], n: [f32; 3]) -> bool {
    let t = &asset.surface;
    let key = t.key_of(p);
    let Some(brick) = t.find(key, prt_format::surface::dominant_axis(n)) else {
        return false;
    };
    let Some(within) = t.surfel_in(brick, key, p) else {
        return false;
    };
    let named = asset.bricks[brick as usize].first_surfel + within;
    t.side_of(named, key, p) != named
}

/// Tolerances of `sample_points_matches_the_cpu_sampler`, relative to the sample's SH0 (for E: to
/// pi Y00 SH0, the mean irradiance): half-float texels round each coefficient to 2^-11 of its
/// magnitude, and the renormalised L1/L2 terms can be a few times SH0's size.
const SH_TOL: f32 = 4e-3;
/// Hardware filter weights: 8-bit fixed-point fractions on most GPUs (1/256 of a texel).
const VALIDITY_TOL: f32 = 1.0 / 256.0;
