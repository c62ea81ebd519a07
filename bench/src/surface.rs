//! `prt-bench surface` (issue 11): irradiance where a renderer shows it, at surface points,
//! against the independent oracle's surface references (`fixtures/surface/*_surface.json`, made by
//! `scripts/surface_refs.sh` with the Mitsuba 3 oracle's `surface_oracle.py`, which is not part of
//! this repository: the references are its output, committed as data).
//!
//! Probe SH are accurate at probe centres; surfaces sample the volume between probes, often with a
//! wall between the point and some of its eight probes. Each case is baked as a new user would
//! (whole scene, default spacing) and at half that spacing, relit on the CPU, and sampled with the
//! CPU twin of the engine's `sample_irradiance` (normal offset included) at the reference points.
//!
//! Scores follow the oracle's `score_surface.py` so that both give the same numbers:
//! - per point, relative error `mean_rgb |E - E_ref| / max(mean_rgb E_ref, 1e-3 median)`, where
//!   `median` is the median over points of the reference's mean-RGB hemispherical irradiance, and
//!   a sample with validity 0 counts as `E = 0` (the shader returns nothing there);
//! - against `sh` (`E_ref` = irradiance of the reference SH at the point, clamped at 0: isolates
//!   interpolation, validity and leaks) and against `e_hemi` (exact irradiance: adds the L2
//!   truncation); mean and p95 (linear interpolation between order statistics, as numpy);
//! - leaks: `E > 1.5 E_hemi` and `E - E_hemi > 0.05 median` (mean RGB);
//! - black (ours): `E < 0.01 mean` while `E_hemi > 0.05 mean`, `mean` being the scene's mean
//!   reference irradiance: a hole or a wall's shadow where the truth is clearly lit;
//! - holes (ours): samples whose eight probes are all invalid (validity 0).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use prt_format::sh::ShRgb;
use prt_runtime::{Lighting, LookupSettings, Sample};
use serde_json::Value;

use crate::results::Out;

#[derive(clap::Args)]
pub struct SurfaceArgs {
    /// Cases to run (comma-separated): cornell, two_rooms, thick_walls, sponza [default: all;
    /// sponza is skipped with a note when its scene or reference is missing].
    #[arg(long = "case", value_delimiter = ',')]
    cases: Vec<String>,
    /// Directory the bundled paths are relative to (the repository root).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Normal offset of the lookup in probe spacings [default: the runtime's, 0.2].
    #[arg(long)]
    normal_bias: Option<f32>,
    #[command(flatten)]
    out: Out,
}

/// A bundled case: paths relative to the repository root.
struct Case {
    name: &'static str,
    scene: &'static str,
    rig: &'static str,
    reference: &'static str,
    double_sided: bool,
}

const CASES: [Case; 4] = [
    Case {
        name: "cornell",
        scene: "fixtures/cornell/cornell.gltf",
        rig: "fixtures/cornell/rig.json",
        reference: "fixtures/surface/cornell_surface.json",
        double_sided: false,
    },
    Case {
        name: "two_rooms",
        scene: "fixtures/two_rooms.gltf",
        rig: "fixtures/rigs/two_rooms.json",
        reference: "fixtures/surface/two_rooms_surface.json",
        double_sided: false,
    },
    Case {
        name: "thick_walls",
        scene: "fixtures/thick_walls.gltf",
        rig: "fixtures/rigs/thick_walls.json",
        reference: "fixtures/surface/thick_walls_surface.json",
        double_sided: false,
    },
    Case {
        name: "sponza",
        scene: "fixtures/scenes/sponza_lod4.glb",
        rig: "fixtures/rigs/sponza_sun_31.json",
        reference: "fixtures/surface/sponza_surface.json",
        double_sided: true,
    },
];

/// One reference point: what the oracle measured there.
struct RefPoint {
    position: [f32; 3],
    normal: [f32; 3],
    /// Irradiance of the reference SH at the point (clamped at 0).
    e_sh: [f64; 3],
    /// Exact hemispherical irradiance.
    e_hemi: [f64; 3],
}

struct Reference {
    points: Vec<RefPoint>,
    /// The oracle's own time for the whole reference, when recorded.
    oracle_seconds: Option<f64>,
}

