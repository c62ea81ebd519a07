//! `prt-bench accuracy`: irradiance error against an independent renderer's probe SH (Mitsuba 3;
//! the Cornell room's is vendored in `fixtures/cornell/`) over rays per probe, brick cell size,
//! factor precision and encoding, against bake time. Bake speed is what buys accuracy (factors
//! fold rays away, so more rays cost bake time and, as far as they reach more bricks, factors):
//! the report's Pareto front says how little error a given bake time buys, and with
//! `--previous` it is set beside the front of earlier sweeps (their `accuracy.md`, for example
//! from an older build run in the same sitting).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use prt_eval::{compare, ErrorStats};
use prt_format::{Asset, Factors, TransferPrecision};
use prt_runtime::{CpuRelighter, Lighting};

mod previous;
mod svg;

use previous::read_previous;
use svg::plot;

#[derive(clap::Args)]
pub struct AccuracyArgs {
    /// glTF scene to bake.
    pub scene: PathBuf,
    /// Light rig (JSON) every bake is relit with.
    #[arg(long)]
    pub lights: PathBuf,
    /// Reference SH JSON (oracle output: each probe's position and sh).
    #[arg(long)]
    pub reference: PathBuf,
    /// Probe spacing in metres [default: about 4,000 probes over the bounds].
    #[arg(long)]
    pub spacing: Option<f32>,
    /// Probe grid bounds MINX,MINY,MINZ,MAXX,MAXY,MAXZ [default: the scene's].
    #[arg(long, value_parser = prt_cli::options::parse_bounds, allow_hyphen_values = true)]
    pub bounds: Option<[f32; 6]>,
    /// Rays per probe, comma-separated: every brick size and precision is baked with each.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "64,128,256,512,1024,2048,4096"
    )]
    pub rays: Vec<u32>,
    /// Coarse bricks for hits this many brick sizes away and farther (0: none).
    #[arg(long, default_value_t = BakeSettings::default().far_ratio)]
    pub far_ratio: f32,
    /// Bakes per setting; the least time is reported (a bake of a small scene lasts
    /// milliseconds, which a busy machine can double).
    #[arg(long, default_value_t = 3)]
    pub repeats: u32,
    /// Earlier sweeps' accuracy.md files, comma-separated: their Pareto front (each setting's
    /// least bake time over the files) is drawn and tabled beside the new one.
    #[arg(long, value_delimiter = ',')]
    pub previous: Vec<PathBuf>,
    /// Directory for accuracy.md and accuracy.svg (docs/results for the published ones).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
}

/// One setting of the sweep.
struct Row {
    rays: u32,
    merge: &'static str,
    precision: TransferPrecision,
    encoding: &'static str,
    bake_s: f64,
    relight_s: f64,
    probes: usize,
    bytes_per_probe: f64,
    transport_per_probe: f64,
    factors_per_probe: f64,
    error: ErrorStats,
    /// Error after Hanning-window deringing of the relit SH (width 4).
    deringed: ErrorStats,
}

/// A setting's bake time and mean error, as a point of an error-against-time plot.
#[derive(Debug)]
struct Point {
    setting: String,
    merge: String,
    flat: bool,
    bake_ms: f64,
    /// Mean error in percent.
    error: f64,
}

/// Brick cell sizes of the sweep: name, cell size override, cells per probe spacing.
const MERGES: [(&str, Option<f32>, f32); 5] = [
    ("none", Some(0.0), 12.0),
    ("spacing/24", None, 24.0),
    ("spacing/12", None, 12.0),
    ("spacing/8 (default)", None, 8.0),
    ("spacing/6", None, 6.0),
];

