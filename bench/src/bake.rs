//! `prt-bench bake`: bake throughput against bare obvhs tracing of the same rays.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Vec3;
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, CwBvh},
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    BvhBuildParams,
};
use prt_bake::{bench, BakeSettings, NoProgress};
use prt_cli::options::parse_bounds;
use rayon::prelude::*;

use crate::results::Out;

#[derive(clap::Args)]
pub struct BakeArgs {
    scene: PathBuf,
    #[arg(long)]
    spacing: Option<f32>,
    #[arg(long, value_parser = parse_bounds, allow_hyphen_values = true)]
    bounds: Option<[f32; 6]>,
    #[arg(long, default_value_t = 512)]
    rays: u32,
    #[arg(long)]
    double_sided: bool,
    /// Bakes, each followed by bare obvhs tracing of its rays, in turn: the first run's
    /// report in full, then a last row of every run's ratio and their median (one run's
    /// swings by 10-20% on a shared machine); the bakes after the first are `prt bake`
    /// processes of their own, timed to the asset written and, in a second median, to
    /// their exit.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    runs: u32,
    /// The `prt` binary whose `prt bake` processes --runs times [default: the `prt` beside this
    /// executable, where `cargo build --release -p prt` puts it].
    #[arg(long, value_name = "PATH")]
    prt: Option<PathBuf>,
    #[command(flatten)]
    out: Out,
}

/// `prt-bench bake`: the report of [`bake`], printed and with `--out` written to `bake.md`.
pub fn run(args: BakeArgs) -> Result<()> {
    let settings = BakeSettings {
        rays: args.rays,
        spacing: args.spacing,
        bounds: args.bounds,
        double_sided: args.double_sided,
        // Every grid point, as the bare obvhs trace it is measured against.
        sparse: false,
        ..BakeSettings::default()
    };
    let runs = args.runs as usize;
    let prt = match args.prt {
        Some(path) => path,
        None => std::env::current_exe()
            .context("finding this executable, beside which `prt` is looked for")?
            .with_file_name(format!("prt{}", std::env::consts::EXE_SUFFIX)),
    };
    // Checked before the first bake, not after it.
    anyhow::ensure!(
        runs == 1 || prt.is_file(),
        "{}: no `prt` binary there, which --runs {runs} runs as `prt bake` processes; build it \
         with `cargo build --release -p prt` or name one with --prt PATH",
        prt.display()
    );
    let md = bake(&args.scene, &settings, runs, &prt)?;
    args.out.report("bake", &md)
}

/// obvhs as its documentation shows it: a CWBVH from `build_cwbvh_from_tris` (PLOC, medium
/// preset) and its closest-hit traversal over `RtTriangle`s in BVH order.
struct ObvhsTracer {
    cwbvh: CwBvh,
    triangles: Vec<RtTriangle>,
}

impl ObvhsTracer {
    /// In the bake's tracing frame (`scale`, [`bench::trace_scale`]).
    fn build(triangles: &[[Vec3; 3]], scale: f32) -> ObvhsTracer {
        let tris = bench::traced_triangles(triangles, scale);
        let cwbvh = build_cwbvh_from_tris(
            &tris,
            BvhBuildParams::medium_build(),
            &mut std::time::Duration::default(),
        );
        let triangles = cwbvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        ObvhsTracer { cwbvh, triangles }
    }

    /// Whether the ray hits anything (closest-hit traversal).
    fn hits(&self, origin: Vec3, dir: Vec3) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let mut hit = RayHit::none();
        self.cwbvh.ray_traverse(
            Ray::new_inf(origin.into(), dir.into()),
            &mut hit,
            |r, id| self.triangles[id].intersect(r),
        )
    }
}

/// Bare closest-hit tracing of a bake's rays: seconds and hit count of each way of tracing them.
struct Bare {
    /// obvhs, single rays: from the asset's probe positions in lattice order and in the bake's
    /// order, then from the grid points in the bake's order; `None` when obvhs panicked
    /// building its BVH (it does on boxes near f32's range).
    obvhs: Option<[(f64, usize); 3]>,
    /// The bake's packet tracer from the asset's probe positions, the bake's order and lattice
    /// order.
    packets: [(f64, usize); 2],
    /// The obvhs tracer (`None` as above) and the rays, for [`repeated`] runs.
    tracer: Option<ObvhsTracer>,
    rays: Rays,
}

