//! # The GPU runtime: relight bricks and gather probes into a 3D SH volume, in wgpu compute
//!
//! [`PrtRuntime::update`] records, into a command encoder the engine owns, one dispatch per
//! stage and chunk of the split arrays. Each stage is one entry of the table in `stages.rs`
//! (its WGSL, its dispatch, when it runs), one WGSL file in `shaders/` and a CPU twin in
//! [`crate::relight`]; its bindings are read from its WGSL and bound by name (`bindings.rs`) to
//! the buffers of [`resources`]. In dispatch order:
//!
//! 1. **cull_lights** (per brick): which of the lights that changed reach the brick (range,
//!    cone, facing, in world space; never through screen-space clusters), kept as one bit per
//!    light in the brick's light mask, and whether a changed light reaches it now or did before:
//!    only then is the brick *dirty*. Each brick takes one bit per (surfel, reaching light) pair
//!    in the shadow-ray cache (two halves, written in turn).
//! 2. **relight_surfels** (per surfel, per surfel chunk; for a dirty brick's): direct irradiance from the brick's
//!    lights, shadowed by shadow rays through the asset's BVH, cached per pair and
//!    re-traced only for lights that moved; other bricks' bits move to the new half. The
//!    surfel's radiance is kept as one word ([`crate::radiance_word`]; three f32 for the exact
//!    preset's f32 surfels).
//! 3. **bounce_surfels** (per surfel, per surfel chunk; built for multi-bounce only, run at the
//!    start of a cycle): the volume's
//!    irradiance at the surfel through the engine's `sample_irradiance`, as bounce radiance
//!    (kept as stage 2 keeps its radiance);
//!    every front-face brick becomes dirty ([`Bounces`]).
//! 4. **brick_radiance** (per brick, per surfel chunk; for a dirty brick, or every front-face
//!    brick when a fixed bounce count restarts): mean and gradient of the brick's radiance, direct plus bounce,
//!    and the mean radiance of each of its near groups (the surface lookup's, `crate::surface`).
//! 5. **coarse_radiance** (per coarse brick, every one; when brick_radiance ran; assets baked
//!    with `--far-ratio` only): a coarse brick with a dirty brick is dirty, and its mean and
//!    gradient are fitted from its bricks' (`prt_format::coarse`).
//! 6. **near_radiance** (per near group, every group; when brick_radiance ran): what the
//!    group's near-field rays bring, for `sample_irradiance`'s surface terms.
//! 7. **mark_probes** (per probe, per factor chunk): probes with a factor on a dirty brick or
//!    coarse brick (or all, when the sky changed, a bounce began or a fixed bounce count
//!    restarted) are flagged for gathering.
//! 8. **gather** (one workgroup per probe of this update's window, per factor chunk): the probe's factors and sky
//!    term reduced into SH9 RGB (subgroup adds where the adapter has them, a shared-memory tree
//!    otherwise), written with its validity into the seven volume textures at once.
//! 9. **fill** (per grid point a sparse bake left to the coarse levels, every one): its SH is
//!    the trilinear interpolation of the coarse probes around it (`prt_format::tier`), written
//!    with validity 1 like a gathered probe's.
//!
//! A light costs a brick's surfels one bit test where it does not reach, and moving one light
//! of a thousand tests it against every brick once and traces only its own pairs
//! (`tests/tests/lights.rs`). Up to [`RuntimeSettings::max_lights`] lights (default 256, at
//! most [`MAX_LIGHTS`]).
//!
//! When nothing changed and no round-robin cycle is pending, `update` records nothing (with
//! [`Bounces::Feedback`] there is always one: it feeds back for ever). With a
//! budget of B probes, the gather visits B probes per update round robin over the P valid ones
//! (a grid point without data, or an invalid probe, costs no window slot: a sparse asset's
//! cycle is as short as its probes with data make it); a gathered probe's texels always hold
//! one complete gather (a filled point's follow its corners as they are gathered), and a cycle
//! of `ceil(P / B)` updates converges exactly to the full update. The fill (stage 9) checks
//! every filled point in every recorded update but redoes only those beside a probe the
//! update gathered.
//! With [`Bounces`] beyond one, each such cycle adds one bounce.