/// Runs the sweep and writes `accuracy.md` and `accuracy.svg` to `args.out`.
pub fn run(args: AccuracyArgs) -> Result<()> {
    let lighting = prt_runtime::load_rig(&args.lights)?;
    let text = std::fs::read_to_string(&args.reference)
        .with_context(|| format!("reading {}", args.reference.display()))?;
    let json = serde_json::from_str(&text)
        .with_context(|| format!("{}: not JSON", args.reference.display()))?;
    let reference = prt_runtime::output::read_probe_sh(&json)
        .with_context(|| format!("{}: no probes[i].position/.sh", args.reference.display()))?;
    if args.repeats == 0 {
        bail!("--repeats 0: at least one bake per setting is needed");
    }
    // Read before the sweep: a bad file fails in a second, not after it.
    let previous = read_previous(&args.previous)?;
    let base = BakeSettings {
        spacing: args.spacing,
        bounds: args.bounds,
        far_ratio: args.far_ratio,
        // The probes themselves are measured, at the reference's positions: trace them all.
        sparse: false,
        ..BakeSettings::default()
    };
    let rows = sweep(&args, &lighting, &reference, &base)?;
    let new: Vec<Point> = rows.iter().map(Row::point).collect();
    let timed = match args.repeats {
        1 => "one bake".to_owned(),
        n => format!("the least of {n} bakes"),
    };
    let caption = format!(
        "{}: {} probes, {} of them compared with the reference; bake time of {timed} on {} threads",
        args.scene.display(),
        rows.first().map_or(0, |r| r.probes),
        rows.first().map_or(0, |r| r.error.probes),
        std::thread::available_parallelism().map_or(1, usize::from),
    );
    let mut md = format!("{caption}.\n\n");
    md.push_str(&table(&rows)?);
    md.push_str(&fronts(&new, &previous)?);
    let svg = plot(&new, &previous, &caption);
    println!("{md}");
    crate::results::write(&args.out, "accuracy.md", md.as_bytes())?;
    crate::results::write(&args.out, "accuracy.svg", svg.as_bytes())
}

/// Bakes every setting (`args.repeats` times, keeping the least time), relights it on the CPU
/// and compares it with `reference`; a line on stderr per setting shows the progress.
fn sweep(
    args: &AccuracyArgs,
    lighting: &Lighting,
    reference: &[([f32; 3], prt_format::sh::ShRgb)],
    base: &BakeSettings,
) -> Result<Vec<Row>> {
    const PRECISIONS: [TransferPrecision; 3] = [
        TransferPrecision::F32,
        TransferPrecision::F16,
        TransferPrecision::U8,
    ];
    let total = args.rays.len() * MERGES.len() * PRECISIONS.len();
    let mut rows = Vec::new();
    let mut step = 0;
    for &n in &args.rays {
        for (merge, cell_size, cells) in MERGES {
            for precision in PRECISIONS {
                let settings = BakeSettings {
                    rays: n,
                    cell_size,
                    cells_per_spacing: cells,
                    transfer_precision: precision,
                    ..base.clone()
                };
                let measured = measure(args, lighting, reference, &settings, merge)?;
                step += 1;
                eprintln!(
                    "accuracy [{step}/{total}] {n} rays, cells {merge}, {precision:?}: bake {:.1} ms, mean error {:.2}%",
                    measured[0].bake_s * 1e3,
                    100.0 * measured[0].error.mean
                );
                rows.extend(measured);
            }
        }
    }
    Ok(rows)
}