/// Times bare tracing of `asset`'s probes and lattice (`rays` per probe) through obvhs and
/// through the bake's packet tracer.
///
/// The bake's rays leave the probes' positions as the asset records them: a grid point that
/// lies on a surface (Sponza's grid puts a layer of probes on its floor and walls) moves a
/// twentieth of a spacing off it first ([`prt_bake::offset::surface_offset`]). Traced from the
/// grid points instead, as this bench did before, those probes' rays start on the surface, and
/// the ones into it end at once (packets) or pass through it (obvhs, which skips a box within
/// 1e-4 of the origin): other, cheaper rays than the bake's. Both are timed; the ratio to the
/// grid points' rays is kept for comparison with earlier figures.
fn bare(scene: &Path, asset: &prt_format::Asset, rays: u32) -> Result<Bare> {
    let loaded = prt_scene::load(scene, &prt_scene::Allowed::default())?;
    let rays_of = Rays::of(asset, rays);
    let Rays {
        scale,
        ref dirs,
        ref probes,
        ref lattice,
    } = rays_of;
    let grid = bench::grid_points(&asset.header.grid);
    let coherent = bench::coherent_order(dirs);
    let tracer = std::panic::catch_unwind(|| ObvhsTracer::build(&loaded.triangles, scale)).ok();
    let obvhs = tracer.as_ref().map(|o| {
        let run = [(probes, lattice), (probes, &coherent), (&grid, &coherent)];
        run.map(|(positions, order)| rays_of.obvhs(o, positions, order))
    });
    // The bake's BVH: built with the preset the bake chose for these rays.
    let traced = probes.len() as u64 * u64::from(rays);
    let bvh = bench::scene_bvh(&loaded.triangles, scale, traced)?;
    let packets = [&coherent, lattice].map(|order| {
        timed(probes, &|p| {
            order
                .chunks(bench::PACKET)
                .map(|packet| {
                    let d: Vec<Vec3> = packet.iter().map(|&i| dirs[i as usize]).collect();
                    let hits = bvh.closest_hits(p, &d, f32::INFINITY);
                    hits.iter().flatten().count()
                })
                .sum()
        })
    });
    Ok(Bare {
        obvhs,
        packets,
        tracer,
        rays: rays_of,
    })
}

/// A bake's rays: its probes' positions and its lattice, with the tracing frame's `scale`.
struct Rays {
    scale: f32,
    dirs: Vec<Vec3>,
    probes: Vec<Vec3>,
    /// The lattice's own order.
    lattice: Vec<u32>,
}

impl Rays {
    fn of(asset: &prt_format::Asset, rays: u32) -> Rays {
        Rays {
            scale: bench::trace_scale(asset.header.grid.spacing),
            dirs: prt_format::directions::fibonacci_directions(rays)
                .into_iter()
                .map(Vec3::from)
                .collect(),
            probes: asset.probes.iter().map(|p| p.position.into()).collect(),
            lattice: (0..rays).collect(),
        }
    }

    /// Seconds and hits of obvhs tracing the lattice in `order` from `positions`.
    fn obvhs(&self, o: &ObvhsTracer, positions: &[Vec3], order: &[u32]) -> (f64, usize) {
        timed(positions, &|p| {
            order
                .iter()
                .filter(|&&i| o.hits(p * self.scale, self.dirs[i as usize]))
                .count()
        })
    }
}

/// Seconds and hits of tracing from every position in parallel.
fn timed(positions: &[Vec3], per_probe: &(dyn Fn(Vec3) -> usize + Sync)) -> (f64, usize) {
    let t = Instant::now();
    let hits: usize = positions.par_iter().map(|&p| per_probe(p)).sum();
    (t.elapsed().as_secs_f64(), hits)
}

