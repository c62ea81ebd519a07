//! The GPU runtime with many lights (per-brick light masks, a shadow-ray cache sized by the
//! (surfel, light) pairs that can reach each other) against the CPU reference, on lavapipe.

use std::path::Path;

use prt_bake::BakeSettings;
use prt_format::sh::ShRgb;
use prt_format::{Light, LightKind, LightRig};
use prt_runtime::gpu::{wgpu, GpuError, PrtRuntime, RuntimeSettings};
use prt_runtime::lights::PreparedLight;
use prt_runtime::{CpuRelighter, Lighting};
use prt_tests::{bake_ok as bake, fixture, gpu_device, worst_of_sh0};

/// `count` ranged point and spot lights scattered through the Cornell room (a fixed
/// low-discrepancy sequence), each reaching a part of it.
fn many_lights(count: usize) -> Lighting {
    let lights = (0..count)
        .map(|i| {
            let f = |k: f32| ((i as f32 + 0.5) * k).fract();
            let spot = i % 3 == 0;
            Light {
                kind: if spot {
                    LightKind::Spot
                } else {
                    LightKind::Point
                },
                position: [
                    -0.9 + 1.8 * f(0.618_034),
                    0.1 + 1.8 * f(0.754_877_7),
                    -0.9 + 1.8 * f(0.569_840_3),
                ],
                direction: [f(0.31) - 0.5, -1.0, f(0.47) - 0.5],
                color: [
                    0.5 + 0.5 * f(0.13),
                    0.5 + 0.5 * f(0.29),
                    0.5 + 0.5 * f(0.41),
                ],
                intensity: 0.02 + 0.05 * f(0.83),
                range: Some(0.25 + 0.5 * f(0.91)),
                inner_cone_angle: 0.2,
                outer_cone_angle: 0.7,
            }
        })
        .collect();
    let rig = LightRig { lights, sky: None };
    Lighting::from_rig(rig, Path::new("."), Path::new("many lights")).unwrap()
}

fn update(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    runtime: &mut PrtRuntime,
    lighting: &Lighting,
) -> (Vec<ShRgb>, prt_runtime::contract::Counters) {
    let mut encoder = device.create_command_encoder(&Default::default());
    runtime.update(&mut encoder, lighting, None).unwrap();
    queue.submit([encoder.finish()]);
    (
        runtime.read_probe_sh().unwrap(),
        runtime.read_counters().unwrap(),
    )
}

/// Shadow rays the CPU reference traces for `light` alone: one per (surfel, light) pair that
/// the light reaches with non-zero irradiance, the pairs the GPU must trace when it moves.
fn pairs_of(cpu: &CpuRelighter, light: &Light) -> u64 {
    cpu.direct_irradiance(&[PreparedLight::new(light)])
        .1
        .shadow_rays
}