pub use sample::sample_points;
pub use wgpu;

mod bindings;
mod changes;
mod memory;
pub mod resources;
pub mod sample;
pub mod shaders;
mod stages;
mod volume;

pub use memory::Allocation;
pub use volume::{read_buffer, sh_from_texels};

use prt_format::sh::ShRgb;
use prt_format::{directions, Asset, Factors};
use wgpu::util::DeviceExt;

pub use crate::settings::{Bounces, LookupSettings};

use crate::contract::*;
use crate::rig::Lighting;
use crate::settings::MAX_BOUNCES;
use crate::sky::SkyModel;
use changes::{light_changes, Plan, State};
use resources::Resources;
use shaders::ShaderConfig;
use stages::{Counts, Pipeline, STAGES};

/// Why the GPU runtime could not start or update.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found ({0}); install a Vulkan driver (e.g. `apt-get install mesa-vulkan-drivers` for the lavapipe software adapter)")]
    NoAdapter(String),
    #[error("cannot open the GPU device: {0}")]
    Device(String),
    #[error("the rig has {count} lights; this GPU runtime was built for at most {max} (RuntimeSettings::max_lights, up to {MAX_LIGHTS})")]
    TooManyLights { count: usize, max: usize },
    #[error("RuntimeSettings::max_lights must be in 1..={MAX_LIGHTS}, got {0}")]
    MaxLights(usize),
    #[error("the asset has no probes")]
    NoProbes,
    #[error("an equirect sky reads the probes' sky masks, which this runtime was built without (RuntimeSettings::equirect_sky is false)")]
    NoSkyMask,
    #[error("{what} needs the device feature {feature}, which this adapter lacks")]
    Feature {
        what: &'static str,
        feature: &'static str,
    },
    #[error("{what} needs {needed}, beyond the device limit {limit}")]
    Limit {
        what: &'static str,
        needed: u64,
        limit: u64,
    },
    #[error("the asset's BVH needs a traversal stack of {needed} entries, more than {max}")]
    BvhTooDeep { needed: usize, max: usize },
    #[error("reading back from the GPU failed: {0}")]
    Readback(String),
    #[error("bounces must be Fixed(1..={max}) or Feedback with damping in (0, 1], got {0:?}", max = MAX_BOUNCES)]
    Bounces(Bounces),
}

/// Texel format of the SH volume.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VolumeFormat {
    /// `Rgba16Float`: half the memory; values beyond +-65504 are clamped to it and counted
    /// (`Counters::probes_clamped`, printed by `prt relight --backend gpu`): use `F32`, or scale
    /// the lights' units, for a scene brighter than that.
    #[default]
    F16,
    /// `Rgba32Float`: exact; sampling with filtering needs `Features::FLOAT32_FILTERABLE`.
    F32,
}

impl VolumeFormat {
    fn texture_format(self) -> wgpu::TextureFormat {
        match self {
            VolumeFormat::F16 => wgpu::TextureFormat::Rgba16Float,
            VolumeFormat::F32 => wgpu::TextureFormat::Rgba32Float,
        }
    }

    fn wgsl(self) -> &'static str {
        match self {
            VolumeFormat::F16 => "rgba16float",
            VolumeFormat::F32 => "rgba32float",
        }
    }
}

