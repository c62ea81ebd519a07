//! `prt render` (docs/conventions.md section 6): options to a [`prt_render::job::RenderJob`].

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use glam::Vec3;
use prt_cli::options::{camera_of, normal_bias, parse_size, parse_vec3};
use prt_render::job::{Output, RenderJob};
use prt_render::{Culling, RenderSettings};
use prt_runtime::gpu::RuntimeSettings;

use crate::common::{ensure_not_input, lighting_of};

#[derive(Clone, Copy, ValueEnum)]
pub enum ViewArg {
    /// Direct + indirect.
    Lit,
    /// Emission and direct light, shadowed.
    Direct,
    /// Indirect diffuse from the probe volume.
    Indirect,
    Albedo,
    /// Lights per tile, with a legend.
    Heatmap,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum CullingArg {
    /// Per-tile light lists (Forward+).
    Tiled,
    /// Every light at every pixel (the reference).
    None,
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// The scene the asset was baked from (.gltf or .glb).
    scene: PathBuf,
    /// The baked asset (.prt).
    asset: PathBuf,
    /// Light rig JSON [default: the scene's KHR_lights_punctual lights, black sky].
    #[arg(long)]
    lights: Option<PathBuf>,
    /// Output PNG (tone-mapped with Khronos PBR Neutral, sRGB), written atomically.
    #[arg(short, long)]
    output: PathBuf,
    /// Also write linear radiance (before exposure and tone mapping) as OpenEXR.
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Camera position X,Y,Z [default: the glTF's first camera, else a view of the whole scene].
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<Vec3>,
    /// Point the camera looks at X,Y,Z (with --eye).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<Vec3>,
    /// Vertical field of view in degrees [default: the glTF camera's, else 50].
    #[arg(long, allow_hyphen_values = true)]
    fov: Option<f32>,
    /// Image size WxH.
    #[arg(long, value_parser = parse_size, default_value = "1280x720")]
    size: (u32, u32),
    #[arg(long, value_enum, default_value = "lit")]
    view: ViewArg,
    /// Exposure in EV (the image is scaled by 2^EV before tone mapping).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    exposure: f32,
    #[arg(long, value_enum, default_value = "tiled")]
    culling: CullingArg,
    /// Tile side in pixels (16 to 256).
    #[arg(long, default_value_t = 16)]
    tile: u32,
    /// Most lights listed per tile (more are dropped and reported).
    #[arg(long, default_value_t = 512)]
    max_lights_per_tile: u32,
    /// Direct light without shadow rays (to measure their cost).
    #[arg(long)]
    no_shadows: bool,
    /// Light bounces of the GI (1: direct light at surfels only; each more feeds the volume
    /// back into the surfels once).
    #[arg(long, default_value_t = 1)]
    bounces: u32,
    /// Move indirect lookups of the probe volume this many probe spacings along the surface
    /// normal [default: the runtime's, 0.2; points with a surfel's terms take the surface
    /// lookup's, `LookupSettings::surface_bias`, but for its fallback where the surfel sees none
    /// of its probes].
    #[arg(long, allow_hyphen_values = true)]
    normal_bias: Option<f32>,
    /// Indirect light by plain trilinear interpolation, without the Chebyshev test against the
    /// probes' depth moments that keeps light from leaking through walls (to compare).
    #[arg(long, alias = "no-visibility")]
    no_depth_moments: bool,
    /// Indirect light from the probe volume alone, without the asset's surface terms (which
    /// probes each surfel sees, its near field; to compare).
    #[arg(long)]
    no_surface_terms: bool,
    /// The sky as the probes see it, not as each surface sees it (without the asset's sky
    /// terms; to compare).
    #[arg(long)]
    no_sky_terms: bool,
    /// Render even if the asset was baked from another scene file.
    #[arg(long)]
    force: bool,
    /// A folder besides the scene's own whose files its buffer and image URIs may name (a
    /// shared texture folder); repeatable. Without it a URI resolving elsewhere is refused.
    #[arg(long = "allow-path", value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

pub fn run(args: RenderArgs) -> Result<()> {
    let job = job_of(args)?;
    let mut inputs = vec![job.scene.as_path(), job.asset.as_path()];
    inputs.extend(job.lights.as_deref());
    for out in std::iter::once(&job.png).chain(&job.exr) {
        ensure_not_input(out, &inputs)?;
    }
    let asset = prt_format::read_asset(&job.asset)
        .with_context(|| format!("loading {}", job.asset.display()))?;
    let lighting = lighting_of(job.lights.as_deref(), &asset)?;
    let report = prt_cli::panics::quietly(|| prt_render::job::run(&job, &lighting, &asset))?;
    print_report(&job, &lighting, &report);
    Ok(())
}

/// The render job the options describe.
fn job_of(args: RenderArgs) -> Result<RenderJob> {
    let camera = camera_of(args.eye, args.target, args.fov)?;
    let runtime = RuntimeSettings {
        lookup: prt_runtime::LookupSettings {
            normal_bias: normal_bias(args.normal_bias)?,
            depth_moments: !args.no_depth_moments,
            surface_terms: !args.no_surface_terms,
            sky_terms: !args.no_sky_terms,
            ..prt_runtime::LookupSettings::default()
        },
        bounces: prt_runtime::gpu::Bounces::Fixed(args.bounces),
        ..RuntimeSettings::default()
    };
    if !args.exposure.is_finite() {
        bail!("--exposure {}: expected a finite EV", args.exposure);
    }
    Ok(RenderJob {
        scene: args.scene,
        asset: args.asset,
        lights: args.lights,
        png: args.output,
        exr: args.exr,
        camera,
        fov: args.fov,
        output: match args.view {
            ViewArg::Lit => Output::Lit,
            ViewArg::Direct => Output::Direct,
            ViewArg::Indirect => Output::Indirect,
            ViewArg::Albedo => Output::Albedo,
            ViewArg::Heatmap => Output::Heatmap,
        },
        exposure_ev: args.exposure,
        settings: RenderSettings {
            width: args.size.0,
            height: args.size.1,
            tile: args.tile,
            max_lights_per_tile: args.max_lights_per_tile,
            culling: match args.culling {
                CullingArg::Tiled => Culling::Tiled,
                CullingArg::None => Culling::None,
            },
            shadows: !args.no_shadows,
        },
        runtime,
        force: args.force,
        allowed: prt_scene::Allowed {
            dirs: args.allow_path,
        },
    })
}

/// The summary of a finished render: camera, lights per pixel, overflow warning, times, files.
fn print_report(
    job: &RenderJob,
    lighting: &prt_runtime::Lighting,
    report: &prt_render::job::RenderReport,
) {
    eprintln!("adapter: {}", report.adapter);
    let c = report.camera;
    println!(
        "camera           eye {:.3},{:.3},{:.3} target {:.3},{:.3},{:.3} fov {:.1}",
        c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z, c.fov_degrees
    );
    println!(
        "lights           {} in the rig; {:.2} evaluated per shaded pixel ({} pixels)",
        lighting.rig.lights.len(),
        report.lights_per_pixel,
        report.shaded_pixels
    );
    if report.stats.overflow_tiles > 0 {
        eprintln!(
            "warning: {} tiles had more than {} lights: {} light entries dropped (raise --max-lights-per-tile or lower --tile)",
            report.stats.overflow_tiles, job.settings.max_lights_per_tile, report.stats.dropped
        );
    }
    println!(
        "time             gi {:.3} s | render {:.3} s",
        report.gi_seconds, report.render_seconds
    );
    println!("wrote            {}", job.png.display());
    if let Some(exr) = &job.exr {
        println!("wrote            {}", exr.display());
    }
}