/// A runtime fitted to its lighting (`RuntimeSettings::fitted_to`: light masks of one word, a
/// shadow-ray cache of one word per surfel, no sky masks without an equirect sky) relights bit
/// for bit as one with room for 256 lights and any sky, in less memory; its cache never
/// overflows, and an equirect sky it was not fitted to is refused.
#[test]
fn a_runtime_fitted_to_its_rig_relights_the_same_in_less_memory() {
    let fitted = |n| {
        let settings = RuntimeSettings::default().fitted_to(&many_lights(n));
        (settings.max_lights, settings.equirect_sky)
    };
    assert_eq!(
        [fitted(0), fitted(20), fitted(32), fitted(33), fitted(5000)],
        [32, 32, 32, 64, prt_runtime::contract::MAX_LIGHTS].map(|m| (m, false))
    );
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let lighting = many_lights(20);
    // A second update with one light moved: the cache's other half, and the bits copied
    // across for bricks the move leaves alone.
    let mut moved = many_lights(20);
    moved.rig.lights[7].position[0] += 0.15;
    let run = |settings| {
        let mut runtime = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
        let first = update(&device, &queue, &mut runtime, &lighting);
        let second = update(&device, &queue, &mut runtime, &moved);
        (first, second, runtime)
    };
    let (roomy, roomy_moved, roomy_runtime) = run(RuntimeSettings::default().with_room_for(20));
    let (first, second, mut runtime) = run(RuntimeSettings::default().fitted_to(&lighting));
    assert!(first.0 == roomy.0, "fitted and roomy runtimes differ");
    assert!(second.0 == roomy_moved.0, "they differ after a light moved");
    assert_eq!(
        (first.1.bricks_uncached, second.1.bricks_uncached),
        (0, 0),
        "the fitted cache overflowed"
    );
    assert!(
        second.1.shadow_rays < first.1.shadow_rays,
        "the cache was not used"
    );
    let (bytes, roomy_bytes) = (runtime.gpu_memory().1, roomy_runtime.gpu_memory().1);
    assert!(
        bytes + asset.sky_mask.len() as u64 * 4 <= roomy_bytes,
        "fitted {bytes} B, with room for 256 lights and sky masks {roomy_bytes} B"
    );
    let equirect = Lighting {
        sky: prt_runtime::SkyModel::Equirect {
            width: 2,
            height: 1,
            texels: vec![[1.0; 3]; 2],
        },
        ..lighting
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    let refused = runtime.update(&mut encoder, &equirect, None);
    assert!(matches!(refused, Err(GpuError::NoSkyMask)), "{refused:?}");
    assert!(RuntimeSettings::default().fitted_to(&equirect).equirect_sky);
}

/// 1,024 point and spot lights relight on the GPU as on the CPU; moving one of them re-traces
/// exactly that light's pairs and tests one light per brick; a pool too small for the cache
/// leaves bricks uncached but the result unchanged.
#[test]
fn a_thousand_lights_equal_the_cpu_and_one_moved_light_costs_its_pairs() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let front = asset
        .bricks
        .iter()
        .filter(|b| b.flags & prt_format::BRICK_BACKFACE == 0)
        .count() as u32;
    let cpu = CpuRelighter::new(&asset).unwrap();
    let mut lighting = many_lights(1024);
    let settings = RuntimeSettings::default().with_room_for(1024);
    assert_eq!(settings.max_lights, 1024);
    let mut runtime = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    let (gpu, first) = update(&device, &queue, &mut runtime, &lighting);
    let reference = cpu.relight(&lighting, 1).unwrap();
    let w = worst_of_sh0(&asset, &gpu, &reference.sh);
    assert!(w <= 1e-4, "1,024 lights: worst |gpu - cpu| / SH0 = {w}");
    assert_eq!(
        first.light_tests,
        1024 * front,
        "first update: every light x brick"
    );
    assert_eq!(
        u64::from(first.shadow_rays),
        reference.stats.shadow_rays,
        "first update: every reaching pair traced once"
    );
    let pairs: u64 = (0..1024)
        .map(|i| pairs_of(&cpu, &lighting.rig.lights[i]))
        .sum();
    assert_eq!(pairs, reference.stats.shadow_rays);

    // Move light 517: only its pairs are traced again.
    lighting.rig.lights[517].position[0] += 0.15;
    let (gpu, moved) = update(&device, &queue, &mut runtime, &lighting);
    let reference = cpu.relight(&lighting, 1).unwrap();
    let w = worst_of_sh0(&asset, &gpu, &reference.sh);
    assert!(w <= 1e-4, "after the move: {w}");
    assert_eq!(moved.light_tests, front, "one light tested per brick");
    assert_eq!(
        u64::from(moved.shadow_rays),
        pairs_of(&cpu, &lighting.rig.lights[517]),
        "only the moved light's pairs are traced"
    );
    assert!(moved.bricks_uncached == 0 && moved.shadow_cache_words > 0);
    eprintln!(
        "1,024 lights: first update {} rays, {} shadow-cache words (surfels {}); one moved: {} rays, {} bricks relit of {front}",
        first.shadow_rays,
        first.shadow_cache_words,
        asset.surfels.len(),
        moved.shadow_rays,
        moved.bricks_relit
    );

    // A pool of 1,000 words: most bricks stay uncached, the light is the same.
    let small = RuntimeSettings {
        shadow_cache_words: Some(1000),
        ..settings
    };
    let mut runtime = PrtRuntime::new(&device, &queue, &asset, small).unwrap();
    update(&device, &queue, &mut runtime, &many_lights(1024));
    let (gpu, counters) = update(&device, &queue, &mut runtime, &lighting);
    assert!(counters.bricks_uncached > 0, "the pool overflowed");
    let w = worst_of_sh0(&asset, &gpu, &reference.sh);
    assert!(w <= 1e-4, "uncached bricks: {w}");
}

/// A rig beyond `max_lights` is refused with both numbers; so is a limit beyond MAX_LIGHTS.
#[test]
fn light_limits_are_errors_with_values() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let settings = RuntimeSettings {
        max_lights: 40,
        ..RuntimeSettings::default()
    };
    let mut runtime = PrtRuntime::new(&device, &queue, &asset, settings).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    let err = runtime
        .update(&mut encoder, &many_lights(41), None)
        .unwrap_err();
    assert!(
        matches!(err, GpuError::TooManyLights { count: 41, max: 40 }),
        "{err}"
    );
    let err = PrtRuntime::new(
        &device,
        &queue,
        &asset,
        RuntimeSettings {
            max_lights: 5000,
            ..RuntimeSettings::default()
        },
    )
    .err()
    .expect("refused");
    assert!(err.to_string().contains("5000"), "{err}");
}

/// Rigs that shrink and grow across a multiple of 32 lights, a moved light after the shrink (its
/// neighbours' cached bits are read at their old slots), a brightness change (no ray) and a third
/// relight that reads bits the non-dirty copy path moved: the GPU stays equal to the CPU.
#[test]
fn shrinking_and_growing_rigs_keep_the_cache_exact() {
    let (device, queue) = gpu_device();
    let asset = bake(&fixture("cornell/cornell.gltf"), &BakeSettings::default());
    let cpu = CpuRelighter::new(&asset).unwrap();
    let mut runtime = PrtRuntime::new(&device, &queue, &asset, RuntimeSettings::default()).unwrap();
    let forty = many_lights(40);
    let mut lighting = forty.clone();
    let mut check = |label: &str, lighting: &Lighting| {
        let (gpu, counters) = update(&device, &queue, &mut runtime, lighting);
        let w = worst_of_sh0(&asset, &gpu, &cpu.relight(lighting, 1).unwrap().sh);
        assert!(w <= 1e-4, "{label}: worst |gpu - cpu| / SH0 = {w}");
        counters
    };
    check("40 lights", &lighting);
    lighting.rig.lights.truncate(32);
    check("down to 32", &lighting);
    lighting.rig.lights[5].position[0] += 0.2;
    let moved = check("one moved after the shrink", &lighting);
    assert!(moved.shadow_rays > 0);
    lighting.rig.lights[20].intensity *= 2.0;
    let brighter = check("one brighter", &lighting);
    assert_eq!(brighter.shadow_rays, 0, "brightness keeps the cache");
    lighting.rig.lights[11].position[2] -= 0.2;
    check("another moved (bits copied twice)", &lighting);
    lighting.rig.lights.push(forty.rig.lights[35].clone());
    check("up to 33", &lighting);
    lighting.rig.lights.truncate(1);
    check("down to 1", &lighting);
}