/// The rows of one setting (named `merge` for its cell size): its bake, and the flat-brick
/// variant of merged f16 bakes.
fn measure(
    args: &AccuracyArgs,
    lighting: &Lighting,
    reference: &[([f32; 3], prt_format::sh::ShRgb)],
    settings: &BakeSettings,
    merge: &'static str,
) -> Result<Vec<Row>> {
    let (n, precision) = (settings.rays, settings.transfer_precision);
    let mut bake_s = f64::MAX;
    let mut baked = None;
    for _ in 0..args.repeats {
        let t = Instant::now();
        let (asset, _) = prt_bake::bake(&args.scene, settings, &NoProgress)
            .with_context(|| format!("bake with {n} rays, cells {merge}"))?;
        let bytes = prt_format::encode(&asset)?.len();
        bake_s = bake_s.min(t.elapsed().as_secs_f64());
        baked = Some((asset, bytes));
    }
    let (asset, bytes) = baked.context("--repeats 0: no bake")?;
    let summary = prt_format::Summary::of(&asset, bytes as u64);
    let mut encodings = vec![("sh9 + gradient", asset.clone())];
    let merged = settings.cell_size != Some(0.0);
    if merged && precision == TransferPrecision::F16 {
        encodings.push(("sh9, flat brick", without_offsets(asset)));
    }
    let mut rows = Vec::new();
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
        rows.push(Row {
            rays: n,
            merge,
            precision,
            encoding,
            bake_s,
            relight_s,
            probes: asset.probes.len(),
            bytes_per_probe: summary.bytes_per_probe,
            transport_per_probe: summary.transport_bytes_per_probe,
            factors_per_probe: summary.factor_count as f64 / asset.probes.len() as f64,
            error: compare(&ours, reference, 1e-3),
            deringed: compare(&windowed(&ours), reference, 1e-3),
        });
    }
    Ok(rows)
}

impl Row {
    fn point(&self) -> Point {
        Point {
            setting: setting(
                &self.rays.to_string(),
                self.merge,
                &format!("{:?}", self.precision),
                self.encoding,
            ),
            merge: self.merge.to_owned(),
            flat: self.encoding.ends_with("flat brick"),
            bake_ms: self.bake_s * 1e3,
            // As the table prints it, so that the new front and an earlier one (read from its
            // table) are compared at one precision.
            error: (1e4 * self.error.mean).round() / 100.0,
        }
    }
}

fn setting(rays: &str, merge: &str, precision: &str, encoding: &str) -> String {
    format!("{rays} rays, cells {merge}, {precision}, {encoding}")
}

/// The sweep's table, one row per setting.
fn table(rows: &[Row]) -> Result<String> {
    let mut md = String::from("| rays | brick cells | transfer | encoding | bake ms | CPU relight ms | file bytes/probe | transport bytes/probe | factors/probe | mean err | p95 err | max err | max coeff / SH0 | mean err deringed |\n|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        writeln!(
            md,
            "| {} | {} | {:?} | {} | {:.1} | {:.2} | {:.0} | {:.0} | {:.1} | {:.2}% | {:.2}% | {:.2}% | {:.1e} | {:.2}% |",
            r.rays, r.merge, r.precision, r.encoding, r.bake_s * 1e3, r.relight_s * 1e3,
            r.bytes_per_probe, r.transport_per_probe, r.factors_per_probe, 100.0 * r.error.mean, 100.0 * r.error.p95,
            100.0 * r.error.max, r.error.max_coeff_rel, 100.0 * r.deringed.mean
        )?;
    }
    Ok(md)
}

/// The Pareto front of `points`: those with less error than every point baked as fast or
/// faster, by increasing bake time.
fn front(points: &[Point]) -> Vec<&Point> {
    crate::plot::front_by(points, |p| p.bake_ms, |p| p.error)
}

/// The least error of `front` within `ms` of bake time, if any point is that fast.
fn best_within<'a>(front: &[&'a Point], ms: f64) -> Option<&'a Point> {
    front.iter().rev().find(|p| p.bake_ms <= ms).copied()
}

/// The new front, and with earlier sweeps the error each buys at the previous front's times.
fn fronts(new: &[Point], previous: &[Point]) -> Result<String> {
    let new_front = front(new);
    let mut md = String::from(
        "\n### Pareto front: least error for a bake time\n\n| setting | bake ms | mean err |\n|---|---:|---:|\n",
    );
    for p in &new_front {
        writeln!(md, "| {} | {:.1} | {:.2}% |", p.setting, p.bake_ms, p.error)?;
    }
    if previous.is_empty() {
        return Ok(md);
    }
    md.push_str("\n### Against the previous front: the error the same bake time buys now\n\n| previous front | bake ms | mean err | now, within that time | bake ms | mean err |\n|---|---:|---:|---|---:|---:|\n");
    for p in front(previous) {
        let now = best_within(&new_front, p.bake_ms).map_or_else(
            || "none as fast | | ".to_owned(),
            |q| format!("{} | {:.1} | {:.2}%", q.setting, q.bake_ms, q.error),
        );
        writeln!(
            md,
            "| {} | {:.1} | {:.2}% | {now} |",
            p.setting, p.bake_ms, p.error
        )?;
    }
    Ok(md)
}

