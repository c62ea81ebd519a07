//! What `prt render` does, as a library call: check that the asset was baked from the scene,
//! relight the GI volume when the view needs it, render one frame and write the PNG (and EXR).

use std::path::{Path, PathBuf};
use std::time::Instant;

use prt_format::Asset;
use prt_runtime::gpu::{PrtRuntime, RuntimeSettings};
use prt_runtime::Lighting;

use crate::image::{self, Heatmap};
use crate::{Camera, CullStats, Frame, RenderError, RenderSettings, Renderer, View};

/// The image a job writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Output {
    #[default]
    Lit,
    Direct,
    Indirect,
    Albedo,
    /// Lights per tile over the albedo, with a legend.
    Heatmap,
}

impl Output {
    /// The shading pass's view for this output.
    pub fn view(self) -> View {
        match self {
            Output::Lit => View::Lit,
            Output::Direct => View::Direct,
            Output::Indirect => View::Indirect,
            Output::Albedo | Output::Heatmap => View::Albedo,
        }
    }

    fn needs_gi(self) -> bool {
        matches!(self, Output::Lit | Output::Indirect)
    }
}

/// One render.
#[derive(Clone, Debug)]
pub struct RenderJob {
    pub scene: PathBuf,
    pub asset: PathBuf,
    /// Light rig JSON; none: the scene's KHR_lights_punctual lights and a black sky.
    pub lights: Option<PathBuf>,
    pub png: PathBuf,
    pub exr: Option<PathBuf>,
    /// None: the glTF's first camera, else a framing of the whole scene.
    pub camera: Option<Camera>,
    /// Overrides the camera's vertical field of view (degrees).
    pub fov: Option<f32>,
    pub output: Output,
    pub exposure_ev: f32,
    pub settings: RenderSettings,
    /// The runtime's settings for the GI volume (its normal offset among them).
    pub runtime: RuntimeSettings,
    /// Render even if the asset was baked from another file.
    pub force: bool,
    /// Folders besides the scene file's own that its buffer and image URIs may reach
    /// ([`prt_scene::Allowed`]; `prt render --allow-path`).
    pub allowed: prt_scene::Allowed,
}

/// What a job did.
#[derive(Clone, Debug)]
pub struct RenderReport {
    pub adapter: String,
    pub camera: Camera,
    pub stats: CullStats,
    /// Mean lights evaluated per shaded pixel.
    pub lights_per_pixel: f64,
    pub shaded_pixels: u64,
    pub gi_seconds: f64,
    pub render_seconds: f64,
}

