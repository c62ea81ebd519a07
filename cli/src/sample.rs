//! `prt sample` (docs/conventions.md section 6): relights an asset once and returns, at given surface
//! points, what the engine-side `sample_irradiance` returns there (SH, irradiance, validity), on
//! the CPU twin (`SurfaceSampler`) or the real snippet on the GPU (`sample_points`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use prt_runtime::gpu::{PrtRuntime, RuntimeSettings};
use prt_runtime::surface::{Explanation, SurfaceSampler};
use prt_runtime::{LookupSettings, Sample};
use serde_json::{json, Value};

use prt_cli::options::normal_bias;

use crate::common::{ensure_not_input, lighting_of, Backend};

#[derive(clap::Args)]
pub struct SampleArgs {
    asset: PathBuf,
    /// Light rig JSON.
    #[arg(long)]
    lights: PathBuf,
    /// `{"points": [{"position": [x,y,z], "normal": [x,y,z]}, ...]}` (normals are normalised).
    #[arg(long)]
    points: PathBuf,
    /// Output JSON, written atomically: `{"samples": [...]}` in input order.
    #[arg(long)]
    json: PathBuf,
    #[arg(long, value_enum, default_value = "cpu")]
    backend: Backend,
    /// Move each point this many probe spacings along its normal before sampling the probe
    /// volume [default: the runtime's, 0.2]; a point with a surfel's terms weighs its probes at
    /// the surface lookup's bias instead (`LookupSettings::surface_bias`, 0.1: the bake's), but
    /// for its fallback where its surfel sees none of them.
    #[arg(long, allow_hyphen_values = true)]
    normal_bias: Option<f32>,
    /// Plain trilinear interpolation: no Chebyshev test against the probes' depth moments.
    #[arg(long, alias = "no-visibility")]
    no_depth_moments: bool,
    /// The probe volume alone: without the asset's surface terms (which probes each surfel
    /// sees, its near field).
    #[arg(long)]
    no_surface_terms: bool,
    /// The sky as the probes see it, not as each surface sees it (without the asset's sky
    /// terms).
    #[arg(long)]
    no_sky_terms: bool,
    /// Add to each sample how the lookup read it (CPU backend): the surfel whose terms stood for
    /// the point, the probes it weighted (which the surfel sees, their own irradiance), the
    /// near field's share of the probes' light, the sky term. Where to start on a leak.
    #[arg(long)]
    explain: bool,
}

/// A surface point: position and unit normal.
type Point = ([f32; 3], [f32; 3]);

pub fn run(args: SampleArgs) -> Result<()> {
    let normal_bias = normal_bias(args.normal_bias)?;
    let settings = RuntimeSettings {
        lookup: LookupSettings {
            normal_bias,
            depth_moments: !args.no_depth_moments,
            surface_terms: !args.no_surface_terms,
            sky_terms: !args.no_sky_terms,
            ..LookupSettings::default()
        },
        ..RuntimeSettings::default()
    };
    if args.explain && matches!(args.backend, Backend::Gpu) {
        bail!("--explain reads the CPU twin of the lookup: use it with --backend cpu");
    }
    ensure_not_input(&args.json, &[&args.asset, &args.lights, &args.points])?;
    let points = read_points(&args.points)?;
    let asset = prt_format::read_asset(&args.asset)
        .with_context(|| format!("loading {}", args.asset.display()))?;
    let lighting = lighting_of(Some(&args.lights), &asset)?;
    let start = std::time::Instant::now();
    // With --explain the points are explained after the timing, by the same sampler: the
    // seconds are the sampling's.
    let (samples, seconds, explained, name) = match args.backend {
        Backend::Cpu => {
            let relit = prt_runtime::CpuRelighter::new(&asset)?.relight(&lighting, 1)?;
            let sampler = SurfaceSampler::for_relit(&asset, &relit, &settings.lookup);
            let samples: Vec<Sample> = points.iter().map(|(p, n)| sampler.sample(*p, *n)).collect();
            let seconds = start.elapsed().as_secs_f64();
            let explained: Vec<Explanation> = match args.explain {
                true => points
                    .iter()
                    .map(|(p, n)| sampler.explain(*p, *n))
                    .collect(),
                false => Vec::new(),
            };
            (samples, seconds, explained, "cpu")
        }
        Backend::Gpu => {
            let samples = sample_gpu(&asset, &lighting, settings, &points)?;
            (samples, start.elapsed().as_secs_f64(), Vec::new(), "gpu")
        }
    };
    let mut doc = samples_json(&points, &samples, name, normal_bias, &asset);
    if let Some(list) = doc["samples"].as_array_mut() {
        for (sample, e) in list.iter_mut().zip(&explained) {
            sample["explain"] = explanation_json(e);
        }
    }
    let text = serde_json::to_vec(&doc)?;
    prt_format::io::write_bytes_atomic(&args.json, &text)
        .with_context(|| format!("writing {}", args.json.display()))?;
    println!(
        "sampled {} points ({name}, normal bias {normal_bias} spacings) in {seconds:.3} s",
        samples.len()
    );
    for (i, e) in explained.iter().enumerate().take(EXPLAINED_LINES) {
        println!("point {i}: {}", explanation_line(e));
    }
    if explained.len() > EXPLAINED_LINES {
        println!(
            "({} more points explained in the JSON)",
            explained.len() - EXPLAINED_LINES
        );
    }
    println!("wrote {}", args.json.display());
    Ok(())
}

/// Points `--explain` summarises on the terminal, one line each (the JSON has them all).
const EXPLAINED_LINES: usize = 20;