/// Scores of one bake against one reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Score {
    pub sh_mean: f64,
    pub sh_p95: f64,
    pub hemi_mean: f64,
    pub hemi_p95: f64,
    pub leaks: usize,
    pub black: usize,
    pub holes: usize,
    pub points: usize,
}

/// One table row: a case at one spacing.
struct Row {
    name: &'static str,
    /// "trilinear" or "visibility" (the runtime's default lookup).
    lookup: &'static str,
    spacing: f32,
    probes: usize,
    valid: usize,
    dilated: usize,
    score: Score,
    bake_s: f64,
    relight_s: f64,
    sample_s: f64,
}

/// `prt-bench surface`: every picked case at its default spacing and half of it, the report
/// printed and with `--out` written to `surface.md`.
pub fn run(args: SurfaceArgs) -> Result<()> {
    let bias = prt_cli::options::normal_bias(args.normal_bias)?;
    let picked = pick_cases(&args.cases)?;
    let mut rows = Vec::new();
    let mut oracle = Vec::new();
    for case in picked {
        let scene = args.root.join(case.scene);
        let reference_path = args.root.join(case.reference);
        let reference = read_reference(&reference_path)?;
        let lighting = prt_runtime::load_rig(&args.root.join(case.rig))
            .with_context(|| format!("loading the rig of case {}", case.name))?;
        eprintln!("{}: {} reference points", case.name, reference.points.len());
        oracle.push((case.name, reference.oracle_seconds));
        let base = BakeSettings {
            double_sided: case.double_sided,
            ..BakeSettings::default()
        };
        let default_rows = measure(case, &scene, &base, &lighting, &reference, bias)?;
        let half = BakeSettings {
            spacing: Some(default_rows[0].spacing / 2.0),
            ..base
        };
        rows.extend(default_rows);
        rows.extend(measure(case, &scene, &half, &lighting, &reference, bias)?);
    }
    args.out.report("surface", &markdown(&rows, &oracle, bias)?)
}

/// The cases named on the command line, in table order (all without names).
fn pick_cases(names: &[String]) -> Result<Vec<&'static Case>> {
    for n in names {
        if !CASES.iter().any(|c| c.name == n) {
            let known: Vec<&str> = CASES.iter().map(|c| c.name).collect();
            bail!("--case {n}: unknown case (known: {})", known.join(", "));
        }
    }
    Ok(CASES
        .iter()
        .filter(|c| names.is_empty() || names.iter().any(|n| n == c.name))
        .collect())
}

/// Bakes and relights one case at one setting, then samples it with the plain trilinear lookup
/// and with the visibility-aware one (a row each).
fn measure(
    case: &Case,
    scene: &Path,
    settings: &BakeSettings,
    lighting: &Lighting,
    reference: &Reference,
    bias: f32,
) -> Result<Vec<Row>> {
    let t = Instant::now();
    let (asset, _) = prt_bake::bake(scene, settings, &NoProgress)
        .with_context(|| format!("baking {}", scene.display()))?;
    let bake_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let sh = prt_runtime::CpuRelighter::new(&asset)?
        .relight(lighting, 1)
        .with_context(|| format!("relighting {}", case.name))?
        .sh;
    let relight_s = t.elapsed().as_secs_f64();
    let spacing = asset.header.grid.spacing;
    let mut rows = Vec::new();
    for (lookup, depth_moments) in [("trilinear", false), ("visibility", true)] {
        let settings = LookupSettings {
            normal_bias: bias,
            depth_moments,
        };
        let t = Instant::now();
        let sampler = prt_runtime::VolumeSampler::for_asset(&asset, &sh, &settings);
        let samples: Vec<Sample> = reference
            .points
            .iter()
            .map(|p| sampler.sample(p.position, p.normal))
            .collect();
        let sample_s = t.elapsed().as_secs_f64();
        let counts = prt_format::Summary::of(&asset, 0);
        let row = Row {
            name: case.name,
            lookup,
            spacing,
            probes: asset.probes.len(),
            valid: counts.valid_probe_count,
            dilated: counts.dilated_probe_count,
            score: score(&reference.points, &samples),
            bake_s,
            relight_s,
            sample_s,
        };
        // Same line and digits as score_surface.py, to compare the two scorers.
        let s = &row.score;
        eprintln!(
            "  spacing {spacing} m, {lookup}, {} probes ({} valid): surface_err sh_mean={:.5} \
             sh_p95={:.5} hemi_mean={:.5} hemi_p95={:.5} points={} leaks={}",
            row.probes, row.valid, s.sh_mean, s.sh_p95, s.hemi_mean, s.hemi_p95, s.points, s.leaks
        );
        rows.push(row);
    }
    Ok(rows)
}

