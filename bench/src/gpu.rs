//! `prt-bench gpu`: the GPU runtime's costs, measured against its baselines in the same run
//! (the prior art's per-probe surfels, an update with nothing changed) and returned as a
//! Markdown report. Benches are measurements, never tests.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use prt_bake::{BakeSettings, NoProgress};
use prt_runtime::gpu::{headless_device, wgpu, Bounces, PrtRuntime, RuntimeSettings};
use prt_runtime::Lighting;

use crate::lights::LightsArgs;
use crate::results::Out;

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

#[derive(clap::Args)]
pub struct GpuArgs {
    scene: PathBuf,
    #[arg(long)]
    lights: PathBuf,
    /// Probe spacings to bake the scene at (one table row each).
    #[arg(long, value_delimiter = ',', default_value = "0.2,0.0857,0.04")]
    spacings: Vec<f32>,
    #[arg(long, default_value_t = 256)]
    rays: u32,
    /// Surfel cell size, fixed so that only the probe count changes between rows.
    #[arg(long, default_value_t = 0.05)]
    cell_size: f32,
    /// Far hits in coarse bricks from this many brick sizes (the bake's `--far-ratio`; 0: none).
    #[arg(long, default_value_t = 0.0)]
    far_ratio: f32,
    #[command(flatten)]
    out: Out,
}

/// `prt-bench gpu`: the table of [`gpu`], then cost against light count on the same scene
/// ([`crate::lights::table`]), each printed as it is done; with `--out` both go to `gpu.md`.
pub fn run(args: GpuArgs) -> Result<()> {
    let lighting = prt_runtime::load_rig(&args.lights)?;
    let gpu = gpu(
        &args.scene,
        &lighting,
        &args.spacings,
        args.rays,
        (args.cell_size, args.far_ratio),
    )?;
    println!("{gpu}");
    // Cost against light count, on the same scene (`prt-bench lights` alone).
    let lights = crate::lights::table(&LightsArgs {
        scene: args.scene,
        lights: vec![1, 32, 256, 1024],
        spacing: None,
        rays: args.rays,
        double_sided: false,
        repeats: 5,
        out: Out::default(),
    })?;
    println!("{lights}");
    args.out.write("gpu", &format!("{gpu}\n{lights}"))
}

/// What every row of [`gpu`] is measured with: one device, the scene's bake settings, the rig
/// as given (`lit`) and with every light moved a little (`moved`), and two constant skies.
struct Setup<'a> {
    device: wgpu::Device,
    queue: wgpu::Queue,
    scene: &'a Path,
    rays: u32,
    cell: f32,
    far_ratio: f32,
    runtime: RuntimeSettings,
    lit: &'a Lighting,
    moved: Lighting,
    skies: [Lighting; 2],
}

/// One row of [`gpu`]: seconds per update of each kind.
struct Row {
    probes: usize,
    factors_per_probe: f64,
    full: f64,
    gather: f64,
    idle: f64,
    bounce: f64,
    /// The prior art's update, when the bake is small enough to run it.
    prior: Option<f64>,
}

/// GPU runtime costs, all measured in one run on one adapter: full update per probe at several
/// probe counts, the gather alone, the update against the prior art's
/// scheme (every probe relights its own unmerged surfels), an update when nothing changed, and a
/// multi-bounce update (the volume fed back into every surfel).
pub fn gpu(
    scene: &Path,
    a: &Lighting,
    spacings: &[f32],
    rays: u32,
    (cell, far_ratio): (f32, f32),
) -> Result<String> {
    let (device, queue, info) = headless_device()?;
    let sky = |c: f32| Lighting {
        rig: a.rig.clone(),
        sky: prt_runtime::SkyModel::Constant([c, c, c]),
    };
    let mut moved = a.clone();
    for l in &mut moved.rig.lights {
        l.position[0] += 0.05;
        l.direction[0] += 0.05;
    }
    let mut md = format!(
        "Adapter: {} ({:?}), subgroups: {}. Scene {}, {rays} rays per probe, cell size {cell} m, \
         far ratio {far_ratio}. \
         Times are wall-clock per update (record, submit, wait); lavapipe runs on the CPU, so \
         compare ratios, not absolute times.\n\n",
        info.name,
        info.backend,
        device.features().contains(wgpu::Features::SUBGROUP),
        scene.display()
    );
    let setup = Setup {
        device,
        queue,
        scene,
        rays,
        cell,
        far_ratio,
        runtime: RuntimeSettings::default().fitted_to(a),
        lit: a,
        moved,
        skies: [sky(0.3), sky(0.4)],
    };
    md.push_str("| probes | factors/probe | full update (lights moved) | per probe | gather only (sky changed) | nothing changed | bounce update (feedback) | bounce / full | prior art: own surfels per probe | speed-up vs prior art |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for &spacing in spacings {
        let r = setup.row(spacing)?;
        writeln!(
            md,
            "| {} | {:.0} | {:.1} ms | {:.2} µs | {:.1} ms | {:.3} ms | {:.1} ms | {:.2}x | {} | {} |",
            r.probes,
            r.factors_per_probe,
            r.full * 1e3,
            r.full * 1e6 / r.probes as f64,
            r.gather * 1e3,
            r.idle * 1e3,
            r.bounce * 1e3,
            r.bounce / r.full,
            r.prior.map_or("not run".into(), |p| format!("{:.1} ms", p * 1e3)),
            r.prior.map_or("-".into(), |p| format!("{:.1}x", p / r.full)),
        )?;
    }
    Ok(md)
}