/// A report row: the throughput ratio of `runs` end-to-end bakes to bare obvhs tracing of
/// their rays in lattice order (`bare`'s tracer), taken in turn, the first pair `first` (bake
/// seconds, obvhs seconds), and their median. The bakes after the first are `prt bake`
/// processes of their own ([`bake_process`]), timed from their start to the asset written (the
/// issue's "process start to file written") and, for a second median and range over them
/// alone (in brackets), to their exit. Processes, not more bakes in this one: a process's first
/// bake pays for every page it touches (2.1-2.5 us a page fault here), and later bakes in the
/// same process reuse what the allocator kept (Sponza at 1.9 m: 0.47-0.50 s against 0.54 s
/// for the first, 14-21k page faults against 44k), which would flatter the bake. On a shared
/// machine one run's ratio swings by 10-20%; pairs taken in turn see the same conditions. A
/// run that fails ends the row with its error; the rest of the report stands.
fn repeated(
    prt: &Path,
    scene: &Path,
    settings: &BakeSettings,
    bare: &Bare,
    runs: usize,
    first: (f64, f64),
) -> String {
    let label = format!(
        "end-to-end throughput / bare obvhs throughput, lattice order, {runs} runs in turn \
         (the first in this process, then `prt bake` processes to the file written; in \
         brackets, the processes to their exit)"
    );
    let Some(o) = &bare.tracer else {
        return format!("| {label} | n/a: obvhs panicked building its BVH |\n");
    };
    let rays = &bare.rays;
    // (to the file written, to exit, obvhs); the first bake ran in this process.
    let mut runs_s = vec![(first.0, first.0, first.1)];
    let mut failed = String::new();
    for run in 1..runs {
        match bake_process(prt, scene, settings) {
            Ok(ProcessTimes { written, exit }) => {
                let obvhs_s = rays.obvhs(o, &rays.probes, &rays.lattice).0;
                runs_s.push((written, exit, obvhs_s));
            }
            Err(e) => {
                failed = format!("; run {} failed: {e:#}", run + 1);
                break;
            }
        }
    }
    // The first run has no exit of its own: the bracketed figures leave it out.
    let processes = &runs_s[1..];
    let ratios = |runs: &[(f64, f64, f64)], bake: fn(&(f64, f64, f64)) -> f64| -> Vec<f64> {
        runs.iter().map(|r| 100.0 * r.2 / bake(r)).collect()
    };
    let median = |mut v: Vec<f64>| -> String {
        v.sort_by(f64::total_cmp);
        match v.len() {
            0 => "n/a".into(),
            n => format!("{:.0}%", 0.5 * (v[(n - 1) / 2] + v[n / 2])),
        }
    };
    let range = |runs: &[(f64, f64, f64)], f: fn(&(f64, f64, f64)) -> f64| {
        let (lo, hi) = runs
            .iter()
            .map(f)
            .fold((f64::INFINITY, 0.0f64), |(l, h), x| (l.min(x), h.max(x)));
        match runs.is_empty() {
            true => "n/a".into(),
            false => format!("{lo:.3}-{hi:.3} s"),
        }
    };
    let written = ratios(&runs_s, |r| r.0);
    let listed = written
        .iter()
        .map(|r| format!("{r:.0}%"))
        .collect::<Vec<_>>();
    format!(
        "| {label} | {} (median {} [{}]); bakes {} [{}], obvhs {}{failed} |\n",
        listed.join(", "),
        median(written),
        median(ratios(processes, |r| r.1)),
        range(&runs_s, |r| r.0),
        range(processes, |r| r.1),
        range(&runs_s, |r| r.2),
    )
}

/// Where the bench's bakes write their asset (one at a time, removed after each): a file in the
/// temporary directory named after this process.
fn output_path() -> PathBuf {
    std::env::temp_dir().join(format!("prt-bench-bake-{}.prt", std::process::id()))
}

/// Seconds of a `prt bake` process from its start.
struct ProcessTimes {
    /// To its "wrote" line, printed once the asset is renamed into place.
    written: f64,
    /// To its exit: after the file is written, the process frees what it holds and the kernel
    /// tears it down (Sponza, 2 threads: 9-20 ms at 1.9 m, 33-48 ms at 1.0 m).
    exit: f64,
}

