//! `prt-bench surface` (issues 11 and 31): irradiance where a renderer shows it, at surface
//! points and (for the levels and Sponza) over a camera view, against the independent oracle's
//! references: the bundled scenes' (`fixtures/surface/*_surface.json`, made by
//! `scripts/surface_refs.sh`; Sponza's pocket flags and `sponza_image.json` by
//! `fixtures/levels/refs.py --scene`) and the level family's (`fixtures/levels/refs/`, made by
//! `fixtures/levels/refs.py`), all with the Mitsuba 3 oracle, which is not part of this
//! repository: the references are its output, committed as data.
//!
//! Probe SH are accurate at probe centres; surfaces sample the volume between probes, often with a
//! wall between the point and some of its eight probes. Each case is baked as a new user would
//! (whole scene, default spacing) and at half that spacing (not with `--no-half`), relit on the
//! CPU, and sampled with the
//! CPU twin of the engine's `sample_irradiance` (normal offset included) at the reference points
//! and pixels, with each lookup of [`lookups`].
//!
//! Point scores follow the oracle's `score_surface.py` so that both give the same numbers:
//! - per point, relative error `mean_rgb |E - E_sh| / max(mean_rgb E_sh, 1e-3 median)`, where
//!   `E_sh` is the irradiance of the reference SH at the point (clamped at 0: isolates
//!   interpolation, validity and leaks from the L2 truncation), `median` the median over all
//!   points of the reference's mean-RGB hemispherical irradiance `E_hemi`, and a sample with
//!   validity 0 counts as `E = 0` (the shader returns nothing there); mean and p95 (linear
//!   interpolation between order statistics, as numpy) over the open points, and the mean over
//!   the pockets apart (a lookup's normal offset steps out of a gap narrower than itself);
//! - leaks: `E > 1.5 E_hemi` and `E - E_hemi > 0.05 median` (mean RGB), over the open points;
//! - black (ours): `E < 0.01 mean` while `E_hemi > 0.05 mean`, `mean` being the scene's mean
//!   reference irradiance: a hole or a wall's shadow where the truth is clearly lit;
//! - holes (ours): samples whose eight probes are all invalid (validity 0).
//!
//! Image scores: [`image`].

mod cases;
pub mod frontier;
mod image;
mod lookups;
pub mod open_air;
mod pictures;
mod placement;
mod refs;
mod report;
pub(crate) mod score;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use prt_format::sh::ShRgb;
use prt_format::{Asset, Summary};
use prt_runtime::{Lighting, Sample};
use rayon::prelude::*;

use crate::gather_lookup::GatherLookup;
use crate::path_lookup::PathLookup;
use crate::ray_lookup::{NearLight, RayLookup};
use crate::results::Out;
use crate::surfel_lookup::SurfelLookup;
use cases::Case;
use image::View;
use lookups::{Kind, Lookup, Lookups, Overrides};
use prt_runtime::surface::SurfaceSampler;
use refs::{RefPoint, Reference};
use report::{Row, Setting};