/// Updates timed per row.
const ITERATIONS: u32 = 4;

impl Setup<'_> {
    /// `iterations` updates of `runtime` with `lighting(i)` ([`time_updates`]).
    fn time<'a>(
        &self,
        runtime: &mut PrtRuntime,
        iterations: u32,
        lighting: impl Fn(u32) -> &'a Lighting,
    ) -> Result<f64> {
        time_updates(&self.device, &self.queue, runtime, iterations, lighting)
    }

    /// The scene baked at `spacing`, its updates timed.
    fn row(&self, spacing: f32) -> Result<Row> {
        let settings = BakeSettings {
            rays: self.rays,
            spacing: Some(spacing),
            cell_size: Some(self.cell),
            far_ratio: self.far_ratio,
            // Every grid point traced: the cost per probe is measured against the prior art's,
            // whose probes are all real (and the published rows were uniform).
            sparse: false,
            ..BakeSettings::default()
        };
        let (asset, _) = prt_bake::bake(self.scene, &settings, &NoProgress)?;
        let probes = asset.probes.len();
        let a = self.lit;
        let mut runtime = PrtRuntime::new(&self.device, &self.queue, &asset, self.runtime)?;
        self.time(&mut runtime, 1, |_| a)?;
        let full = self.time(&mut runtime, ITERATIONS, alternate(&self.moved, a))?;
        let [sky1, sky2] = &self.skies;
        let gather = self.time(&mut runtime, ITERATIONS, alternate(sky1, sky2))?;
        let idle = self.time(&mut runtime, ITERATIONS, |_| sky2)?;
        drop(runtime);
        // Endless feedback with nothing changed: every update samples the volume at every
        // surfel, rebuilds every brick and gathers every probe (one more bounce each).
        let feedback = RuntimeSettings {
            bounces: Bounces::Feedback { damping: 1.0 },
            ..self.runtime
        };
        let mut runtime = PrtRuntime::new(&self.device, &self.queue, &asset, feedback)?;
        // The first update lights; the second is the first to run the bounce stage.
        self.time(&mut runtime, 2, |_| a)?;
        let bounce = self.time(&mut runtime, ITERATIONS, |_| a)?;
        drop(runtime);
        let prior = match probes <= 2_000 {
            true => Some(self.prior_art(&settings)?),
            false => None,
        };
        Ok(Row {
            probes,
            factors_per_probe: asset.factors.factor_counts().0 as f64 / probes as f64,
            full,
            gather,
            idle,
            bounce,
            prior,
        })
    }

    /// The prior art's full update: the bake of `settings` unmerged, every probe relighting its
    /// own surfels.
    fn prior_art(&self, settings: &BakeSettings) -> Result<f64> {
        let unmerged = BakeSettings {
            cell_size: Some(0.0),
            ..settings.clone()
        };
        let (asset, _) = prt_bake::bake(self.scene, &unmerged, &NoProgress)?;
        let mut runtime = PrtRuntime::new(&self.device, &self.queue, &asset, self.runtime)?;
        let a = self.lit;
        self.time(&mut runtime, 1, |_| a)?;
        self.time(&mut runtime, ITERATIONS, alternate(&self.moved, a))
    }
}