/// Fails before any GPU work when `path` cannot be written (`prt_format::io::check_replaceable`:
/// its directory must exist, and it must not be a device or a directory).
fn check_output(path: &Path) -> Result<(), RenderError> {
    prt_format::io::check_replaceable(path).map_err(|e| RenderError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

/// Fails unless `scene_bytes` are the bytes `asset` was baked from.
pub fn check_source(
    scene: &Path,
    scene_bytes: &[u8],
    asset_path: &Path,
    asset: &Asset,
) -> Result<(), RenderError> {
    let hash = xxhash_rust::xxh3::xxh3_64(scene_bytes);
    if hash != asset.header.source_hash {
        return Err(RenderError::Scene(format!(
            "{} (xxh3 {hash:016x}) is not the file {} was baked from ({}, xxh3 {:016x}); pass --force to render anyway",
            scene.display(),
            asset_path.display(),
            asset.header.source_name,
            asset.header.source_hash
        )));
    }
    Ok(())
}

/// The job's camera: its own, else the scene's first (`scene_camera`), else a framing of the
/// scene's `bounds`; `--fov` applied; a bad one named after where it came from.
fn choose_camera(
    job: &RenderJob,
    scene_camera: Option<Camera>,
    bounds: Option<(glam::Vec3, glam::Vec3)>,
) -> Result<Camera, RenderError> {
    let mut camera = match (&job.camera, scene_camera) {
        (Some(c), _) => *c,
        (None, Some(c)) => c,
        (None, None) => {
            let (lo, hi) = bounds.ok_or(RenderError::NoTriangles)?;
            Camera::framing(lo, hi)
        }
    };
    if let Some(fov) = job.fov {
        camera.fov_degrees = fov;
    }
    // Name where a bad camera came from: the flags, or the scene's own camera.
    camera.validate().map_err(|e| match (&job.camera, e) {
        (None, RenderError::Camera(m)) => RenderError::Camera(format!(
            "{} (the camera of {}; pass --eye, --target and --fov to override it)",
            m,
            job.scene.display()
        )),
        (_, e) => e,
    })?;
    Ok(camera)
}

/// `f`'s result and its wall time in seconds.
fn timed<T>(f: impl FnOnce() -> Result<T, RenderError>) -> Result<(T, f64), RenderError> {
    let start = Instant::now();
    let out = f()?;
    Ok((out, start.elapsed().as_secs_f64()))
}

/// The GI volume relit and settled under `lighting`, when the job's output shows it.
fn relight(
    job: &RenderJob,
    lighting: &Lighting,
    asset: &Asset,
    (device, queue): (&wgpu::Device, &wgpu::Queue),
) -> Result<Option<PrtRuntime>, RenderError> {
    if !job.output.needs_gi() {
        return Ok(None);
    }
    let settings = job.runtime.fitted_to(lighting);
    let mut rt = PrtRuntime::new(device, queue, asset, settings)?;
    rt.settle(lighting)?;
    rt.wait()?;
    Ok(Some(rt))
}

/// Records and submits one frame and reads it back.
fn draw(
    renderer: &Renderer,
    runtime: Option<&PrtRuntime>,
    (device, queue): (&wgpu::Device, &wgpu::Queue),
) -> Result<Frame, RenderError> {
    let mut encoder = device.create_command_encoder(&Default::default());
    let volume = runtime.map(|rt| renderer.volume_group(rt));
    renderer.record(&mut encoder, volume.as_ref());
    queue.submit([encoder.finish()]);
    renderer.read_frame(device, queue)
}

/// Tone-maps `frame` (with the heat map on request) and writes the PNG and the EXR: both files
/// or neither (the EXR first, removed again if the PNG fails).
fn write_images(
    job: &RenderJob,
    renderer: &Renderer,
    frame: &Frame,
    (device, queue): (&wgpu::Device, &wgpu::Queue),
) -> Result<(), RenderError> {
    let mut pixels = image::tone_map(&frame.radiance, job.exposure_ev);
    if job.output == Output::Heatmap {
        let counts = renderer.read_tile_counts(device, queue)?;
        pixels = Heatmap {
            width: frame.width,
            height: frame.height,
            tile: job.settings.tile,
            tiles_x: renderer.tiles().0,
            counts: &counts,
        }
        .draw(&pixels);
    }
    if let Some(exr) = &job.exr {
        image::write_exr(exr, frame.width, frame.height, &frame.radiance)?;
    }
    if let Err(e) = image::write_png(&job.png, frame.width, frame.height, &pixels) {
        if let Some(exr) = &job.exr {
            let _ = std::fs::remove_file(exr);
        }
        return Err(e);
    }
    Ok(())
}

/// Shaded pixels (those with geometry) and the mean lights evaluated at each.
fn lights_per_pixel(frame: &Frame) -> (u64, f64) {
    let shaded: Vec<&[f32; 4]> = frame
        .radiance
        .iter()
        .zip(&frame.position)
        .filter(|(_, p)| p[3] > 0.0)
        .map(|(r, _)| r)
        .collect();
    let evaluated: f64 = shaded.iter().map(|r| f64::from(r[3])).sum();
    (shaded.len() as u64, evaluated / shaded.len().max(1) as f64)
}

/// Runs the job: checks, the scene and camera, GI when the output needs it, one frame, the
/// files.
pub fn run(
    job: &RenderJob,
    lighting: &Lighting,
    asset: &Asset,
) -> Result<RenderReport, RenderError> {
    let scene_bytes = prt_format::read_regular_file(&job.scene)
        .map_err(|e| RenderError::Scene(format!("reading {}: {e}", job.scene.display())))?;
    if !job.force {
        check_source(&job.scene, &scene_bytes, &job.asset, asset)?;
    }
    for out in std::iter::once(&job.png).chain(&job.exr) {
        check_output(out)?;
    }
    let scene = prt_scene::load_bytes(&job.scene, &scene_bytes, &job.allowed)
        .map_err(|e| RenderError::Scene(e.to_string()))?;
    let scene_camera = scene.cameras.first().map(Camera::from_gltf);
    let camera = choose_camera(job, scene_camera, scene.bounds())?;
    let max_gi = prt_runtime::contract::MAX_LIGHTS;
    if job.output.needs_gi() && lighting.rig.lights.len() > max_gi {
        return Err(RenderError::GiLights {
            count: lighting.rig.lights.len(),
            max: max_gi,
        });
    }
    let (device, queue, info) = prt_runtime::gpu::headless_device()?;
    let mut renderer = Renderer::new(&device, &scene, asset, job.settings)?;
    renderer.set_lights(&queue, &lighting.rig.lights)?;
    renderer.set_camera(&queue, &camera, job.output.view())?;
    let gpu = (&device, &queue);
    let (runtime, gi_seconds) = timed(|| relight(job, lighting, asset, gpu))?;
    let (frame, render_seconds) = timed(|| draw(&renderer, runtime.as_ref(), gpu))?;
    write_images(job, &renderer, &frame, gpu)?;
    let (shaded_pixels, lights_per_pixel) = lights_per_pixel(&frame);
    Ok(RenderReport {
        adapter: format!("{} ({:?})", info.name, info.backend),
        camera,
        stats: frame.stats,
        lights_per_pixel,
        shaded_pixels,
        gi_seconds,
        render_seconds,
    })
}