#[derive(clap::Args)]
pub struct SurfaceArgs {
    /// Cases to run (comma-separated): case names (cornell, two_rooms, thick_walls, sponza,
    /// sponza_sun_2, and each level of fixtures/levels/levels.json) and groups: bundled,
    /// tuning, held-out, family (tuning + held-out), unseen (seeds 24-31), fresh (seeds
    /// 32-39), all [default: bundled,family,unseen,fresh;
    /// street_20_L120 and plaza_40 run only when named or with all].
    #[arg(long = "case", value_delimiter = ',')]
    cases: Vec<String>,
    /// Lookups to sample with (comma-separated): default (the runtime's), no_sky (the same
    /// without the sky terms), trilinear, and the
    /// references of issue 31: rays, rays_light (per point, through the asset's BVH), surfels
    /// (the same terms per surfel), path, gather, surfel_gather, sky_point (the point's own
    /// sky instead of the probes') [default: trilinear, moments, default, rays, rays_light and
    /// surfels, trilinear on the bundled cases only].
    #[arg(long = "lookup", value_delimiter = ',')]
    lookups: Vec<String>,
    /// Directory the cases' paths are relative to (the repository root).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Normal offset of every lookup in probe spacings [default: each lookup's own; the
    /// runtime's is 0.2]; the surface lookup (`default`, `surfels`) weighs its probes at
    /// `LookupSettings::surface_bias` (0.1) instead, the bias the bake's sky terms take.
    #[arg(long)]
    normal_bias: Option<f32>,
    /// Near-field reach of the ray lookups that have one (rays, rays_light) in probe spacings
    /// [default: each lookup's own: 0.75 and 1].
    #[arg(long)]
    reach: Option<f32>,
    /// Rays per point of the path lookup (`--lookup path`) [default: 256; its figures against
    /// the probes' in docs/results/surface_candidates.md took 4096], per gather of `gather`
    /// and `surfel_gather` [default: 512], and per point of `sky_point` [default: 4096].
    #[arg(long)]
    path_rays: Option<u32>,
    /// The surface lookup's floor under L2's ringing, a share of the non-linear L1 model's
    /// irradiance (`LookupSettings::ringing_floor`; 0: off) [default: the runtime's, 0.15].
    #[arg(long)]
    ringing_floor: Option<f32>,
    /// Bake at this spacing in metres instead of the default, and at half of it (unless
    /// `--no-half`) [default: the bake's default for each case].
    #[arg(long)]
    spacing: Option<f32>,
    /// Bake on the uniform grid (`prt bake --uniform`) instead of the default sparse placement.
    #[arg(long)]
    uniform: bool,
    /// Bake at the default spacing (or `--spacing`) only, not at half of it too: for a level
    /// whose grid at half the spacing would not fit (an open level's uniform grid at 0.5 m).
    #[arg(long)]
    no_half: bool,
    /// Rays per probe (`prt bake --rays`) [default: the bake's].
    #[arg(long)]
    rays: Option<u32>,
    /// At most this many probes with data (`prt bake --probe-budget`), twice as many in the
    /// second bake, at half the spacing [default: no budget].
    #[arg(long)]
    probe_budget: Option<usize>,
    /// Drop probes whose prediction error is below this (`prt bake --prune-error`).
    #[arg(long)]
    prune_error: Option<f32>,
    /// Move the grid's layers down by X,Y,Z of a step, each in [0, 1)
    /// (`BakeSettings::grid_shift`: the same steps, one more layer past the bounds): where the
    /// layers fall beside walls decides much of a level's error (`docs/limits.md`). The
    /// half-spacing bake takes the same shares of its own steps [default: 0,0,0, the first
    /// layer on the bounds' minimum].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_shift)]
    grid_shift: Option<Shift>,
    /// Keep bricks whole where a wall stands on them (`prt bake --no-split-bricks`).
    #[arg(long)]
    no_split_bricks: bool,
    /// Send hits at least this many brick sizes away to coarse bricks (`prt bake --far-ratio`;
    /// 0: none) [default: the bake's].
    #[arg(long)]
    far_ratio: Option<f32>,
    /// Write each camera view (the levels') per spacing and lookup to DIR as a PNG: reference,
    /// lookup, over-lit (red) and under-lit (blue) pixels (`surface/pictures.rs`).
    #[arg(long, value_name = "DIR")]
    pictures: Option<PathBuf>,
    /// Write each sampling's per-point scores to DIR/CASE_SPACING_LOOKUP.csv (position,
    /// normal, pocket, truth, estimate, relative error, over-lit), and with a camera view its
    /// hit pixels' to DIR/CASE_SPACING_LOOKUP_image.csv (in view order; the error per pixel).
    #[arg(long, value_name = "DIR")]
    points_out: Option<PathBuf>,
    #[command(flatten)]
    out: Out,
}

/// A case's references, read before its bakes so that a bad file fails fast.
struct Refs {
    points: Reference,
    /// The camera view's hit pixels (levels, Sponza).
    image: Option<View>,
    /// Where the camera view's pictures go (`--pictures`).
    pictures: Option<PathBuf>,
    /// Where the per-point scores go (`--points-out`).
    points_out: Option<PathBuf>,
}