/// Runtime options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RuntimeSettings {
    pub volume_format: VolumeFormat,
    /// Split the factor tables into storage bindings of at most this many bytes (default: the
    /// device's storage binding limit). Lower values trade one extra mark and gather dispatch
    /// per chunk for smaller buffers.
    pub max_factor_chunk_bytes: Option<u64>,
    /// Split the surfel arrays into storage bindings of at most this many bytes of surfels
    /// (default: the device's storage binding limit), whole bricks each. Each chunk costs one
    /// more dispatch of the per-surfel and per-brick stages.
    pub max_surfel_chunk_bytes: Option<u64>,
    /// How the engine's snippet looks the volume up ([`LookupSettings`]); bounces beyond the
    /// first sample the volume at the surfels through the same lookup.
    pub lookup: LookupSettings,
    /// Light bounces ([`Bounces`]); default one.
    pub bounces: Bounces,
    /// Most lights a rig may have (1 to [`MAX_LIGHTS`], default 256; see
    /// [`RuntimeSettings::with_room_for`]): each brick keeps a mask of `max_lights / 32` words,
    /// twice, so the masks take `bricks x max_lights / 4` bytes in one storage binding (128 MiB
    /// on lavapipe: 2 M bricks at 256 lights, 524k at 1,024).
    pub max_lights: usize,
    /// Words in each half of the shadow-ray cache, one bit per (surfel, light that reaches its
    /// brick) pair, rounded to words per surfel [default: 2 words per surfel, for bricks reached
    /// by up to 64 lights on average; 1 when `max_lights` is at most 32, all a surfel can
    /// need]. Bricks past it are left uncached (traced every time they are relit;
    /// `Counters::bricks_uncached`), never wrong.
    pub shadow_cache_words: Option<u64>,
    /// Whether the runtime can relight with an equirect sky (`SkyModel::Equirect`), which
    /// reads each probe's sky mask (`prt_format::sky_mask`: 82 bytes a probe on average on
    /// `street_20_L120` at 1 m, 2.5 MB). Without it the mask is not uploaded and such a sky is
    /// refused ([`GpuError::NoSkyMask`]); constant and black skies need none [default: true].
    pub equirect_sky: bool,
}

impl RuntimeSettings {
    /// These settings fitted to `lighting`, for a runtime whose rig never grows and whose sky
    /// never becomes an image (a command-line relight, sample or render, and the GPU bench):
    /// `max_lights` its light count rounded up to a whole light-mask word (32; at most
    /// [`MAX_LIGHTS`]) and `equirect_sky` only for an equirect sky, whatever these settings
    /// had. The per-brick light masks and the shadow-ray cache then take what the rig needs
    /// rather than what 256 lights would: on `street_20_L120` at 1 m (60k bricks, 860k
    /// surfels, 8 lights, a constant sky) the masks go from 3.9 to 0.5 MB, the cache from 13.8
    /// to 6.9 MB and the sky masks from 2.5 MB (7.7 before format 17) to none, with the same
    /// relit result (`tests/tests/lights.rs`). An engine whose rig may grow keeps
    /// [`RuntimeSettings::with_room_for`].
    pub fn fitted_to(self, lighting: &crate::Lighting) -> RuntimeSettings {
        RuntimeSettings {
            max_lights: lighting
                .rig
                .lights
                .len()
                .max(1)
                .next_multiple_of(32)
                .min(MAX_LIGHTS),
            equirect_sky: matches!(lighting.sky, crate::SkyModel::Equirect { .. }),
            ..self
        }
    }

    /// These settings with `max_lights` raised to fit a rig of `lights` lights (up to
    /// [`MAX_LIGHTS`]; a larger rig is refused at `update`).
    pub fn with_room_for(self, lights: usize) -> RuntimeSettings {
        RuntimeSettings {
            max_lights: lights.clamp(self.max_lights, MAX_LIGHTS.max(self.max_lights)),
            ..self
        }
    }
}

impl Default for RuntimeSettings {
    fn default() -> Self {
        RuntimeSettings {
            bounces: Bounces::Fixed(1),
            max_lights: 256,
            shadow_cache_words: None,
            equirect_sky: true,
            volume_format: VolumeFormat::default(),
            max_factor_chunk_bytes: None,
            max_surfel_chunk_bytes: None,
            lookup: LookupSettings::default(),
        }
    }
}