/// One line of what the lookup did at a point: what it read (mean of RGB), the surfel's
/// agreement, near field and sky term, and how many of the probes the surfel sees.
fn explanation_line(e: &Explanation) -> String {
    let mean = |v: [f32; 3]| (v[0] + v[1] + v[2]) / 3.0;
    let e_out = mean(e.sample.irradiance);
    let probes = mean(e.probes_irradiance);
    match e.surfel {
        None => format!(
            "E {e_out:.4e}: no surfel, the probe volume's lookup over {} probe(s)",
            e.probes.len()
        ),
        Some(s) => {
            let seen = e.probes.iter().filter(|p| p.seen == Some(true)).count();
            let kept = match probes > 0.0 {
                true => mean(s.before_floor) / probes,
                false => 1.0,
            };
            format!(
                "E {e_out:.4e}: surfel {} (normal agreement {:.2}), sees {seen} of {} probes \
                 (their E {probes:.4e}{}), near field {}/{} hits keeps {:.0}%{}, sky term {:+.4}",
                s.index,
                s.agreement,
                e.probes.len(),
                if s.sees_a_probe {
                    ""
                } else {
                    ", by depth moments"
                },
                s.near_hits,
                s.near_rays,
                100.0 * kept,
                match (0..3).any(|c| s.near_field_irradiance[c] > s.before_floor[c]) {
                    true => " (the ringing floor)",
                    false => "",
                },
                s.sky_term
            )
        }
    }
}

/// An [`Explanation`] as JSON (`--explain`): the fields of `prt_runtime::surface`'s
/// `Explanation`, `SurfelStep` and `ProbeStep`.
fn explanation_json(e: &Explanation) -> Value {
    let surfel = e.surfel.map(|s| {
        json!({
            "index": s.index,
            "brick": s.brick,
            "position": s.position,
            "normal": s.normal,
            "agreement": s.agreement,
            "sees_a_probe": s.sees_a_probe,
            "near_hits": s.near_hits,
            "near_rays": s.near_rays,
            "escaping": s.escaping,
            "hemisphere": s.hemisphere,
            "near": s.near,
            "ringing_floor": s.ringing_floor,
            "before_floor": s.before_floor,
            "near_field_irradiance": s.near_field_irradiance,
            "sky_term": s.sky_term,
        })
    });
    let probes: Vec<Value> = (e.probes.iter())
        .map(|p| {
            json!({
                "index": p.index,
                "position": p.position,
                "seen": p.seen,
                "irradiance": p.irradiance,
            })
        })
        .collect();
    json!({
        "surfel": surfel,
        "probes": probes,
        "probes_irradiance": e.probes_irradiance,
    })
}

/// One full GPU update, then the real snippet at every point.
fn sample_gpu(
    asset: &prt_format::Asset,
    lighting: &prt_runtime::Lighting,
    settings: RuntimeSettings,
    points: &[Point],
) -> Result<Vec<Sample>> {
    let (device, queue, info) = prt_runtime::gpu::headless_device()?;
    eprintln!("adapter: {} ({:?})", info.name, info.backend);
    let settings = settings.fitted_to(lighting);
    let mut runtime = PrtRuntime::new(&device, &queue, asset, settings)?;
    runtime.settle(lighting)?;
    Ok(prt_runtime::gpu::sample_points(
        &device, &queue, &runtime, points,
    )?)
}

/// The output document of docs/conventions.md section 6 (plus the backend and the bias used).
fn samples_json(
    points: &[Point],
    samples: &[Sample],
    backend: &str,
    normal_bias: f32,
    asset: &prt_format::Asset,
) -> Value {
    let samples: Vec<Value> = points
        .iter()
        .zip(samples)
        .map(|((p, n), s)| {
            json!({
                "position": p,
                "normal": n,
                "irradiance": s.irradiance,
                "sh": s.sh,
                "validity": s.validity,
            })
        })
        .collect();
    json!({
        "backend": backend,
        "normal_bias": normal_bias,
        "normal_bias_metres": normal_bias * asset.header.grid.spacing,
        "samples": samples,
    })
}

/// Reads and checks the points file; every error names the file, and the point and value at
/// fault.
fn read_points(path: &Path) -> Result<Vec<Point>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let doc: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    let Some(list) = doc.get("points").and_then(Value::as_array) else {
        bail!(
            "{}: expected {{\"points\": [{{\"position\": [x,y,z], \"normal\": [x,y,z]}}, ...]}}",
            path.display()
        );
    };
    list.iter()
        .enumerate()
        .map(|(i, p)| {
            let field = |name: &str| {
                vec3(p.get(name)).with_context(|| {
                    format!(
                        "{}: point {i}: \"{name}\" is {}, expected [x, y, z] of finite 32-bit floats",
                        path.display(),
                        p.get(name).map_or("missing".to_string(), Value::to_string)
                    )
                })
            };
            let position = field("position")?;
            let normal = field("normal")?;
            // Scaled by the largest component first: no overflow or underflow on the way.
            let big = normal.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            if big == 0.0 {
                bail!(
                    "{}: point {i}: \"normal\" {normal:?} has zero length",
                    path.display()
                );
            }
            let scaled = normal.map(|v| v / big);
            let len = scaled.iter().map(|v| v * v).sum::<f32>().sqrt();
            Ok((position, scaled.map(|v| v / len)))
        })
        .collect()
}

/// Three finite f32s, or `None`.
fn vec3(v: Option<&Value>) -> Option<[f32; 3]> {
    let a = v?.as_array()?;
    if a.len() != 3 {
        return None;
    }
    let mut out = [0.0f32; 3];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x.as_f64()? as f32;
        if !o.is_finite() {
            return None;
        }
    }
    Some(out)
}