/// One bake of a case, relit with `lighting`.
struct Baked<'l> {
    /// The asset with black surfels and its probes' direct view of the sky ([`sky_view`]),
    /// for `sky_point`.
    sky: Option<(Asset, Vec<ShRgb>)>,
    asset: Asset,
    /// The relit bricks, for the near-field hits of the reference lookups that need them.
    near: Option<NearLight>,
    sh: Vec<ShRgb>,
    /// The relit surfels' radiance (the surface lookup's near field).
    radiance: Vec<[f32; 3]>,
    /// The sky's mean radiance (the surface lookup's sky term).
    sky_mean: [f32; 3],
    /// The rig it was relit with (the path lookup lights its hits with it).
    lighting: &'l Lighting,
    bake_s: f64,
    relight_s: f64,
}

/// `prt-bench surface`: every picked case at its default spacing and half of it, one row per
/// lookup, the report printed and with `--out` written to `surface.md`.
pub fn run(args: SurfaceArgs) -> Result<()> {
    let bias = args
        .normal_bias
        .map(|b| prt_cli::options::normal_bias(Some(b)))
        .transpose()?;
    if let Some(reach) = args.reach {
        anyhow::ensure!(
            reach.is_finite() && reach > 0.0,
            "--reach {reach}: expected a finite number of probe spacings > 0"
        );
    }
    if let Some(floor) = args.ringing_floor {
        anyhow::ensure!(
            floor.is_finite() && floor >= 0.0,
            "--ringing-floor {floor}: expected a finite share >= 0"
        );
    }
    anyhow::ensure!(
        args.path_rays != Some(0),
        "--path-rays 0: expected at least one ray per point"
    );
    let overrides = Overrides {
        normal_bias: bias,
        reach: args.reach,
        path_rays: args.path_rays,
        ringing_floor: args.ringing_floor,
    };
    let lookups = Lookups::parse(&args.lookups, overrides)?;
    let picked = cases::pick(&args.cases, cases::all(&args.root)?)?;
    let mut rows = Vec::new();
    let mut oracle = Vec::new();
    for case in &picked {
        let refs = Refs {
            points: refs::read_reference(&case.points)?,
            image: case.image.as_deref().map(image::read_image).transpose()?,
            pictures: args.pictures.clone(),
            points_out: args.points_out.clone(),
        };
        eprintln!(
            "{} ({}): {} reference points ({} pockets), {} image pixels",
            case.name,
            case.set.label(),
            refs.points.points.len(),
            refs.points.points.iter().filter(|p| p.pocket).count(),
            refs.image.as_ref().map_or(0, |v| v.pixels.len())
        );
        oracle.push((case.name.clone(), refs.points.oracle_seconds));
        rows.extend(measure(
            case,
            &refs,
            &lookups.for_set(case.set),
            (
                (args.spacing, args.grid_shift.unwrap_or_default()),
                !args.uniform,
                args.probe_budget,
                args.prune_error,
            ),
            (
                !args.no_split_bricks,
                args.far_ratio,
                args.rays,
                !args.no_half,
            ),
        )?);
    }
    let mut md = report::markdown(&rows, &oracle)?;
    if let Some([x, y, z]) = args.grid_shift.filter(|s| *s != [0.0; 3]) {
        // A shifted run's table would otherwise read as the default grid's.
        md = format!("Every bake's grid layers moved down by {x}, {y}, {z} of a step along x, y, z (`--grid-shift`).\n\n{md}");
    }
    args.out.report("surface", &md)
}