/// Runs `prt bake` with `settings` (the `prt` binary at `exe`, the options the bench takes, the
/// rest at their defaults), the asset written to a temporary file and removed, and times it.
fn bake_process(exe: &Path, scene: &Path, settings: &BakeSettings) -> Result<ProcessTimes> {
    use std::io::{BufRead, Read};
    let out = output_path();
    let mut args: Vec<std::ffi::OsString> = vec!["bake".into(), scene.into(), "-o".into()];
    args.push(out.clone().into());
    args.extend(["--rays".into(), settings.rays.to_string().into()]);
    if let Some(s) = settings.spacing {
        args.extend(["--spacing".into(), s.to_string().into()]);
    }
    if let Some(b) = settings.bounds {
        let b = b.map(|v| v.to_string()).join(",");
        args.push(format!("--bounds={b}").into());
    }
    if settings.double_sided {
        args.push("--double-sided".into());
    }
    if !settings.sparse {
        args.push("--uniform".into());
    }
    let start = Instant::now();
    let mut child = std::process::Command::new(exe)
        .args(&args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .with_context(|| format!("running {}", exe.display()))?;
    let (stdout, mut stderr) = (child.stdout.take(), child.stderr.take());
    // Stderr drained beside stdout, so that neither pipe fills while the other is read.
    let (written, errors) = std::thread::scope(|s| {
        let errors = s.spawn(move || {
            let mut text = String::new();
            if let Some(e) = stderr.as_mut() {
                e.read_to_string(&mut text).ok();
            }
            text
        });
        let mut written = None;
        for line in stdout
            .into_iter()
            .flat_map(|o| std::io::BufReader::new(o).lines())
        {
            if line.is_ok_and(|l| l.starts_with("wrote")) {
                written = Some(start.elapsed().as_secs_f64());
            }
        }
        (written, errors.join().unwrap_or_default())
    });
    let status = child.wait();
    let exit = start.elapsed().as_secs_f64();
    std::fs::remove_file(&out).ok();
    let status = status.with_context(|| format!("waiting for {}", exe.display()))?;
    match (status.success(), written) {
        (true, Some(written)) => Ok(ProcessTimes { written, exit }),
        (true, None) => anyhow::bail!("`prt bake` for the repeated runs printed no \"wrote\" line"),
        (false, _) => anyhow::bail!(
            "`prt bake` for the repeated runs failed ({status}): {}",
            errors.trim()
        ),
    }
}

/// Bake throughput against bare obvhs tracing of the same rays, and asset size per probe.
/// With `runs` above 1, more bakes (`prt bake` processes of the binary `prt`) and obvhs runs in
/// turn after the first ([`repeated`]).
fn bake(scene: &Path, settings: &BakeSettings, runs: usize, prt: &Path) -> Result<String> {
    // To a file, synced, as `prt bake` does: the "process start to file written".
    let out = output_path();
    let (start, before) = (Instant::now(), usage());
    let baked = prt_bake::bake_to_file(scene, &out, settings, &NoProgress);
    let bake_s = start.elapsed().as_secs_f64();
    let cpu = cpu_since(before);
    std::fs::remove_file(&out).ok();
    let (asset, report) = baked?;
    let peak = prt_cli::process::peak_rss_kib().map_or("unknown".into(), |kb| {
        format!("{:.0} MiB", kb as f64 / 1024.0)
    });
    let bare = bare(scene, &asset, settings.rays)?;
    let summary = prt_format::Summary::of(&asset, report.file_bytes);
    let rays = asset.probes.len() as f64 * f64::from(settings.rays);
    let trace_s = report
        .timings
        .iter()
        .find(|(s, _)| *s == "trace")
        .map_or(0.0, |(_, d)| d.as_secs_f64());
    let mut md = String::new();
    head_rows(&mut md, scene, settings.rays, &summary)?;
    writeln!(md, "| peak memory of the bake (resident) | {peak} |")?;
    writeln!(
        md,
        "| factor rows past the memory budget, through a temporary file | {:.1} MiB |",
        report.rows_spilled as f64 / f64::from(1 << 20)
    )?;
    writeln!(
        md,
        "| CPU time of the bake (system time: page faults and the file write) | {cpu} |"
    )?;
    writeln!(
        md,
        "| end-to-end bake (load, BVH, trace, bricks, assemble, write to a file and sync it) | {bake_s:.3} s |"
    )?;
    writeln!(
        md,
        "| end-to-end throughput | {:.0} probes/s, {:.2} M rays/s |",
        summary.probe_count as f64 / bake_s,
        rays / bake_s / 1e6
    )?;
    writeln!(
        md,
        "| bake trace stage alone (tracing and merging, overlapped) | {:.2} M rays/s |",
        rays / trace_s / 1e6
    )?;
    baseline_rows(&mut md, &bare, rays, bake_s)?;
    writeln!(
        md,
        "| stage times | {} |",
        report
            .timings
            .iter()
            .map(|(s, d)| format!("{s} {:.3} s", d.as_secs_f64()))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    sizes(&mut md, &summary)?;
    if runs > 1 {
        let obvhs_s = bare.obvhs.map_or(f64::NAN, |[(s, _), ..]| s);
        md.push_str(&repeated(
            prt,
            scene,
            settings,
            &bare,
            runs,
            (bake_s, obvhs_s),
        ));
    }
    Ok(md)
}

/// The report's header and its rows of what was baked: the scene, its probes, rays and threads.
fn head_rows(
    md: &mut String,
    scene: &Path,
    rays: u32,
    summary: &prt_format::Summary,
) -> Result<()> {
    writeln!(md, "| figure | value |\n|---|---|")?;
    writeln!(
        md,
        "| scene | {} ({} triangles) |",
        scene.display(),
        summary.triangle_count
    )?;
    writeln!(
        md,
        "| probes (valid) | {} ({}) |",
        summary.probe_count, summary.valid_probe_count
    )?;
    writeln!(md, "| rays per probe | {rays} |")?;
    writeln!(md, "| threads | {} |", rayon::current_num_threads())?;
    Ok(())
}

/// The report's rows of the baselines: bare obvhs and bare packet tracing of the bake's `rays`
/// rays, and the bake's throughput against obvhs' (`bake_s` end to end).
fn baseline_rows(md: &mut String, bare: &Bare, rays: f64, bake_s: f64) -> Result<()> {
    let timed = |(s, _): (f64, usize)| format!("{s:.3} s, {:.2} M rays/s", rays / s / 1e6);
    match bare.obvhs {
        Some([lattice, coherent, grid]) => {
            writeln!(
                md,
                "| bare obvhs tracing, same rays (from the probes' positions) in lattice order ({} hits) | {} |",
                lattice.1,
                timed(lattice)
            )?;
            writeln!(
                md,
                "| bare obvhs tracing, same rays in the bake's order | {} |",
                timed(coherent)
            )?;
            writeln!(
                md,
                "| bare obvhs tracing from the grid points instead, the bake's order ({} hits) | {} |",
                grid.1,
                timed(grid)
            )?;
        }
        None => writeln!(
            md,
            "| bare obvhs tracing | n/a: obvhs panicked building its BVH |"
        )?,
    }
    let [packets, lattice_packets] = bare.packets;
    writeln!(
        md,
        "| bare packet tracing, the bake's BVH8 and order ({} rays a packet, {} hits) | {} |",
        bench::PACKET,
        packets.1,
        timed(packets)
    )?;
    writeln!(
        md,
        "| bare packet tracing, packets of consecutive rays in lattice order | {} |",
        timed(lattice_packets)
    )?;
    if let Some([lattice, coherent, grid]) = bare.obvhs {
        let rows = [
            ("lattice order", lattice),
            ("the bake's order", coherent),
            ("from the grid points, the bake's order", grid),
        ];
        for (name, (s, _)) in rows {
            writeln!(
                md,
                "| end-to-end throughput / bare tracing throughput, {name} | {:.0}% |",
                100.0 * s / bake_s
            )?;
        }
    }
    Ok(())
}

/// CPU time and page faults of this process so far.
struct Usage {
    user: f64,
    system: f64,
    faults: u64,
}

/// [`Usage`] from `getrusage`. The bake's system time is mostly the kernel zeroing the pages
/// it touches first (its footprint), and that cost varies between sittings of a shared
/// machine far more than tracing does, so the report shows it beside the wall time.
fn usage() -> Option<Usage> {
    let mut u = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes one `rusage` into the pointer it is given, which points at one.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, u.as_mut_ptr()) } != 0 {
        return None;
    }
    // SAFETY: zeroed, then filled by the successful call above.
    let u = unsafe { u.assume_init() };
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(Usage {
        user: secs(u.ru_utime),
        system: secs(u.ru_stime),
        faults: u.ru_minflt as u64,
    })
}

/// CPU time and page faults since `before` ([`usage`]), as the report prints them.
fn cpu_since(before: Option<Usage>) -> String {
    match (before, usage()) {
        (Some(a), Some(b)) => format!(
            "{:.2} s user, {:.2} s system; {} minor page faults",
            b.user - a.user,
            b.system - a.system,
            b.faults - a.faults
        ),
        _ => "unknown".into(),
    }
}

/// The asset's size rows of the report.
fn sizes(md: &mut String, summary: &prt_format::Summary) -> Result<()> {
    writeln!(
        md,
        "| asset bytes per probe (file) | {:.0} |",
        summary.bytes_per_probe
    )?;
    writeln!(
        md,
        "| per-probe runtime data (probe, sky mask and transfer, visibility map, factors) | {:.0} bytes |",
        summary.transport_bytes_per_probe
    )?;
    writeln!(
        md,
        "| factors per probe | {:.1} |",
        summary.factors_per_probe
    )?;
    writeln!(
        md,
        "| surfels (ray hits before merging) / bricks | {} ({}) / {} |",
        summary.surfel_count, summary.surfels_unmerged, summary.brick_count
    )?;
    Ok(())
}
