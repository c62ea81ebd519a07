//! `prt-bench frontier` (issue 32, item 3): what a bake costs against what it buys. Each case
//! of `prt-bench surface` (the level family and Sponza under both rigs by default) is baked at
//! several probe spacings (relative to the case's default) and ray counts, relit on the CPU and
//! sampled with the runtime's lookup at the oracle's surface points and camera pixels. Per
//! setting: bake seconds, the runtime bytes an engine uploads and the transport bytes per
//! probe against the surface error (open points, leaks, over-lit pixels), as tables and as
//! log-log plots with their Pareto fronts: the settings users pick from. The family's figures
//! are medians over its levels (and the worst level), so that no level's size dominates.
//!
//! Placement is the uniform grid or the sparse one (`--placement`; `prt bake --uniform` or the
//! bake's default, issue 32, item 2): the grid points surfaces need and coarse levels around
//! them.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use prt_bake::BakeSettings;
use prt_format::Summary;

use super::cases::{self, Set};
use super::lookups::{Lookups, Overrides};
use super::refs;
use super::report::Setting;
use super::{image, Refs};
use crate::plot::{self, Panel, Point, Series};
use crate::results::{self, Out};

#[derive(clap::Args)]
pub struct FrontierArgs {
    /// Cases (comma-separated), named as `prt-bench surface --case` names them.
    #[arg(
        long = "case",
        value_delimiter = ',',
        default_value = "family,sponza,sponza_sun_2"
    )]
    cases: Vec<String>,
    /// Probe spacings relative to each case's default (1: the default; 0.5: half, 8x the
    /// probes), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1.26,1,0.79,0.63,0.5")]
    scales: Vec<f32>,
    /// Rays per probe, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "512,2048")]
    rays: Vec<u32>,
    /// Surfel cells per probe spacing (the bake's `cells_per_spacing`; 8 is its default),
    /// comma-separated: surfels, bricks and surface terms grow with the square of it.
    #[arg(long, value_delimiter = ',', default_value = "8")]
    cells: Vec<f32>,
    /// Far ratios (the bake's `far_ratio`: hits this many brick sizes away and farther share
    /// coarse bricks; 0: none), comma-separated [default: the bake's].
    #[arg(long, value_delimiter = ',')]
    far: Vec<f32>,
    /// Probe placements, comma-separated: uniform (every grid point), sparse (only those
    /// surfaces need and coarse levels around them, the bake's default).
    #[arg(long, value_delimiter = ',', default_value = "uniform")]
    placement: Vec<Placement>,
    /// Directory the cases' paths are relative to (the repository root).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Also write frontier.md, frontier.svg (the family), frontier_sponza.svg and
    /// frontier_sponza_sun_2.svg to DIR.
    #[command(flatten)]
    out: Out,
}

/// Where a bake places probes.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
enum Placement {
    Uniform,
    Sparse,
}

/// What a bake traces and merges: rays per probe, surfel cells per spacing, far ratio, and
/// where its probes are.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Knob {
    rays: u32,
    cells: f32,
    far: f32,
    placement: Placement,
}

impl Knob {
    fn placement(self) -> &'static str {
        match self.placement {
            Placement::Uniform => "uniform",
            Placement::Sparse => "sparse",
        }
    }

    fn label(self) -> String {
        let sparse = match self.placement {
            Placement::Uniform => "",
            Placement::Sparse => ", sparse",
        };
        format!(
            "{} rays, cells spacing/{}, far {}{sparse}",
            self.rays, self.cells, self.far
        )
    }
}

impl FrontierArgs {
    /// Every ray count with every cell size, far ratio and placement, in argument order.
    fn knobs(&self) -> Vec<Knob> {
        let far = match self.far.is_empty() {
            true => vec![BakeSettings::default().far_ratio],
            false => self.far.clone(),
        };
        let mut knobs = Vec::new();
        for &rays in &self.rays {
            for &cells in &self.cells {
                for &far in &far {
                    for &placement in &self.placement {
                        knobs.push(Knob {
                            rays,
                            cells,
                            far,
                            placement,
                        });
                    }
                }
            }
        }
        knobs
    }
}