/// What one `update` recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateReport {
    /// Nothing changed and no cycle was pending: no command was recorded.
    pub idle: bool,
    /// Lights whose parameters changed (or that were added or removed).
    pub changed_lights: u32,
    pub sky_changed: bool,
    /// Where in the valid probes (grid order) the gather window starts, and how many it gathers
    /// (it wraps around the valid probes).
    pub window: (u32, u32),
    /// Updates still needed to visit every probe since the last change, times the cycles still
    /// needed for the bounces ([`Bounces::Fixed`]; 0 with [`Bounces::Feedback`]'s endless cycles
    /// once the first is done).
    pub pending_windows: u32,
    /// The volume was fed back into the surfels (stage 3 ran): a cycle of bounces began.
    pub bounce: bool,
}

/// Opens a headless device on the first adapter (lavapipe where there is no GPU), with subgroup
/// operations and the highest limits the adapter offers. Fails loudly when there is no adapter.
pub fn headless_device() -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), GpuError> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
    let wanted = wgpu::Features::SUBGROUP | wgpu::Features::FLOAT32_FILTERABLE;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("prt"),
        required_features: adapter.features() & wanted,
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .map_err(|e| GpuError::Device(e.to_string()))?;
    Ok((device, queue, adapter.get_info()))
}

/// Workgroup counts `(x, y)` covering `groups` linear workgroups.
fn dispatch_size(groups: u32) -> (u32, u32) {
    let x = groups.clamp(1, DISPATCH_WIDTH);
    (x, groups.div_ceil(x).max(1))
}

/// The first update serial (`Params::update_serial`): a probe's dirty word is 0 before its
/// first gather, 1 while it waits for one (`mark_probes`), and the serial of the update that
/// last gathered it after.
const GATHERED_FIRST: u32 = 2;

/// The GPU relighting runtime of one asset.
pub struct PrtRuntime {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// Valid probes: what the gather's round robin cycles over (`resources::gather_list`).
    gather_count: u32,
    /// Grid points the coarse levels fill (`resources::fill_list`).
    fill_count: u32,
    /// Entries of `probe_sh` in use: the probes with data.
    sh_entry_count: u32,
    /// The asset's grid points (`Params::probe_count` is their count): where
    /// [`PrtRuntime::read_probe_sh`] finds a probe's entry
    /// ([`probe_sh_entry`]) and how it fills the other points from their corners, as
    /// `fill.wgsl` does (`crate::fill`). A host copy of 32 bytes a grid point (17 MB for the
    /// 110 m plaza at 1 m) that spares the GPU 108 bytes a filled point.
    probes: Vec<prt_format::Probe>,
    brick_count: u32,
    coarse_count: u32,
    surfel_spread_sq: f32,
    ray_count: u32,
    grid: prt_format::Grid,
    offset_scale: f32,
    settings: RuntimeSettings,
    /// Every buffer and texture, bound by name (`bindings.rs`).
    res: Resources,
    cache_capacity: u32,
    /// The half of the shadow-ray cache the last relight wrote.
    cache_parity: u32,
    /// The stages built for these settings, in dispatch order.
    pipelines: Vec<Pipeline>,
    state: Option<State>,
    /// The last equirect sky, its lattice radiance (`SkyModel::lattice` averages the map over
    /// every direction's cell: computed again only when the sky changes, not every update)
    /// and its mean (`SkyModel::mean_radiance`).
    sky_cache: Option<(SkyModel, Vec<[f32; 4]>, [f32; 3])>,
    cursor: u32,
    /// Probes gathered in the current cycle (one pass of the gather over every valid probe).
    cycle_gathered: u32,
    /// Cycles completed since the last change of lights or sky.
    cycles_done: u32,
    /// This update's number (`Params::update_serial`): what the gather leaves in a probe's
    /// dirty word, so that the fill redoes only the points beside probes it gathered.
    serial: u32,
}