/// Probe SH with Hanning-window deringing applied (`prt_format::sh::hanning_window`, width 4).
fn windowed(
    ours: &[([f32; 3], bool, prt_format::sh::ShRgb)],
) -> Vec<([f32; 3], bool, prt_format::sh::ShRgb)> {
    ours.iter()
        .map(|(p, v, c)| (*p, *v, prt_format::sh::hanning_window(c, 4.0)))
        .collect()
}

/// The same f32 or f16 asset with every factor's offset zeroed: each brick seen as its mean
/// radiance (a u8 table is left as it is: its lobe factors' directions need their offsets).
fn without_offsets(mut asset: Asset) -> Asset {
    match &mut asset.factors {
        Factors::F32(f) => f.iter_mut().for_each(|f| f.offset = [0.0; 3]),
        Factors::F16(f) => f.iter_mut().for_each(|f| f.offset = [0; 2]),
        Factors::U8 { .. } => {}
    }
    asset
}

#[cfg(test)]
mod tests {
    use super::previous::parse_table;
    use super::*;
    use std::path::Path;

    fn point(ms: f64, error: f64) -> Point {
        Point {
            setting: format!("{ms} {error}"),
            merge: String::new(),
            flat: false,
            bake_ms: ms,
            error,
        }
    }

    #[test]
    fn front_keeps_points_no_faster_point_beats() {
        let points = [
            point(3.0, 5.0),
            point(1.0, 9.0),
            point(2.0, 10.0),
            point(4.0, 1.0),
        ];
        let f: Vec<(f64, f64)> = front(&points)
            .iter()
            .map(|p| (p.bake_ms, p.error))
            .collect();
        assert_eq!(f, [(1.0, 9.0), (3.0, 5.0), (4.0, 1.0)]);
        assert_eq!(best_within(&front(&points), 3.5).unwrap().error, 5.0);
        assert!(best_within(&front(&points), 0.5).is_none());
    }

    #[test]
    fn previous_tables_parse_and_bad_cells_are_named() {
        let md = "| rays | brick cells | transfer | encoding | bake ms | mean err |\n|---:|---|---|---|---:|---:|\n| 64 | none | F32 | sh9 + gradient | 2.9 | 27.70% |\n| 512 | spacing/6 | F16 | sh9, flat brick | 1.4 | 15.89% |\n\nafter the table\n";
        let points = parse_table(md, Path::new("a.md")).unwrap();
        assert_eq!(points.len(), 2);
        assert_eq!(
            points[0].setting,
            "64 rays, cells none, F32, sh9 + gradient"
        );
        assert_eq!((points[1].bake_ms, points[1].error), (1.4, 15.89));
        assert!(points[1].flat);
        let bad = md.replace("2.9", "fast");
        let e = parse_table(&bad, Path::new("a.md"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("a.md line 3") && e.contains("'bake ms'") && e.contains("'fast'"),
            "{e}"
        );
        let e = parse_table("| rays |\n|---|\n| 1 |\n", Path::new("b.md")).unwrap_err();
        assert!(
            e.to_string()
                .contains("b.md line 1: no column 'brick cells'"),
            "{e}"
        );
        let no_separator: String = md
            .lines()
            .filter(|l| !l.starts_with("|---"))
            .collect::<Vec<_>>()
            .join("\n");
        let e = parse_table(&no_separator, Path::new("c.md"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.md line 2") && e.contains("separator"), "{e}");
        let e = parse_table(&md.replace("| 512 |", "| 5l2 |"), Path::new("d.md"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("d.md line 4: column 'rays' is '5l2', not a ray count"),
            "{e}"
        );
    }
}