/// Bakes and relights `case` at its default spacing (or `spacing`) and, with `half`, at half of
/// it, with sparse placement or not, a row per lookup each.
fn measure(
    case: &Case,
    refs: &Refs,
    lookups: &[Lookup],
    (grid, sparse, probe_budget, prune_error): (GridSetting, bool, Option<usize>, Option<f32>),
    (split_bricks, far_ratio, rays, half): (bool, Option<f32>, Option<u32>, bool),
) -> Result<Vec<Row>> {
    let lighting = prt_runtime::load_rig(&case.rig)
        .with_context(|| format!("{}: loading the rig {}", case.name, case.rig.display()))?;
    let (spacing, grid_shift) = grid;
    let base = BakeSettings {
        double_sided: case.double_sided,
        spacing,
        grid_shift,
        sparse,
        probe_budget,
        prune_error: prune_error.unwrap_or(BakeSettings::default().prune_error),
        split_bricks,
        far_ratio: far_ratio.unwrap_or(BakeSettings::default().far_ratio),
        rays: rays.unwrap_or(BakeSettings::default().rays),
        ..BakeSettings::default()
    };
    let needs = (
        lookups.iter().any(Lookup::needs_bricks),
        lookups.iter().any(Lookup::needs_sky),
    );
    let baked = bake(case, &base, &lighting, needs)?;
    let mut rows = sample_all(case, &baked, Setting::Default, refs, lookups)?;
    if !half {
        return Ok(rows);
    }
    let half = BakeSettings {
        spacing: Some(baked.asset.header.grid.spacing / 2.0),
        probe_budget: probe_budget.map(|b| 2 * b),
        ..base
    };
    drop(baked);
    let baked = bake(case, &half, &lighting, needs)?;
    rows.extend(sample_all(case, &baked, Setting::Half, refs, lookups)?);
    Ok(rows)
}

/// A grid shift (`--grid-shift`): per axis, a share of a step in [0, 1).
type Shift = [f32; 3];

/// The spacing (`None`: the bake's default) and the grid shift a case is baked with.
type GridSetting = (Option<f32>, Shift);

/// `--grid-shift`'s three shares (the bake's own check of its settings refuses one outside
/// [0, 1), naming `grid_shift` and the value).
fn parse_shift(s: &str) -> std::result::Result<Shift, String> {
    let v: Vec<f32> = (s.split(','))
        .map(|x| x.trim().parse::<f32>().map_err(|e| format!("{x:?}: {e}")))
        .collect::<std::result::Result<_, _>>()?;
    <[f32; 3]>::try_from(v).map_err(|_| format!("{s:?}: three shares of a step X,Y,Z"))
}

/// A row per lookup, each reported on stderr as it is made.
fn sample_all(
    case: &Case,
    baked: &Baked<'_>,
    setting: Setting,
    refs: &Refs,
    lookups: &[Lookup],
) -> Result<Vec<Row>> {
    let row = |lookup| {
        let row = sample(case, baked, setting, refs, lookup)?;
        eprintln!("{}", report::progress(&row));
        Ok(row)
    };
    lookups.iter().map(row).collect()
}

/// Bakes `case` with `settings`, relights it with `lighting`, with `bricks` keeps the relit
/// bricks for the reference lookups' near field (outside the relight's time), and with `sky`
/// the probes' direct view of the sky ([`sky_view`], for `sky_point`).
fn bake<'l>(
    case: &Case,
    settings: &BakeSettings,
    lighting: &'l Lighting,
    (bricks, sky): (bool, bool),
) -> Result<Baked<'l>> {
    let t = Instant::now();
    let (asset, report) = prt_bake::bake(&case.scene, settings, &NoProgress)
        .with_context(|| format!("{}: baking {}", case.name, case.scene.display()))?;
    if let Some(r) = report.refined {
        eprintln!(
            "  {}: refine dropped {} of {} candidates (error up to {:.3}); {} of {} probes with \
             data kept",
            case.name, r.dropped, r.candidates, r.worst_dropped, r.after, r.before
        );
    }
    let bake_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let relighter = prt_runtime::CpuRelighter::new(&asset)?;
    let relit = relighter
        .relight(lighting, 1)
        .with_context(|| format!("{}: relighting with {}", case.name, case.rig.display()))?;
    let relight_s = t.elapsed().as_secs_f64();
    let near = bricks
        .then(|| NearLight::for_asset(&asset, relighter.brick_radiance(&relit.surfel_radiance)));
    let sky = sky.then(|| sky_view(&asset, lighting)).transpose()?;
    Ok(Baked {
        sky,
        asset,
        lighting,
        sh: relit.sh,
        radiance: relit.surfel_radiance,
        sky_mean: relit.sky,
        near,
        bake_s,
        relight_s,
    })
}