impl PrtRuntime {
    /// Uploads `asset` and builds the pipelines. The device needs 12 storage buffers and 7 storage
    /// textures per shader stage (above WebGPU's defaults: request the adapter's limits, as
    /// [`headless_device`] does); a device or asset beyond its limits is a [`GpuError::Limit`].
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        asset: &Asset,
        settings: RuntimeSettings,
    ) -> Result<PrtRuntime, GpuError> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let runtime = Self::create(device, queue, asset, settings);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(e.to_string()));
        }
        runtime
    }

    fn create(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        asset: &Asset,
        settings: RuntimeSettings,
    ) -> Result<PrtRuntime, GpuError> {
        if !settings.bounces.is_valid() {
            return Err(GpuError::Bounces(settings.bounces));
        }
        if !(1..=MAX_LIGHTS).contains(&settings.max_lights) {
            return Err(GpuError::MaxLights(settings.max_lights));
        }
        let mask_stride = settings.max_lights.div_ceil(32) as u32;
        // Stage 3 samples the volume with the engine's filtering sampler.
        if settings.bounces.feeds_back()
            && settings.volume_format == VolumeFormat::F32
            && !device
                .features()
                .contains(wgpu::Features::FLOAT32_FILTERABLE)
        {
            return Err(GpuError::Feature {
                what: "bounces with an f32 volume (filtered sampling)",
                feature: "FLOAT32_FILTERABLE",
            });
        }
        if asset.probes.is_empty() {
            return Err(GpuError::NoProbes);
        }
        let needed = asset.geometry.stack_needed();
        if needed > MAX_STACK {
            return Err(GpuError::BvhTooDeep {
                needed,
                max: MAX_STACK,
            });
        }
        let subgroups = device.features().contains(wgpu::Features::SUBGROUP);
        let config = ShaderConfig {
            factors: asset.factors.precision(),
            surfels: asset.header.settings.surfel_precision,
            volume_format: settings.volume_format.wgsl(),
            subgroups,
            mask_stride,
            bounces: settings.bounces.feeds_back(),
        };
        let sh_entry_count = asset.probes.iter().filter_map(probe_sh_entry).count() as u32;
        let res = Resources::new(device, asset, &settings, mask_stride, sh_entry_count)?;
        let counts = Counts {
            bricks: asset.bricks.len() as u32,
            probes: asset.probes.len() as u32,
            groups: asset.surface.group_surfels.len() as u32,
            coarse: asset.coarse.bricks.len() as u32,
            fills: res.asset.fill_count,
        };
        let pipelines = STAGES
            .iter()
            .filter(|stage| !stage.bounces_only || settings.bounces.feeds_back())
            .map(|stage| Pipeline::new(device, &res, stage, &config, counts))
            .collect::<Result<_, GpuError>>()?;
        Ok(PrtRuntime {
            device: device.clone(),
            queue: queue.clone(),
            gather_count: res.asset.gather_count,
            fill_count: res.asset.fill_count,
            sh_entry_count,
            probes: asset.probes.clone(),
            brick_count: asset.bricks.len() as u32,
            coarse_count: asset.coarse.bricks.len() as u32,
            surfel_spread_sq: crate::lights::surfel_spread_sq(asset.header.settings.cell_size),
            ray_count: asset.header.ray_count,
            grid: asset.header.grid,
            offset_scale: match &asset.factors {
                Factors::U8 { offset_scale, .. } => *offset_scale,
                _ => 1.0,
            },
            settings,
            cache_capacity: res.state.cache_capacity as u32,
            res,
            cache_parity: 1,
            pipelines,
            state: None,
            sky_cache: None,
            cursor: 0,
            cycle_gathered: 0,
            cycles_done: 0,
            serial: GATHERED_FIRST,
        })
    }

    /// Records this update's compute work into `encoder`. `budget` is the number of probes
    /// gathered per update (`None`: all). Submit the encoder before the next `update`.
    pub fn update(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        lighting: &Lighting,
        budget: Option<u32>,
    ) -> Result<UpdateReport, GpuError> {
        let new = self.state_for(lighting)?;
        let changes = light_changes(
            self.state.as_ref().map(|s| &s.lights[..]),
            &new.lights,
            self.res.mask_stride as usize,
        );
        let changed = changes.len() as u32 - self.res.mask_stride;
        // Words of the light masks in use: the old lights' too, so that removed lights' bits
        // are cleared and the old masks counted in full.
        let light_words = (new.lights.len())
            .max(self.state.as_ref().map_or(0, |s| s.lights.len()))
            .div_ceil(32) as u32;
        let Some(plan) = self.plan(&new, changed, budget) else {
            return Ok(UpdateReport {
                idle: true,
                ..UpdateReport::default()
            });
        };
        // Serials from GATHERED_FIRST up, wrapping past the dirty word's other values.
        self.serial = self.serial.checked_add(1).unwrap_or(GATHERED_FIRST);
        let params = self.params(&new, changed, light_words, &plan);
        if plan.sky_changed && self.settings.lookup.sky_terms {
            let pi = std::f32::consts::PI;
            self.res.info.sky_irradiance = new.sky_mean.map(|l| pi * l);
        }
        if plan.relight() {
            self.cache_parity = params.cache_parity;
        }
        self.upload(encoder, &params, &new, &changes, &plan);
        self.record(encoder, &plan);
        self.advance(plan.window.1);
        self.state = Some(new);
        Ok(UpdateReport {
            idle: false,
            changed_lights: changed,
            sky_changed: plan.sky_changed,
            window: plan.window,
            pending_windows: self.pending(plan.window.1),
            bounce: plan.bounce,
        })
    }

    /// Records what this update's stages read before they run: the uniform block, the lights,
    /// the light changes and sky where they changed, zeroed counters, and (when a fixed bounce
    /// count restarts) zeroed bounce radiance.
    fn upload(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        params: &Params,
        new: &State,
        changes: &[u32],
        plan: &Plan,
    ) {
        if plan.fixed_restart {
            for [_, _, bounce, _] in &self.res.chunk_surfels {
                encoder.clear_buffer(bounce, 0, None);
            }
        }
        let copy = |encoder: &mut wgpu::CommandEncoder, dst: &wgpu::Buffer, bytes: &[u8]| {
            if bytes.is_empty() {
                return;
            }
            let src = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("prt upload"),
                    contents: bytes,
                    usage: wgpu::BufferUsages::COPY_SRC,
                });
            encoder.copy_buffer_to_buffer(&src, 0, dst, 0, bytes.len() as u64);
        };
        copy(encoder, &self.res.state.params, bytemuck::bytes_of(params));
        copy(
            encoder,
            &self.res.state.lights,
            bytemuck::cast_slice(&new.lights),
        );
        if plan.relight() {
            copy(
                encoder,
                &self.res.state.light_changes,
                bytemuck::cast_slice(changes),
            );
        }
        if plan.sky_changed {
            copy(
                encoder,
                &self.res.state.sky_directions,
                bytemuck::cast_slice(&new.sky_directions),
            );
            copy(
                encoder,
                &self.res.volume_info,
                bytemuck::bytes_of(&self.res.info),
            );
        }
        encoder.clear_buffer(&self.res.state.counters, 0, None);
    }

    /// The uniform block of this update.
    fn params(&self, new: &State, changed: u32, light_words: u32, plan: &Plan) -> Params {
        Params {
            probe_count: self.probes.len() as u32,
            brick_count: self.brick_count,
            ray_count: self.ray_count,
            light_count: new.lights.len() as u32,
            changed_count: changed,
            sky_mode: new.sky_mode,
            all_probes_dirty: u32::from(plan.sky_changed || plan.bounce || plan.fixed_restart),
            sky_color: new.sky_color,
            ray_weight: directions::direction_weight(self.ray_count),
            grid_counts: self.grid.counts,
            window_start: plan.window.0,
            window_count: plan.window.1,
            texel_limit: match self.settings.volume_format {
                VolumeFormat::F16 => HALF_MAX,
                VolumeFormat::F32 => f32::MAX,
            },
            dispatch_width: DISPATCH_WIDTH,
            light_words,
            offset_scale: self.offset_scale,
            all_bricks_dirty: u32::from(plan.first),
            all_radiance_dirty: u32::from(plan.fixed_restart),
            ray_scale: self.grid.spacing,
            bounce_damping: match self.settings.bounces {
                Bounces::Feedback { damping } => damping,
                Bounces::Fixed(_) => 1.0,
            },
            cache_parity: if plan.relight() {
                1 - self.cache_parity
            } else {
                self.cache_parity
            },
            cache_capacity: self.cache_capacity,
            coarse_count: self.coarse_count,
            surfel_spread_sq: self.surfel_spread_sq,
            gather_count: self.gather_count,
            fill_count: self.fill_count,
            update_serial: self.serial,
            _pad: 0,
        }
    }

    /// One compute pass: each stage that runs this update, once per bind-group set.
    fn record(&self, encoder: &mut wgpu::CommandEncoder, plan: &Plan) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prt update"),
            timestamp_writes: None,
        });
        for pipeline in &self.pipelines {
            pipeline.record(&mut pass, plan);
        }
    }

    /// Records and submits updates (every probe each) until nothing is pending: one for one
    /// bounce, `n` for [`Bounces::Fixed`]`(n)`, one cycle for [`Bounces::Feedback`] (call again
    /// to feed back more). Returns the number of updates.
    pub fn settle(&mut self, lighting: &Lighting) -> Result<u32, GpuError> {
        self.settle_each(lighting, |_| Ok(()))
    }

    /// [`PrtRuntime::settle`], calling `after` once each non-idle update is submitted.
    fn settle_each(
        &mut self,
        lighting: &Lighting,
        mut after: impl FnMut(&PrtRuntime) -> Result<(), GpuError>,
    ) -> Result<u32, GpuError> {
        let mut updates = 0;
        loop {
            let mut encoder = self.device.create_command_encoder(&Default::default());
            let report = self.update(&mut encoder, lighting, None)?;
            self.queue.submit([encoder.finish()]);
            updates += 1;
            if report.idle {
                return Ok(updates);
            }
            after(self)?;
            if report.pending_windows == 0 {
                return Ok(updates);
            }
        }
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }
}

/// Relights `asset` on the GPU until settled (all probes, blocking: one update per bounce) and
/// returns every probe's SH, the work counters summed over the updates, the adapter and the
/// runtime's GPU memory: what `prt relight --backend gpu` runs.
pub fn relight_once(
    asset: &Asset,
    lighting: &Lighting,
    settings: RuntimeSettings,
) -> Result<Relit, GpuError> {
    let (device, queue, adapter) = headless_device()?;
    let mut runtime = PrtRuntime::new(&device, &queue, asset, settings)?;
    let mut counters = Counters::default();
    runtime.settle_each(lighting, |r| {
        counters = counters.plus(&r.read_counters()?);
        Ok(())
    })?;
    Ok(Relit {
        sh: runtime.read_probe_sh()?,
        counters,
        adapter,
        memory: runtime.gpu_memory(),
    })
}

/// What [`relight_once`] returns.
pub struct Relit {
    /// Every probe's SH, in grid order.
    pub sh: Vec<ShRgb>,
    /// The work counters summed over the updates.
    pub counters: Counters,
    pub adapter: wgpu::AdapterInfo,
    /// The runtime's allocations, largest first, and their total ([`PrtRuntime::gpu_memory`]).
    pub memory: (Vec<Allocation>, u64),
}