/// One bake of one case, scored.
struct Row {
    case: String,
    set: Set,
    knob: Knob,
    /// Spacing relative to the case's default.
    scale: f32,
    spacing: f32,
    probes: usize,
    runtime_bytes: u64,
    transport_per_probe: f64,
    bake_s: f64,
    /// Percent.
    open_mean: f64,
    /// Percent of the open points.
    leaks: f64,
    /// Percent of the view's hit pixels (cases with a camera view).
    over_lit: Option<f64>,
}

/// `prt-bench frontier`: every case at every ray count and spacing, the report printed and with
/// `--out` written with its plots.
pub fn run(args: FrontierArgs) -> Result<()> {
    if args.scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) || args.scales.is_empty() {
        bail!(
            "--scales {:?}: every scale must be a positive number",
            args.scales
        );
    }
    if args.rays.contains(&0) || args.rays.is_empty() {
        bail!("--rays {:?}: every ray count must be at least 1", args.rays);
    }
    if args.cells.iter().any(|c| !(c.is_finite() && *c >= 1.0)) || args.cells.is_empty() {
        bail!("--cells {:?}: every value must be at least 1", args.cells);
    }
    if args.far.iter().any(|f| !(f.is_finite() && *f >= 0.0)) {
        bail!(
            "--far {:?}: every value must be finite and at least 0",
            args.far
        );
    }
    let picked = cases::pick(&args.cases, cases::all(&args.root)?)?;
    let default = ["default".to_owned()];
    let lookup = Lookups::parse(&default, Overrides::default())?.for_set(Set::Bundled)[0];
    let mut rows = Vec::new();
    for case in &picked {
        let refs = Refs {
            points: refs::read_reference(&case.points)?,
            image: case.image.as_deref().map(image::read_image).transpose()?,
            pictures: None,
            points_out: None,
        };
        let lighting = prt_runtime::load_rig(&case.rig)
            .with_context(|| format!("{}: loading the rig {}", case.name, case.rig.display()))?;
        let mut default_spacing = None;
        for knob in args.knobs() {
            for &scale in &args.scales {
                let settings = |spacing: Option<f32>| BakeSettings {
                    double_sided: case.double_sided,
                    rays: knob.rays,
                    cells_per_spacing: knob.cells,
                    far_ratio: knob.far,
                    sparse: knob.placement == Placement::Sparse,
                    spacing,
                    ..BakeSettings::default()
                };
                let scaled = default_spacing.map(|s: f32| s * scale);
                let mut baked = super::bake(case, &settings(scaled), &lighting, (false, false))?;
                if default_spacing.is_none() {
                    // The first bake learns the case's default spacing; rebake it scaled.
                    let s = baked.asset.header.grid.spacing;
                    default_spacing = Some(s);
                    if scale != 1.0 {
                        baked = super::bake(
                            case,
                            &settings(Some(s * scale)),
                            &lighting,
                            (false, false),
                        )?;
                    }
                }
                let sampled = super::sample(case, &baked, Setting::Default, &refs, &lookup)?;
                let summary = Summary::of(&baked.asset, 0);
                let row = Row {
                    case: case.name.clone(),
                    set: case.set,
                    knob,
                    scale,
                    spacing: sampled.spacing,
                    probes: sampled.probes,
                    runtime_bytes: sampled.runtime_bytes,
                    transport_per_probe: summary.transport_bytes_per_probe,
                    bake_s: baked.bake_s,
                    open_mean: 100.0 * sampled.points.open_mean,
                    leaks: sampled.points.leak_percent(),
                    over_lit: sampled.image.as_ref().map(|i| i.over_lit_percent()),
                };
                eprintln!("{}", progress(&row));
                rows.push(row);
            }
        }
    }
    let md = markdown(&rows, &args);
    args.out.report("frontier", &md)?;
    if let Some(dir) = &args.out.out {
        let family = plot_family(&rows, &args);
        results::write(dir, "frontier.svg", family.as_bytes())?;
        for case in ["sponza", "sponza_sun_2"] {
            if rows.iter().any(|r| r.case == case) {
                let name = format!("frontier_{case}.svg");
                results::write(dir, &name, plot_case(&rows, case).as_bytes())?;
            }
        }
    }
    Ok(())
}

