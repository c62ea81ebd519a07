//! `prt-bench lights`: GPU update cost against light count (issue 9). Scattered point and spot
//! lights (ranges 3-12% of the scene's diagonal, `render::scattered_lights`) relight a
//! baked scene: a full update (every light moved) and an update where one light moved, with
//! the work counters that explain them. The goal is cost linear in the (light, brick) pairs
//! that reach each other, not in all lights.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use glam::Vec3;
use prt_bake::{BakeSettings, NoProgress};
use prt_runtime::contract::Counters;
use prt_runtime::gpu::{headless_device, wgpu, PrtRuntime, RuntimeSettings};
use prt_runtime::{Lighting, SkyModel};

use crate::results::Out;

#[derive(clap::Args)]
pub struct LightsArgs {
    pub scene: PathBuf,
    /// Light counts, one row each.
    #[arg(long, value_delimiter = ',', default_value = "1,32,256,1024")]
    pub lights: Vec<usize>,
    /// Probe spacing of the bake [default: about 4,000 probes].
    #[arg(long)]
    pub spacing: Option<f32>,
    #[arg(long, default_value_t = 256)]
    pub rays: u32,
    /// Bake treating every material as double-sided.
    #[arg(long)]
    pub double_sided: bool,
    /// Timed updates per figure (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    #[command(flatten)]
    pub out: Out,
}

fn lighting(lights: Vec<prt_format::Light>) -> Lighting {
    Lighting {
        rig: prt_format::LightRig { lights, sky: None },
        sky: SkyModel::Black,
    }
}

/// Median wall time of `repeats` updates (record, submit, wait) with `lighting(i)`, and the
/// counters of the last.
fn timed(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    runtime: &mut PrtRuntime,
    repeats: usize,
    lighting: impl Fn(usize) -> Lighting,
) -> Result<(f64, Counters)> {
    let mut times = Vec::with_capacity(repeats);
    for i in 0..repeats {
        let l = lighting(i);
        let t = Instant::now();
        let mut encoder = device.create_command_encoder(&Default::default());
        runtime.update(&mut encoder, &l, None)?;
        queue.submit([encoder.finish()]);
        runtime.wait()?;
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2], runtime.read_counters()?))
}

/// `prt-bench lights`: the table of [`table`], printed and with `--out` written to `lights.md`.
pub fn run(args: LightsArgs) -> Result<()> {
    args.out.report("lights", &table(&args)?)
}

/// The light-count table for `args`, as markdown.
pub fn table(args: &LightsArgs) -> Result<String> {
    use std::fmt::Write;
    let mut md = String::new();
    let settings = BakeSettings {
        rays: args.rays,
        spacing: args.spacing,
        double_sided: args.double_sided,
        // The grid's probe count, as the published rows (uniform) were measured.
        sparse: false,
        ..BakeSettings::default()
    };
    let (asset, _) = prt_bake::bake(&args.scene, &settings, &NoProgress)?;
    let (device, queue, info) = headless_device()?;
    let g = asset.header.grid;
    let lo = Vec3::from(g.origin);
    let hi = lo + Vec3::from(g.step) * Vec3::from(g.counts.map(|c| c.saturating_sub(1) as f32));
    let front = asset
        .bricks
        .iter()
        .filter(|b| b.flags & prt_format::BRICK_BACKFACE == 0)
        .count();
    writeln!(
        md,
        "Adapter: {} ({:?}). Scene {}: {} probes, {front} front-face bricks, {} surfels, {} rays \
         per probe. Median of {} updates each; lavapipe runs on the CPU, so compare ratios.\n",
        info.name,
        info.backend,
        args.scene.display(),
        asset.probes.len(),
        asset.surfels.len(),
        args.rays,
        args.repeats
    )?;
    writeln!(md, "| lights | full update (all moved) | reaching (light, brick) pairs | shadow rays | per 1k pairs | one light moved (the widest) | its bricks | rays traced | bricks relit | shadow-ray cache |")?;
    writeln!(md, "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    let bench = Bench {
        device: &device,
        queue: &queue,
        asset: &asset,
        repeats: args.repeats,
        lo,
        hi,
    };
    for &count in &args.lights {
        md.push_str(&bench.row(count)?);
    }
    Ok(md)
}

/// What every row of [`table`] is measured with: the device, the baked scene, and the box the
/// lights are scattered in.
struct Bench<'a> {
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    asset: &'a prt_format::Asset,
    repeats: usize,
    lo: Vec3,
    hi: Vec3,
}

impl Bench<'_> {
    /// The row of `count` scattered lights: every light moved, then the one that reaches the
    /// most bricks.
    fn row(&self, count: usize) -> Result<String> {
        let (lo, hi) = (self.lo, self.hi);
        let base = crate::render::scattered_lights(count, lo, hi);
        let shifted = |k: usize, which: Option<usize>| {
            let mut l = base.clone();
            for (i, light) in l.iter_mut().enumerate() {
                if which.is_none_or(|w| w == i) {
                    light.position[0] += 1e-3 * (k % 2) as f32 * (hi - lo).length();
                }
            }
            lighting(l)
        };
        let (device, queue) = (self.device, self.queue);
        let runtime_settings = RuntimeSettings::default().with_room_for(count);
        let mut runtime = PrtRuntime::new(device, queue, self.asset, runtime_settings)?;
        // Every update moves every light (odd: shifted, even: back).
        let (full, _) = timed(device, queue, &mut runtime, self.repeats, |i| {
            shifted(i + 1, None)
        })?;
        let reach = reach(self.asset, &base);
        let pairs: usize = reach.iter().sum();
        let (_, all) = timed(device, queue, &mut runtime, 1, |_| shifted(0, None))?;
        // The light that reaches the most bricks moves.
        let one = (0..count)
            .max_by_key(|&i| (reach[i], usize::MAX - i))
            .unwrap_or(0);
        let (moved, c) = timed(device, queue, &mut runtime, self.repeats, |i| {
            shifted(i + 1, Some(one))
        })?;
        Ok(format!(
            "| {count} | {:.1} ms | {pairs} | {} | {} | {:.1} ms | {} | {} | {} | {} words |\n",
            full * 1e3,
            all.shadow_rays,
            if pairs == 0 {
                "-".to_string()
            } else {
                format!("{:.2} ms", full * 1e3 / (pairs as f64 / 1e3))
            },
            moved * 1e3,
            reach.get(one).copied().unwrap_or(0),
            c.shadow_rays,
            c.bricks_relit,
            all.shadow_cache_words,
        ))
    }
}

/// The front-face bricks of `asset` each of `lights` reaches (the CPU twin of the cull stage).
fn reach(asset: &prt_format::Asset, lights: &[prt_format::Light]) -> Vec<usize> {
    let normals = prt_runtime::lights::brick_normal_bounds(asset);
    lights
        .iter()
        .map(|light| {
            let l = prt_runtime::lights::PreparedLight::new(light);
            asset
                .bricks
                .iter()
                .zip(&normals)
                .filter(|(b, nb)| {
                    b.flags & prt_format::BRICK_BACKFACE == 0 && l.cull(b, nb).is_none()
                })
                .count()
        })
        .collect()
}
