//! `prt bench`: measurements, never tests. Each function measures its baseline in the same run
//! and returns a Markdown report (and, for the accuracy sweep, an SVG plot).

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use prt_eval::{compare, ErrorStats};
use prt_format::{Asset, Factors, TransferPrecision};
use prt_runtime::gpu::{headless_device, wgpu, Bounces, PrtRuntime, RuntimeSettings};
use prt_runtime::{CpuRelighter, Lighting};

/// One setting of the accuracy sweep.
struct Row {
    rays: u32,
    merge: String,
    precision: TransferPrecision,
    encoding: &'static str,
    bake_s: f64,
    relight_s: f64,
    bytes_per_probe: f64,
    transport_per_probe: f64,
    factors_per_probe: f64,
    error: ErrorStats,
    /// Error after Hanning-window deringing of the relit SH (width 4).
    deringed: ErrorStats,
}

/// Sweeps rays, brick cell size, factor encoding and storage precision; reports bake time,
/// relight time, bytes per probe and the error against `reference`.
pub fn accuracy(
    scene: &Path,
    lighting: &Lighting,
    reference: &[([f32; 3], prt_format::sh::ShRgb)],
    base: &BakeSettings,
    rays: &[u32],
) -> Result<(String, String)> {
    let merges: [(&str, Option<f32>, f32); 4] = [
        ("none", Some(0.0), 12.0),
        ("spacing/24", None, 24.0),
        ("spacing/12 (default)", None, 12.0),
        ("spacing/6", None, 6.0),
    ];
    let mut rows = Vec::new();
    for &n in rays {
        for (name, cell_size, cells) in merges {
            for precision in [
                TransferPrecision::F32,
                TransferPrecision::F16,
                TransferPrecision::U8,
            ] {
                let settings = BakeSettings {
                    rays: n,
                    cell_size,
                    cells_per_spacing: cells,
                    transfer_precision: precision,
                    ..base.clone()
                };
                let t = Instant::now();
                let (asset, _) = prt_bake::bake(scene, &settings, &NoProgress)
                    .with_context(|| format!("bake with {n} rays, cells {name}"))?;
                let bytes = prt_format::encode(&asset)?.len();
                let bake_s = t.elapsed().as_secs_f64();
                let summary = prt_format::Summary::of(&asset, bytes as u64);
                let mut encodings = vec![("sh9 + gradient", asset.clone())];
                if cell_size != Some(0.0) && precision == TransferPrecision::F16 {
                    encodings.push(("sh9, flat brick", without_offsets(asset)));
                }
                for (encoding, asset) in encodings {
                    let relighter = CpuRelighter::new(&asset)?;
                    let t = Instant::now();
                    let relit = relighter.relight(lighting, 1)?;
                    let relight_s = t.elapsed().as_secs_f64();
                    let ours: Vec<_> = asset
                        .probes
                        .iter()
                        .zip(&relit.sh)
                        .map(|(p, c)| (p.position, p.is_valid(), *c))
                        .collect();
                    let probes = asset.probes.len() as f64;
                    rows.push(Row {
                        rays: n,
                        merge: name.to_owned(),
                        precision,
                        encoding,
                        bake_s,
                        relight_s,
                        bytes_per_probe: summary.bytes_per_probe,
                        transport_per_probe: summary.transport_bytes_per_probe,
                        factors_per_probe: asset.factors.len() as f64 / probes,
                        error: compare(&ours, reference, 1e-3),
                        deringed: compare(&windowed(&ours), reference, 1e-3),
                    });
                }
            }
        }
    }
    let mut md = String::from("| rays | brick cells | transfer | encoding | bake ms | CPU relight ms | file bytes/probe | transport bytes/probe | factors/probe | mean err | p95 err | max err | max coeff / SH0 | mean err deringed |\n|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in &rows {
        writeln!(
            md,
            "| {} | {} | {:?} | {} | {:.1} | {:.2} | {:.0} | {:.0} | {:.1} | {:.2}% | {:.2}% | {:.2}% | {:.1e} | {:.2}% |",
            r.rays, r.merge, r.precision, r.encoding, r.bake_s * 1e3, r.relight_s * 1e3,
            r.bytes_per_probe, r.transport_per_probe, r.factors_per_probe, 100.0 * r.error.mean, 100.0 * r.error.p95,
            100.0 * r.error.max, r.error.max_coeff_rel, 100.0 * r.deringed.mean
        )?;
    }
    Ok((md, plot(&rows)))
}