/// Scores samples against the reference (module docs for the definitions).
pub fn score_irradiance(reference: &[([f64; 3], [f64; 3])], candidate: &[[f64; 3]]) -> Score {
    let mean = |c: &[f64; 3]| (c[0] + c[1] + c[2]) / 3.0;
    let hemi: Vec<f64> = reference.iter().map(|(_, h)| mean(h)).collect();
    let median = percentile(&hemi, 0.5);
    let scene_mean = hemi.iter().sum::<f64>() / hemi.len().max(1) as f64;
    let floor = 1e-3 * median;
    let rel = |e: &[f64; 3], r: &[f64; 3]| {
        let diff = (0..3).map(|c| (e[c] - r[c]).abs()).sum::<f64>() / 3.0;
        diff / mean(r).max(floor)
    };
    let r_sh: Vec<f64> = candidate
        .iter()
        .zip(reference)
        .map(|(e, (s, _))| rel(e, s))
        .collect();
    let r_hemi: Vec<f64> = candidate
        .iter()
        .zip(reference)
        .map(|(e, (_, h))| rel(e, h))
        .collect();
    let pairs = || candidate.iter().map(mean).zip(hemi.iter().copied());
    let n = r_sh.len().max(1) as f64;
    Score {
        sh_mean: r_sh.iter().sum::<f64>() / n,
        sh_p95: percentile(&r_sh, 0.95),
        hemi_mean: r_hemi.iter().sum::<f64>() / n,
        hemi_p95: percentile(&r_hemi, 0.95),
        leaks: pairs()
            .filter(|&(e, h)| e > 1.5 * h && e - h > 0.05 * median)
            .count(),
        black: pairs()
            .filter(|&(e, h)| e < 0.01 * scene_mean && h > 0.05 * scene_mean)
            .count(),
        holes: 0,
        points: candidate.len(),
    }
}

/// Scores the CPU twin's samples: validity 0 counts as black (`E = 0`), as in the shader.
fn score(points: &[RefPoint], samples: &[Sample]) -> Score {
    let reference: Vec<([f64; 3], [f64; 3])> = points.iter().map(|p| (p.e_sh, p.e_hemi)).collect();
    let candidate: Vec<[f64; 3]> = samples
        .iter()
        .map(|s| {
            if s.validity > 0.0 {
                s.irradiance.map(f64::from)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    Score {
        holes: samples.iter().filter(|s| s.validity <= 0.0).count(),
        ..score_irradiance(&reference, &candidate)
    }
}

/// The `q` quantile with linear interpolation between order statistics (numpy's default).
fn percentile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n => {
            let h = (n - 1) as f64 * q;
            let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
            v[lo] + (h - lo as f64) * (v[hi] - v[lo])
        }
    }
}

/// Reads `surface_oracle.py` output; every error names the file and the point at fault.
fn read_reference(path: &Path) -> Result<Reference> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let doc: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    let Some(list) = doc.get("points").and_then(Value::as_array) else {
        bail!("{}: no \"points\" array", path.display());
    };
    let points = list
        .iter()
        .enumerate()
        .map(|(i, p)| ref_point(p).with_context(|| format!("{}: point {i}", path.display())))
        .collect::<Result<Vec<_>>>()?;
    if points.is_empty() {
        bail!("{}: no points", path.display());
    }
    Ok(Reference {
        points,
        oracle_seconds: doc.get("seconds").and_then(Value::as_f64),
    })
}

