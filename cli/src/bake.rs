//! `prt bake` (docs/conventions.md section 6): the bake's options, turned into [`BakeSettings`] for
//! [`prt_bake::bake_to_file`], and the summary printed once the asset is written.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use prt_bake::BakeSettings;
use prt_format::TransferPrecision;

use prt_cli::options::parse_bounds;
use prt_cli::panics;
use prt_cli::process::peak_rss_kib;

use crate::progress;

#[derive(Clone, Copy, ValueEnum)]
enum Quality {
    /// The pure 512-direction lattice, every hit in its own brick's factor, fixed for good:
    /// what the data-equivalence tests against the reference renderer use; a quarter of the
    /// default's trace time.
    Fast,
    /// 2048 rays per probe, far hits (5 brick sizes away and more) in coarse bricks: a fifth
    /// more transport bytes a probe than `fast` (13% more runtime data on the level family),
    /// less noise where a hard sun lights small patches, probe SH nearer the reference
    /// (`BakeSettings::rays` has the figures), 2x the bake time.
    Default,
    /// 4096 rays per probe, cells of a 24th of the spacing, no coarse bricks: against `fast`
    /// about 8x lower error on the Cornell reference, 8x the trace time and about 5.6x the
    /// factors per probe.
    High,
}

#[derive(Clone, Copy, ValueEnum)]
enum Precision {
    /// 32-byte factors of halves.
    F16,
    /// 56-byte factors of floats, and surfels of floats (80 bytes; 32 otherwise).
    F32,
    /// Factors of 8 bytes where a lobe toward the mean hit point fits their SH terms (`R` and
    /// the band-2 scale stored; most factors), 16 with 7-bit band-1 and 5-bit band-2 terms
    /// elsewhere; 6-bit offsets.
    U8,
}