/// Probe SH with Hanning-window deringing applied (`prt_format::sh::hanning_window`, width 4).
fn windowed(
    ours: &[([f32; 3], bool, prt_format::sh::ShRgb)],
) -> Vec<([f32; 3], bool, prt_format::sh::ShRgb)> {
    ours.iter()
        .map(|(p, v, c)| (*p, *v, prt_format::sh::hanning_window(c, 4.0)))
        .collect()
}

/// The same asset with every factor's offset zeroed: each brick seen as its mean radiance.
fn without_offsets(mut asset: Asset) -> Asset {
    match &mut asset.factors {
        Factors::F32(f) => f.iter_mut().for_each(|f| f.offset = [0.0; 3]),
        Factors::F16(f) => f.iter_mut().for_each(|f| f.offset = [0; 2]),
        Factors::U8 { factors, .. } => factors.iter_mut().for_each(|f| f.packed[0] &= 0xff00_0000),
    }
    asset
}

/// SVG scatter of mean error against bake + relight time, log-log, with the Pareto front.
fn plot(rows: &[Row]) -> String {
    let (w, h, m) = (760.0, 480.0, 60.0);
    let pts: Vec<(f64, f64, &Row)> = rows
        .iter()
        .filter(|r| r.error.mean > 0.0)
        .map(|r| {
            (
                (r.bake_s + r.relight_s).log10(),
                (100.0 * r.error.mean).log10(),
                r,
            )
        })
        .collect();
    let (x0, x1) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let sx = |x: f64| m + (x - x0) / (x1 - x0).max(1e-9) * (w - 2.0 * m);
    let sy = |y: f64| h - m - (y - y0) / (y1 - y0).max(1e-9) * (h - 2.0 * m);
    let color = |merge: &str| match merge {
        "none" => "#d62728",
        "spacing/24" => "#1f77b4",
        "spacing/6" => "#2ca02c",
        _ => "#ff7f0e",
    };
    let mut s = format!("<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{h}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n");
    let _ = writeln!(s, "<text x='{}' y='20' text-anchor='middle' font-size='14'>Mean irradiance error vs bake + CPU relight time (log-log)</text>", w / 2.0);
    let _ = writeln!(s, "<line x1='{m}' y1='{}' x2='{}' y2='{}' stroke='black'/><line x1='{m}' y1='{m}' x2='{m}' y2='{}' stroke='black'/>", h - m, w - m, h - m, h - m);
    for (x, label) in [(x0, 10f64.powf(x0)), (x1, 10f64.powf(x1))] {
        let _ = writeln!(
            s,
            "<text x='{}' y='{}' text-anchor='middle'>{:.0} ms</text>",
            sx(x),
            h - m + 16.0,
            label * 1e3
        );
    }
    for (y, label) in [(y0, 10f64.powf(y0)), (y1, 10f64.powf(y1))] {
        let _ = writeln!(
            s,
            "<text x='{}' y='{}' text-anchor='end'>{label:.2}%</text>",
            m - 4.0,
            sy(y) + 4.0
        );
    }
    let mut front: Vec<&(f64, f64, &Row)> = pts.iter().collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut best = f64::MAX;
    let front: Vec<String> = front
        .into_iter()
        .filter(|p| {
            let keep = p.1 < best;
            best = best.min(p.1);
            keep
        })
        .map(|p| format!("{:.1},{:.1}", sx(p.0), sy(p.1)))
        .collect();
    let _ = writeln!(
        s,
        "<polyline points='{}' fill='none' stroke='#555' stroke-dasharray='4 3'/>",
        front.join(" ")
    );
    for (x, y, r) in &pts {
        let shape = if r.encoding == "sh9, flat brick" {
            "fill='none' stroke-width='1.5' stroke"
        } else {
            "fill"
        };
        let _ = writeln!(s, "<circle cx='{:.1}' cy='{:.1}' r='4' {shape}='{}'><title>{} rays, {}, {:?}, {}: {:.2}%</title></circle>", sx(*x), sy(*y), color(&r.merge), r.rays, r.merge, r.precision, r.encoding, 100.0 * r.error.mean);
    }
    for (i, merge) in ["none", "spacing/24", "spacing/12 (default)", "spacing/6"]
        .iter()
        .enumerate()
    {
        let y = m + 16.0 * i as f64;
        let _ = writeln!(
            s,
            "<circle cx='{}' cy='{}' r='4' fill='{}'/><text x='{}' y='{}'>bricks: {merge}</text>",
            w - 200.0,
            y,
            color(merge),
            w - 190.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        s,
        "<text x='{}' y='{}'>hollow: flat brick radiance; dashed: Pareto front</text>",
        w - 330.0,
        m + 70.0
    );
    s.push_str("</svg>\n");
    s
}

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