fn progress(r: &Row) -> String {
    format!(
        "{} {} x{}: {:.3} m, {} probes, {:.1} MB, {:.0} B/probe transport, bake {:.2} s; open mean {:.1}%, leaks {:.1}%, over-lit {}",
        r.case,
        r.knob.label(),
        r.scale,
        r.spacing,
        r.probes,
        r.runtime_bytes as f64 / 1e6,
        r.transport_per_probe,
        r.bake_s,
        r.open_mean,
        r.leaks,
        r.over_lit.map_or("-".into(), |o| format!("{o:.1}%"))
    )
}

/// The median (the mean of the two middle values for an even count), 0 for none.
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// One setting's figures over a set of levels.
struct Aggregate {
    knob: Knob,
    scale: f32,
    levels: usize,
    probes: f64,
    runtime_mb: f64,
    transport: f64,
    bake_s: f64,
    median_open: f64,
    worst_open: (f64, String),
    worst_leaks: f64,
    worst_over_lit: f64,
}

/// Per setting (in the order of the arguments), the medians and worsts over the `rows` that
/// `keep` takes.
fn aggregate(rows: &[Row], keep: impl Fn(&Row) -> bool, args: &FrontierArgs) -> Vec<Aggregate> {
    let mut out = Vec::new();
    for knob in args.knobs() {
        for &scale in &args.scales {
            let of: Vec<&Row> = rows
                .iter()
                .filter(|r| r.knob == knob && r.scale == scale && keep(r))
                .collect();
            if of.is_empty() {
                continue;
            }
            let med = |f: fn(&Row) -> f64| median(of.iter().map(|r| f(r)).collect());
            let max = |f: fn(&Row) -> f64| of.iter().map(|r| f(r)).fold(0.0, f64::max);
            let worst = of
                .iter()
                .max_by(|a, b| a.open_mean.total_cmp(&b.open_mean))
                .expect("not empty");
            out.push(Aggregate {
                knob,
                scale,
                levels: of.len(),
                probes: med(|r| r.probes as f64),
                runtime_mb: med(|r| r.runtime_bytes as f64 / 1e6),
                transport: med(|r| r.transport_per_probe),
                bake_s: med(|r| r.bake_s),
                median_open: med(|r| r.open_mean),
                worst_open: (worst.open_mean, worst.case.clone()),
                worst_leaks: max(|r| r.leaks),
                worst_over_lit: max(|r| r.over_lit.unwrap_or(0.0)),
            });
        }
    }
    out
}

/// Whether no other setting is at most as large on `x` and better on the median error.
fn on_front(all: &[Aggregate], a: &Aggregate, x: fn(&Aggregate) -> f64) -> bool {
    !all.iter().any(|b| {
        (x(b) <= x(a) && b.median_open < a.median_open)
            || (x(b) < x(a) && b.median_open <= a.median_open)
    })
}

fn summary_table(md: &mut String, title: &str, rows: &[Aggregate]) {
    let _ = writeln!(md, "\n### {title}\n");
    md.push_str("| rays | cells, far ratio, placement | spacing | levels | probes (median) | runtime MB (median) | transport B/probe (median) | bake s (median) | open mean, median level | open mean, worst level | open leaks, worst level | over-lit pixels, worst level | front: bytes / bake time |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n");
    for a in rows {
        let front = |x: fn(&Aggregate) -> f64| if on_front(rows, a, x) { "yes" } else { "-" };
        let _ = writeln!(
            md,
            "| {} | spacing/{}, {}, {} | x{} | {} | {:.0} | {:.1} | {:.0} | {:.2} | {:.1}% | {:.1}% {} | {:.1}% | {:.1}% | {} / {} |",
            a.knob.rays,
            a.knob.cells,
            a.knob.far,
            a.knob.placement(),
            a.scale,
            a.levels,
            a.probes,
            a.runtime_mb,
            a.transport,
            a.bake_s,
            a.median_open,
            a.worst_open.0,
            a.worst_open.1,
            a.worst_leaks,
            a.worst_over_lit,
            front(|a| a.runtime_mb),
            front(|a| a.bake_s),
        );
    }
}

