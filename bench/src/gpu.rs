//! `prt bench gpu`: the GPU runtime's costs, measured against its baselines in the same run
//! (the prior art's per-probe surfels, an update with nothing changed) and returned as a
//! Markdown report. Benches are measurements, never tests.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use prt_bake::{BakeSettings, NoProgress};
use prt_runtime::gpu::{headless_device, wgpu, Bounces, PrtRuntime, RuntimeSettings};
use prt_runtime::Lighting;

/// Wall time of `iterations` recorded-and-submitted updates, each waited for, in seconds per
/// update; `lighting(i)` gives the lighting of update i.
fn time_updates<'a>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    runtime: &mut PrtRuntime,
    iterations: u32,
    lighting: impl Fn(u32) -> &'a Lighting,
) -> Result<f64> {
    let t = Instant::now();
    for i in 0..iterations {
        let mut encoder = device.create_command_encoder(&Default::default());
        runtime.update(&mut encoder, lighting(i), None)?;
        queue.submit([encoder.finish()]);
        runtime.wait()?;
    }
    Ok(t.elapsed().as_secs_f64() / f64::from(iterations))
}

/// Lighting for update i: `even` on even updates, `odd` on odd ones (every update a change).
fn alternate<'a>(even: &'a Lighting, odd: &'a Lighting) -> impl Fn(u32) -> &'a Lighting {
    move |i| if i % 2 == 0 { even } else { odd }
}

/// GPU runtime costs, all measured in one run on one adapter: full update per probe at several
/// probe counts, the gather alone, the update against the prior art's
/// scheme (every probe relights its own unmerged surfels), an update when nothing changed, and a
/// multi-bounce update (the volume fed back into every surfel).
pub fn gpu(scene: &Path, a: &Lighting, spacings: &[f32], rays: u32, cell: f32) -> Result<String> {
    let (device, queue, info) = headless_device()?;
    let baselines = RuntimeSettings::default().with_room_for(a.rig.lights.len());
    let sky = |c: f32| Lighting {
        rig: a.rig.clone(),
        sky: prt_runtime::SkyModel::Constant([c, c, c]),
    };
    let (sky1, sky2) = (sky(0.3), sky(0.4));
    let mut b = a.clone();
    for l in &mut b.rig.lights {
        l.position[0] += 0.05;
        l.direction[0] += 0.05;
    }
    let mut md = format!(
        "Adapter: {} ({:?}), subgroups: {}. Scene {}, {rays} rays per probe, cell size {cell} m. \
         Times are wall-clock per update (record, submit, wait); lavapipe runs on the CPU, so \
         compare ratios, not absolute times.\n\n",
        info.name,
        info.backend,
        device.features().contains(wgpu::Features::SUBGROUP),
        scene.display()
    );
    md.push_str("| probes | factors/probe | full update (lights moved) | per probe | gather only (sky changed) | nothing changed | bounce update (feedback) | bounce / full | prior art: own surfels per probe | speed-up vs prior art |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for &spacing in spacings {
        let settings = BakeSettings {
            rays,
            spacing: Some(spacing),
            cell_size: Some(cell),
            ..BakeSettings::default()
        };
        let (asset, _) = prt_bake::bake(scene, &settings, &NoProgress)?;
        let probes = asset.probes.len();
        let mut runtime = PrtRuntime::new(&device, &queue, &asset, baselines)?;
        let iterations = 4;
        time_updates(&device, &queue, &mut runtime, 1, |_| a)?;
        let full = time_updates(&device, &queue, &mut runtime, iterations, alternate(&b, a))?;
        let gather = time_updates(
            &device,
            &queue,
            &mut runtime,
            iterations,
            alternate(&sky1, &sky2),
        )?;
        let idle = time_updates(&device, &queue, &mut runtime, iterations, |_| &sky2)?;
        drop(runtime);
        // Endless feedback with nothing changed: every update samples the volume at every
        // surfel, rebuilds every brick and gathers every probe (one more bounce each).
        let feedback = RuntimeSettings {
            bounces: Bounces::Feedback { damping: 1.0 },
            ..baselines
        };
        let mut runtime = PrtRuntime::new(&device, &queue, &asset, feedback)?;
        // The first update lights; the second is the first to run the bounce stage.
        time_updates(&device, &queue, &mut runtime, 2, |_| a)?;
        let bounce = time_updates(&device, &queue, &mut runtime, iterations, |_| a)?;
        drop(runtime);
        let prior = if probes <= 2_000 {
            let unmerged = BakeSettings {
                cell_size: Some(0.0),
                ..settings.clone()
            };
            let (asset, _) = prt_bake::bake(scene, &unmerged, &NoProgress)?;
            let mut runtime = PrtRuntime::new(&device, &queue, &asset, baselines)?;
            time_updates(&device, &queue, &mut runtime, 1, |_| a)?;
            Some(time_updates(
                &device,
                &queue,
                &mut runtime,
                iterations,
                alternate(&b, a),
            )?)
        } else {
            None
        };
        writeln!(
            md,
            "| {probes} | {:.0} | {:.1} ms | {:.2} µs | {:.1} ms | {:.3} ms | {:.1} ms | {:.2}x | {} | {} |",
            asset.factors.len() as f64 / probes as f64,
            full * 1e3,
            full * 1e6 / probes as f64,
            gather * 1e3,
            idle * 1e3,
            bounce * 1e3,
            bounce / full,
            prior.map_or("not run".into(), |p| format!("{:.1} ms", p * 1e3)),
            prior.map_or("-".into(), |p| format!("{:.1}x", p / full)),
        )?;
    }
    Ok(md)
}