/// `asset` with black surfels (no albedo, no emission) and, per grid point, the SH of the sky
/// its probes see directly: that asset relit with `lighting`'s sky alone (the fill and
/// dilation as the runtime's).
fn sky_view(asset: &Asset, lighting: &Lighting) -> Result<(Asset, Vec<ShRgb>)> {
    let mut black = asset.clone();
    for s in &mut black.surfels {
        s.albedo = [0.0; 3];
        s.emission = [0.0; 3];
    }
    let sky_only = Lighting {
        rig: prt_format::LightRig {
            lights: Vec::new(),
            sky: lighting.rig.sky.clone(),
        },
        sky: lighting.sky.clone(),
    };
    let sh = prt_runtime::CpuRelighter::new(&black)?
        .relight(&sky_only, 1)?
        .sh;
    Ok((black, sh))
}

/// The sampler of one lookup over one bake.
enum Sampler<'a> {
    Runtime(SurfaceSampler<'a>),
    Rays(RayLookup<'a>),
    Surfels(SurfelLookup<'a>),
    Path(PathLookup<'a>),
    Gather(GatherLookup<'a>),
    SkyPoint(Box<crate::sky_point_lookup::SkyPointLookup<'a>>),
}

impl<'a> Sampler<'a> {
    fn new(baked: &'a Baked<'_>, lookup: &Lookup) -> Result<Self> {
        let (asset, sh, settings) = (&baked.asset, &baked.sh[..], &lookup.settings);
        let near = || {
            baked
                .near
                .as_ref()
                .context("the relit bricks were not kept")
        };
        Ok(match lookup.kind {
            Kind::Runtime => {
                let sky = baked.sky_mean;
                Sampler::Runtime(SurfaceSampler::new(
                    asset,
                    sh,
                    &baked.radiance,
                    sky,
                    settings,
                ))
            }
            Kind::Rays(r) => {
                let rays = RayLookup::for_asset(asset, sh, settings.normal_bias, r);
                Sampler::Rays(match r.near_light {
                    true => rays.with_near_light(near()?),
                    false => rays,
                })
            }
            Kind::Surfels => Sampler::Surfels(SurfelLookup::new(asset, sh, near()?, settings)),
            Kind::Path(rays) => {
                let light = (&baked.lighting.rig, &baked.lighting.sky);
                Sampler::Path(PathLookup::new(asset, near()?, light, rays))
            }
            Kind::SkyPoint(rays) => {
                let (black, sky_sh) = baked.sky.as_ref().context("the sky view was not kept")?;
                let dark = vec![[0.0f32; 3]; black.surfels.len()];
                // Its settings leave the sky terms out: it swaps the probes' sky itself.
                let pair = (
                    SurfaceSampler::new(asset, sh, &baked.radiance, baked.sky_mean, settings),
                    SurfaceSampler::new(black, sky_sh, &dark, baked.sky_mean, settings),
                );
                Sampler::SkyPoint(Box::new(crate::sky_point_lookup::SkyPointLookup::new(
                    asset,
                    pair,
                    &baked.lighting.sky,
                    rays,
                )))
            }
            Kind::Gather { rays, per_surfel } => {
                let sky = baked.sky_mean;
                let surface = SurfaceSampler::new(asset, sh, &baked.radiance, sky, settings);
                let with = (near()?, &baked.lighting.sky);
                Sampler::Gather(GatherLookup::new(asset, surface, with, rays, per_surfel))
            }
        })
    }

    fn sample(&self, p: [f32; 3], n: [f32; 3]) -> Sample {
        match self {
            Sampler::Runtime(s) => s.sample(p, n),
            Sampler::Rays(s) => s.sample(p, n),
            Sampler::Surfels(s) => s.sample(p, n),
            Sampler::Path(s) => s.sample(p, n),
            Sampler::Gather(s) => s.sample(p, n),
            Sampler::SkyPoint(s) => s.sample(p, n),
        }
    }
}

/// Samples `baked` with `lookup` at the reference points and pixels, and scores it.
fn sample(
    case: &Case,
    baked: &Baked<'_>,
    setting: Setting,
    refs: &Refs,
    lookup: &Lookup,
) -> Result<Row> {
    let t = Instant::now();
    let sampler = Sampler::new(baked, lookup)?;
    let at = |p: [f32; 3], n: [f32; 3]| sampler.sample(p, n);
    let samples: Vec<Sample> = refs
        .points
        .points
        .par_iter()
        .map(|p| at(p.position, p.normal))
        .collect();
    let points_s = t.elapsed().as_secs_f64();
    if let Some(dir) = &refs.points_out {
        let path = dir.join(format!(
            "{}_{}_{}.csv",
            case.name,
            setting.label(),
            lookup.name
        ));
        std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::write(&path, score::points_csv(&refs.points.points, &samples)))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let t = Instant::now();
    let image = match &refs.image {
        Some(view) => {
            let samples: Vec<Sample> = view
                .pixels
                .par_iter()
                .map(|p| at(p.position, p.normal))
                .collect();
            let e = score::irradiance(&samples);
            if let Some(dir) = &refs.points_out {
                let as_points: Vec<RefPoint> = (view.pixels.iter())
                    .map(|p| RefPoint {
                        position: p.position,
                        normal: p.normal,
                        e_sh: p.e_sh,
                        e_hemi: p.e_hemi,
                        pocket: false,
                    })
                    .collect();
                let name = format!(
                    "{}_{}_{}_image.csv",
                    case.name,
                    setting.label(),
                    lookup.name
                );
                let path = dir.join(name);
                std::fs::write(&path, score::points_csv(&as_points, &samples))
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            if let Some(dir) = &refs.pictures {
                let name = format!("{}_{}_{}", case.name, setting.label(), lookup.name);
                pictures::write(dir, &name, view, &e)?;
            }
            Some(image::score_image(&view.pixels, &e))
        }
        None => None,
    };
    let image_s = t.elapsed().as_secs_f64();
    if let Sampler::Gather(g) = &sampler {
        eprintln!("  {} {}: {}", case.name, lookup.name, g.note());
    }
    let summary = Summary::of(&baked.asset, 0);
    Ok(Row {
        case: case.name.clone(),
        set: case.set,
        setting,
        spacing: baked.asset.header.grid.spacing,
        lookup: *lookup,
        probes: summary.probes_with_data,
        grid_points: baked.asset.probes.len(),
        surface_probes: placement::surface_probes(&baked.asset),
        valid: summary.valid_probe_count,
        dilated: summary.dilated_probe_count,
        runtime_bytes: runtime_bytes(&summary),
        points: score::score_points(&refs.points.points, &samples),
        image,
        bake_s: baked.bake_s,
        relight_s: baked.relight_s,
        points_s,
        image_s,
    })
}

/// The asset's bytes an engine keeps at runtime: every array section of `prt_format::Summary`
/// (the sizes `prt inspect` prints: packed surfels as stored), since the GPU runtime uploads them all (probes,
/// sky mask and transfer, visibility maps and factors for the gather; bricks and surfels for
/// the direct light; coarse bricks; BVH and triangles for its shadow rays; the surface
/// lookup's terms). The file adds a header and a few bytes of lengths per section.
fn runtime_bytes(summary: &Summary) -> u64 {
    let s = &summary.section_bytes;
    s.probes
        + s.sky_mask
        + s.sky_transfer
        + s.probe_depth
        + s.factors
        + s.bricks
        + s.coarse
        + s.surfels
        + s.bvh_nodes
        + s.triangles
        + s.surface
}