fn markdown(rows: &[Row], args: &FrontierArgs) -> String {
    // surface.md named by its repository path, not linked: `--out` may be any folder (the
    // reports copied under docs/results/ had links that pointed nowhere).
    let mut md = String::from(
        "Bake seconds and runtime bytes against surface error (`prt-bench frontier`, issue 32 item 3): each case baked at spacings relative to its default (x1) and at several ray counts, on the uniform grid or, labelled sparse, at the grid points surfaces need and coarse levels around them (the bake's default; uniform is `prt bake --uniform`), relit on the CPU (one bounce) and sampled with the runtime's lookup (`default`, the surface terms) at the oracle's surface points and camera pixels. Scores as in `docs/results/surface.md` (`prt-bench surface`): open mean is the mean relative error at points that are not pockets, leaks the open points lit over 1.5x their truth, over-lit the camera view's pixels lit over 1.5x. Runtime MB: every array an engine uploads (probes, sky, visibility, factors, bricks, surfels, BVH, triangles, surface terms). Bake seconds on all of this machine's cores (2 here). A setting is on a front when no other setting is as small on that axis and better on the median level's error.\n\n## Summary\n",
    );
    let sets: [(&str, Keep); 7] = [
        ("The level family (seeds 0-15)", in_family),
        ("Tuning seeds 0-7", |r| r.set == Set::Tuning),
        ("Held-out seeds 8-15", |r| r.set == Set::HeldOut),
        ("Unseen seeds 24-31", |r| r.set == Set::Unseen),
        ("Fresh seeds 32-39", |r| r.set == Set::Fresh),
        (
            "Sponza (double-sided, fixtures/rigs/sponza_sun_31.json)",
            |r| r.case == "sponza",
        ),
        (
            "Sponza under the sun and two lights (fixtures/rigs/sponza_sun_2.json)",
            |r| r.case == "sponza_sun_2",
        ),
    ];
    for (title, keep) in sets {
        let agg = aggregate(rows, keep, args);
        if !agg.is_empty() {
            summary_table(&mut md, title, &agg);
        }
    }
    md.push_str("\n## Per case\n\n| case | set | rays | cells, far ratio, placement | spacing | probes | runtime MB | transport B/probe | bake s | open mean | open leaks | over-lit pixels |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | spacing/{}, {}, {} | {:.3} m (x{}) | {} | {:.1} | {:.0} | {:.2} | {:.2}% | {:.1}% | {} |",
            r.case,
            r.set.label(),
            r.knob.rays,
            r.knob.cells,
            r.knob.far,
            r.knob.placement(),
            r.spacing,
            r.scale,
            r.probes,
            r.runtime_bytes as f64 / 1e6,
            r.transport_per_probe,
            r.bake_s,
            r.open_mean,
            r.leaks,
            r.over_lit.map_or("-".into(), |o| format!("{o:.2}%"))
        );
    }
    md
}

/// Colours of the ray counts' series, in argument order.
const COLORS: [&str; 6] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
];

/// Which rows a summary table takes.
type Keep = fn(&Row) -> bool;

/// A level of the level family (seeds 0-15).
fn in_family(r: &Row) -> bool {
    matches!(r.set, Set::Tuning | Set::HeldOut)
}

/// One plotted setting: runtime MB, bake seconds, error (percent), label and tooltip.
struct Dot {
    mb: f64,
    bake_s: f64,
    error: f64,
    label: String,
    title: String,
}

