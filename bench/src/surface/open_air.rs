//! `prt-bench open-air` (issue 32, item 2): what the coarse levels of sparse placement costs
//! away from surfaces. Each case is baked uniform and sparse at the same spacing and relit on
//! the CPU with its rig; at every grid point the sparse bake fills from a coarse level
//! (`prt_format::tier`), the filled SH is compared with the uniform bake's own probe there,
//! traced with the same ray lattice. That probe is the best the fine grid knows (the 2048-ray
//! default sits near the Monte Carlo floor at probe centres, docs/results/coarse.md), so the
//! difference is the error a point in open air (a dynamic object, a particle) gets from the
//! coarse levels instead of the fine grid.
//!
//! Per point: the irradiance of both SH on the six axis-aligned normals, mean RGB; its
//! relative error is `sum |E_sparse - E_uniform| / max(sum E_uniform, 1e-3 median)` over the
//! normals (relative to the point's own light, so that a normal facing away from a point's only
//! light, E near 0, does not make a tiny difference infinite; `median`: the median over the
//! case's points of that sum). Mean and p95 over the filled points whose uniform probe is valid
//! and not dilated.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use prt_bake::BakeSettings;
use prt_format::sh::ShRgb;
use prt_format::Summary;

use super::cases::{self, Case};
use super::score::percentile;
use crate::results::Out;

#[derive(clap::Args)]
pub struct OpenAirArgs {
    /// Cases (comma-separated), as for `prt-bench surface` [default: bundled,family].
    #[arg(long = "case", value_delimiter = ',')]
    cases: Vec<String>,
    /// Directory the cases' paths are relative to (the repository root).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Bake at this spacing in metres [default: the bake's default for each case].
    #[arg(long)]
    spacing: Option<f32>,
    #[command(flatten)]
    out: Out,
}

/// One case's row.
struct Row {
    case: String,
    set: &'static str,
    spacing: f32,
    grid: usize,
    with_data: [usize; 2],
    runtime_mb: [f64; 2],
    bake_s: [f64; 2],
    filled: usize,
    compared: usize,
    mean: f64,
    p95: f64,
}

/// `prt-bench open-air`: a row per case, the report printed and with `--out` written to
/// `open_air.md`.
pub fn run(args: OpenAirArgs) -> Result<()> {
    let picked = cases::pick(&args.cases, cases::all(&args.root)?)?;
    let mut rows = Vec::new();
    for case in &picked {
        let row = measure(case, args.spacing)?;
        eprintln!(
            "{}: {} filled, error mean {:.2}% p95 {:.2}%; probes with data {} -> {}",
            row.case,
            row.filled,
            100.0 * row.mean,
            100.0 * row.p95,
            row.with_data[0],
            row.with_data[1]
        );
        rows.push(row);
    }
    args.out.report("open_air", &markdown(&rows))
}

fn measure(case: &Case, spacing: Option<f32>) -> Result<Row> {
    let lighting = prt_runtime::load_rig(&case.rig)
        .with_context(|| format!("{}: loading the rig {}", case.name, case.rig.display()))?;
    let settings = |sparse| BakeSettings {
        double_sided: case.double_sided,
        spacing,
        sparse,
        ..BakeSettings::default()
    };
    let uniform = super::bake(case, &settings(false), &lighting, (false, false))?;
    let sparse = super::bake(case, &settings(true), &lighting, (false, false))?;
    let (u, s) = (&uniform.asset, &sparse.asset);
    let points: Vec<usize> = (0..s.probes.len())
        .filter(|&p| s.probes[p].is_filled())
        .filter(|&p| u.probes[p].is_valid() && !u.probes[p].is_dilated())
        .collect();
    let errors = relative_errors(&points, &uniform.sh, &sparse.sh);
    let summary = |a| Summary::of(a, 0);
    let (su, ss) = (summary(u), summary(s));
    let mb = |s: &Summary| super::runtime_bytes(s) as f64 / 1e6;
    Ok(Row {
        case: case.name.clone(),
        set: case.set.label(),
        spacing: u.header.grid.spacing,
        grid: u.probes.len(),
        with_data: [su.probes_with_data, ss.probes_with_data],
        runtime_mb: [mb(&su), mb(&ss)],
        bake_s: [uniform.bake_s, sparse.bake_s],
        filled: ss.filled_probe_count,
        compared: points.len(),
        mean: errors.iter().sum::<f64>() / errors.len().max(1) as f64,
        p95: percentile(&errors, 0.95),
    })
}

/// Per point of `points`: the relative irradiance error of `got` against `truth` over the six
/// axis normals (module docs).
fn relative_errors(points: &[usize], truth: &[ShRgb], got: &[ShRgb]) -> Vec<f64> {
    const NORMALS: [[f32; 3]; 6] = prt_format::sh::AXIS_NORMALS;
    let e = |sh: &ShRgb, n| {
        let v = prt_format::sh::irradiance(sh, n);
        f64::from(v[0] + v[1] + v[2]) / 3.0
    };
    let pairs: Vec<[(f64, f64); 6]> = points
        .iter()
        .map(|&p| NORMALS.map(|n| (e(&truth[p], n), e(&got[p], n))))
        .collect();
    let light: Vec<f64> = pairs
        .iter()
        .map(|ps| ps.iter().map(|p| p.0).sum())
        .collect();
    let floor = (1e-3 * percentile(&light, 0.5)).max(f64::MIN_POSITIVE);
    pairs
        .iter()
        .zip(&light)
        .map(|(ps, &l)| ps.iter().map(|&(t, g)| (g - t).abs()).sum::<f64>() / l.max(floor))
        .collect()
}

fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "# Open air: the coarse levels against the fine grid (`prt-bench open-air`)\n\n\
         Each case baked `--uniform` and sparse (the default) at its default spacing, relit on the CPU with \
         its rig; at each grid point the sparse bake fills from a coarse level, the filled SH \
         against the uniform bake's probe there: the relative irradiance error summed over the \
         six axis normals, mean and p95 over those points (`bench/src/surface/open_air.rs`).\n\n\
         | case | set | spacing m | grid points | probes with data, uniform / sparse | runtime MB, uniform / sparse | bake s, uniform / sparse | filled | compared | error mean | p95 |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {:.3} | {} | {} / {} | {:.1} / {:.1} | {:.2} / {:.2} | {} | {} | {:.2}% | {:.2}% |",
            r.case,
            r.set,
            r.spacing,
            r.grid,
            r.with_data[0],
            r.with_data[1],
            r.runtime_mb[0],
            r.runtime_mb[1],
            r.bake_s[0],
            r.bake_s[1],
            r.filled,
            r.compared,
            100.0 * r.mean,
            100.0 * r.p95
        );
    }
    let means: Vec<f64> = rows.iter().map(|r| r.mean).collect();
    if !means.is_empty() {
        let median = percentile(&means, 0.5);
        let worst = rows.iter().map(|r| r.mean).fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "\nMedian case {:.2}%, worst case {:.2}% (mean error at the filled points).",
            100.0 * median,
            100.0 * worst
        );
    }
    s
}