#[derive(Args)]
pub struct BakeArgs {
    /// The scene (.gltf or .glb).
    scene: PathBuf,
    /// Output asset (.prt), written atomically.
    #[arg(short, long)]
    output: PathBuf,
    /// Probe spacing in metres [default: about 4,000 probes over the bounds].
    #[arg(long)]
    spacing: Option<f32>,
    /// Trace every grid point. By default the bake traces the points surfaces need (within a
    /// cell and a quarter spacing of a triangle) and coarse levels 2, 4 and 8 steps apart
    /// around them, and the runtime fills the other points from those levels.
    #[arg(long)]
    uniform: bool,
    /// Bake bounds MINX,MINY,MINZ,MAXX,MAXY,MAXZ [default: the scene's bounds].
    #[arg(long, value_parser = parse_bounds, allow_hyphen_values = true)]
    bounds: Option<[f32; 6]>,
    /// Rays per probe [default: the --quality preset's: 2048, fast 512, high 4096].
    #[arg(long)]
    rays: Option<u32>,
    /// Accuracy preset.
    #[arg(long, value_enum, default_value = "default")]
    quality: Quality,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Refuse grids with more probes than this.
    #[arg(long, default_value_t = 1 << 20)]
    max_probes: u64,
    /// At most this many probes with data: past it the bake drops the probes between every
    /// other grid point whose light those points predict best (those that see all those
    /// points around them first), and the runtime fills them from those points [default: no
    /// budget].
    #[arg(long)]
    probe_budget: Option<usize>,
    /// Drop the probes between every other grid point whose light those points predict
    /// within this error (in units of pi, under test lightings of stripes, sky, a point light
    /// and half-spaces) whatever the budget; 0 keeps them [default: the --quality preset's:
    /// 0.15, high 0; sparse bakes only].
    #[arg(long)]
    prune_error: Option<f32>,
    /// Surfel cell size in metres (bricks are 4x4x4 cells) [default: spacing /
    /// --cells-per-spacing]; 0 = no merging.
    #[arg(long)]
    cell_size: Option<f32>,
    /// Surfel cells per probe spacing, 1 to 256, whatever spacing the bake picks. 6 takes
    /// about a quarter fewer runtime bytes than 8 at about the same error on Sponza under 31
    /// lights and small levels, but is worse under a hard sun (docs/results/cells.md)
    /// [default: the --quality preset's: 8, high 24].
    #[arg(long, conflicts_with_all = ["cell_size", "no_merge"])]
    cells_per_spacing: Option<f32>,
    /// Keep every ray hit as its own surfel and brick (same as --cell-size 0).
    #[arg(long)]
    no_merge: bool,
    /// Hits at least this many brick sizes from their probe share factors of coarse bricks,
    /// one level coarser each time the distance doubles up to cells of 8 bricks; 0 gives every
    /// brick its own factor
    /// [default: the --quality preset's: 5, fast and high 0].
    #[arg(long)]
    far_ratio: Option<f32>,
    /// Treat every material as double-sided (for files with inconsistent winding).
    #[arg(long)]
    double_sided: bool,
    /// Leave probes inside geometry where they are (dilated or invalid) instead of moving them
    /// out through the nearest back side their rays hit, within half a spacing.
    #[arg(long)]
    no_virtual_offset: bool,
    /// Keep a brick whole where a wall stands on it: by default it is split into a brick per
    /// side, so that a dark room beside a lit one does not read the lit side's light through
    /// the floor or wall that runs on under their shared wall (docs/surfaces.md).
    #[arg(long)]
    no_split_bricks: bool,
    /// Probes with more than this fraction of back-face hits are invalid.
    #[arg(long, default_value_t = 0.1)]
    invalid_backface_fraction: f32,
    /// Probes that see no sky and hit the back of their triangles' winding with more than
    /// this fraction of their rays are inside closed geometry (double-sided thick walls).
    #[arg(long, default_value_t = 0.75)]
    inside_facing_away_fraction: f32,
    /// Leave probes inside geometry empty instead of copying their nearest valid
    /// neighbour's data (dilation).
    #[arg(long)]
    no_dilation: bool,
    /// Keep probes that lie on a surface where they are (by default they move a twentieth
    /// of a spacing off it).
    #[arg(long)]
    no_surface_offset: bool,
    /// Skip the surface terms (which probes each surfel sees, its near field): a faster bake
    /// whose surfaces are sampled from the probe volume alone.
    #[arg(long)]
    no_surface_terms: bool,
    /// Storage precision of factor transfers (f32 also keeps surfels in f32).
    #[arg(long, value_enum, default_value = "u8")]
    precision: Precision,
    /// MiB of factor rows held in memory while probes are traced; past it the oldest wait
    /// in a temporary file in $TMPDIR (the asset is the same).
    #[arg(long, default_value_t = BakeSettings::default().row_memory >> 20)]
    row_memory: usize,
    /// A folder besides the scene's own whose files its buffer and image URIs may name (a
    /// shared texture folder); repeatable. Without it a URI resolving elsewhere is refused.
    #[arg(long = "allow-path", value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

/// Bakes as `args` say, prints the summary, and fails with the bake's error named by its scene.
pub fn run(args: BakeArgs) -> Result<()> {
    let BakeArgs {
        scene,
        output,
        spacing,
        uniform,
        bounds,
        rays,
        quality,
        threads,
        max_probes,
        probe_budget,
        prune_error,
        cell_size,
        cells_per_spacing,
        no_merge,
        far_ratio,
        double_sided,
        no_virtual_offset,
        no_split_bricks,
        invalid_backface_fraction,
        inside_facing_away_fraction,
        no_dilation,
        no_surface_offset,
        no_surface_terms,
        precision,
        row_memory,
        allow_path,
    } = args;
    let preset = match quality {
        Quality::Fast => BakeSettings::fast(),
        Quality::Default => BakeSettings::default(),
        Quality::High => BakeSettings::high_quality(),
    };
    if uniform && prune_error.is_some() {
        anyhow::bail!(
            "--prune-error applies to sparse bakes; --uniform keeps every traced probe \
             (--probe-budget still caps the count)"
        );
    }
    let settings = BakeSettings {
        rays: rays.unwrap_or(preset.rays),
        spacing,
        sparse: !uniform,
        bounds,
        max_probes,
        probe_budget,
        prune_error: prune_error.unwrap_or(preset.prune_error),
        cell_size: if no_merge { Some(0.0) } else { cell_size },
        cells_per_spacing: cells_per_spacing.unwrap_or(preset.cells_per_spacing),
        far_ratio: far_ratio.unwrap_or(preset.far_ratio),
        double_sided,
        virtual_offset: !no_virtual_offset,
        split_bricks: !no_split_bricks,
        invalid_backface_fraction,
        inside_facing_away_fraction,
        dilate: !no_dilation,
        surface_terms: !no_surface_terms,
        surface_offset: !no_surface_offset,
        transfer_precision: match precision {
            Precision::F16 => TransferPrecision::F16,
            Precision::F32 => TransferPrecision::F32,
            Precision::U8 => TransferPrecision::U8,
        },
        threads,
        row_memory: row_memory.saturating_mul(1 << 20),
        allowed: prt_scene::Allowed { dirs: allow_path },
        ..preset
    };
    let progress = progress::Bar::new();
    let (asset, report) =
        panics::quietly(|| prt_bake::bake_to_file(&scene, &output, &settings, &progress))
            .with_context(|| format!("baking {}", scene.display()))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    println!("{}", prt_format::Summary::of(&asset, report.file_bytes));
    if let Some(p) = report.placed {
        println!("{}", placement_line(&p));
    }
    if let Some(r) = report.refined {
        println!("{}", refine_line(&r));
    }
    if report.split.0 > 0 {
        println!(
            "split            {} bricks where a wall stands on them, into {} parts",
            report.split.0, report.split.1
        );
    }
    let times: Vec<String> = report
        .timings
        .iter()
        .map(|(stage, d)| format!("{stage} {:.3} s", d.as_secs_f64()))
        .collect();
    println!("time             {}", times.join(" | "));
    if let Some(kb) = peak_rss_kib() {
        let spilled = match report.rows_spilled {
            0 => String::new(),
            b => format!(
                " ({:.1} MiB of factor rows past --row-memory waited in a temporary file)",
                b as f64 / f64::from(1 << 20)
            ),
        };
        println!(
            "peak memory      {:.1} MiB resident{spilled}",
            kb as f64 / 1024.0
        );
    }
    // `prt-bench bake --runs` times a bake to this line: keep its first word.
    println!("wrote            {}", output.display());
    Ok(())
}

/// The summary line of what the refine stage dropped.
fn refine_line(r: &prt_bake::refine::Refined) -> String {
    let budget = r.budget.map_or(String::new(), |b| format!(" (budget {b})"));
    format!(
        "refine           {} of {} probes between every other grid point dropped (prediction \
         error up to {:.3}), filled from those points; {} of {} probes with data kept{budget}",
        r.dropped, r.candidates, r.worst_dropped, r.after, r.before
    )
}

/// The summary line of what sparse placement placed where.
fn placement_line(p: &prt_bake::Placed) -> String {
    let filled: usize = p.filled.iter().sum();
    format!(
        "placement        sparse: {} grid points traced; {filled} filled from coarse levels \
         1 / 2 / 3 (probes 2 / 4 / 8 steps apart: {:?}); {} without light (not traced, and \
         their level's probes all inside geometry); cells surfaces pass through per level: {:?}",
        p.traced,
        p.filled,
        p.grid - p.traced - filled,
        p.busy_cells
    )
}