/// Plotted settings per knob, in the order first seen.
#[derive(Default)]
struct ByKnob(Vec<(Knob, Vec<Dot>)>);

impl ByKnob {
    fn push(&mut self, knob: Knob, dot: Dot) {
        match self.0.iter_mut().find(|(k, _)| *k == knob) {
            Some((_, v)) => v.push(dot),
            None => self.0.push((knob, vec![dot])),
        }
    }

    /// Two panels: `what` against runtime MB, and against bake seconds.
    fn panels(&self, what: &str) -> Vec<Panel> {
        let make = |x_name: &str, x_unit: &'static str, x: fn(&Dot) -> f64| Panel {
            title: format!("{what} against {x_name}"),
            x_name: x_name.to_owned(),
            x_unit,
            y_name: what.to_owned(),
            y_unit: "%",
            series: self
                .0
                .iter()
                .enumerate()
                .map(|(i, (knob, dots))| Series {
                    name: knob.label(),
                    color: COLORS[i % COLORS.len()],
                    points: dots
                        .iter()
                        .map(|d| Point {
                            x: x(d),
                            y: d.error,
                            label: d.label.clone(),
                            title: d.title.clone(),
                        })
                        .collect(),
                })
                .collect(),
        };
        vec![
            make("runtime bytes", " MB", |d| d.mb),
            make("bake time", " s", |d| d.bake_s),
        ]
    }
}

/// The family's plot: per setting, the median level's open mean against the median level's
/// runtime MB and bake seconds.
fn plot_family(rows: &[Row], args: &FrontierArgs) -> String {
    let mut by_knob = ByKnob::default();
    for knob in args.knobs() {
        for &scale in &args.scales {
            let of: Vec<&Row> = rows
                .iter()
                .filter(|r| in_family(r) && r.knob == knob && r.scale == scale)
                .collect();
            if of.is_empty() {
                continue;
            }
            let med = |f: fn(&Row) -> f64| median(of.iter().map(|r| f(r)).collect());
            let (mb, bake_s, error) = (
                med(|r| r.runtime_bytes as f64 / 1e6),
                med(|r| r.bake_s),
                med(|r| r.open_mean),
            );
            let title = format!(
                "{}, spacing x{scale}: {error:.1}% median level, {mb:.1} MB, {bake_s:.2} s",
                knob.label()
            );
            let label = format!("x{scale}");
            by_knob.push(
                knob,
                Dot {
                    mb,
                    bake_s,
                    error,
                    label,
                    title,
                },
            );
        }
    }
    let levels: std::collections::BTreeSet<&str> = rows
        .iter()
        .filter(|r| in_family(r))
        .map(|r| r.case.as_str())
        .collect();
    plot::svg(
        "The level family: surface error against runtime bytes and bake time",
        &format!(
            "median of {} levels per setting; labels: spacing relative to each level's default; settings not marked sparse: the uniform grid",
            levels.len()
        ),
        &by_knob.panels("open-point error, median level"),
    )
}

/// One case's plot: its open mean against its runtime MB and bake seconds.
fn plot_case(rows: &[Row], case: &str) -> String {
    let mut by_knob = ByKnob::default();
    for r in rows.iter().filter(|r| r.case == case) {
        let mb = r.runtime_bytes as f64 / 1e6;
        let title = format!(
            "{}, {:.2} m ({} probes): {:.1}%, {mb:.1} MB, {:.2} s",
            r.knob.label(),
            r.spacing,
            r.probes,
            r.open_mean,
            r.bake_s
        );
        let dot = Dot {
            mb,
            bake_s: r.bake_s,
            error: r.open_mean,
            label: format!("{:.2} m", r.spacing),
            title,
        };
        by_knob.push(r.knob, dot);
    }
    plot::svg(
        &format!("{case}: surface error against runtime bytes and bake time"),
        "labels: probe spacing; settings not marked sparse: the uniform grid",
        &by_knob.panels("open-point error"),
    )
}