fn ref_point(p: &Value) -> Result<RefPoint> {
    let vec3 = |key: &str| -> Result<[f64; 3]> {
        let v: Vec<f64> = p
            .get(key)
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default();
        v.try_into()
            .map_err(|_| anyhow::anyhow!("\"{key}\" is not 3 numbers"))
    };
    let sh_rows = p
        .get("sh")
        .and_then(Value::as_array)
        .filter(|a| a.len() == 9)
        .context("\"sh\" is not 9 [r,g,b] rows")?;
    let mut sh: ShRgb = [[0.0; 3]; 9];
    for (k, row) in sh_rows.iter().enumerate() {
        let v: Vec<f64> = row
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default();
        let v: [f64; 3] = v
            .try_into()
            .map_err(|_| anyhow::anyhow!("\"sh\"[{k}] is not 3 numbers"))?;
        sh[k] = v.map(|c| c as f32);
    }
    let position = vec3("position")?.map(|c| c as f32);
    let normal = vec3("normal")?.map(|c| c as f32);
    Ok(RefPoint {
        position,
        normal,
        e_sh: prt_format::sh::irradiance(&sh, normal).map(f64::from),
        e_hemi: vec3("e_hemi")?,
    })
}

/// The report: the accuracy table, then timings.
fn markdown(rows: &[Row], oracle: &[(&str, Option<f64>)], bias: f32) -> Result<String> {
    let mut md = String::new();
    writeln!(
        md,
        "Surface irradiance against the oracle's surface references (`fixtures/surface/`), CPU \
         relight (one bounce) and the CPU twin of `sample_irradiance`, normal bias {bias} \
         spacings. Errors are relative to the reference irradiance per point (floor 1e-3 of the \
         median); \"sh\" = against the reference SH's irradiance, \"hemi\" = against the exact \
         hemispherical irradiance. Leaks: lit > 1.5x the truth and by more than 5% of the median. \
         Black: below 1% of the scene's mean reference irradiance where the truth is above 5% of \
         it. Holes: no valid probe among the eight.\n"
    )?;
    writeln!(
        md,
        "| scene | spacing | probes (valid, dilated) | lookup | mean err (sh) | p95 (sh) | mean err (hemi) | p95 (hemi) | leaks | black | holes |"
    )?;
    writeln!(md, "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")?;
    for r in rows {
        let s = &r.score;
        writeln!(
            md,
            "| {} | {:.3} m | {} ({}, {}) | {} | {:.2}% | {:.1}% | {:.2}% | {:.1}% | {} of {} | {} | {} |",
            r.name,
            r.spacing,
            r.probes,
            r.valid,
            r.dilated,
            r.lookup,
            100.0 * s.sh_mean,
            100.0 * s.sh_p95,
            100.0 * s.hemi_mean,
            100.0 * s.hemi_p95,
            s.leaks,
            s.points,
            s.black,
            s.holes
        )?;
    }
    writeln!(
        md,
        "\n| scene | spacing | lookup | bake s | CPU relight s | sampling ms |\n|---|---:|---|---:|---:|---:|"
    )?;
    for r in rows {
        writeln!(
            md,
            "| {} | {:.3} m | {} | {:.2} | {:.3} | {:.2} |",
            r.name,
            r.spacing,
            r.lookup,
            r.bake_s,
            r.relight_s,
            1e3 * r.sample_s
        )?;
    }
    let timed: Vec<String> = oracle
        .iter()
        .filter_map(|(n, s)| s.map(|s| format!("{n} {s:.1} s")))
        .collect();
    if !timed.is_empty() {
        writeln!(
            md,
            "\nOracle time per reference (300 points, 65,536 directions): {}.",
            timed.join(", ")
        )?;
    }
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_matches_numpy_linear() {
        let v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(percentile(&v, 0.5), 2.5);
        assert!((percentile(&v, 0.95) - 3.85).abs() < 1e-12);
        assert_eq!(percentile(&[7.0], 0.95), 7.0);
    }

    #[test]
    fn leaks_and_black_follow_their_thresholds() {
        let reference = [
            ([1.0; 3], [1.0; 3]),
            ([1.0; 3], [1.0; 3]),
            ([0.0; 3], [0.0; 3]),
        ];
        // Exact, black where the truth is lit, and a leak into the dark point.
        let s = score_irradiance(&reference, &[[1.0; 3], [0.0; 3], [0.5; 3]]);
        assert_eq!((s.leaks, s.black, s.points), (1, 1, 3));
        assert!((s.sh_mean - (0.0 + 1.0 + 0.5 / 1e-3) / 3.0).abs() < 1e-9);
    }
}
