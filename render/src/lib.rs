//! # prt-render: a tiled Forward+ renderer with prt's indirect diffuse
//!
//! The reference integration of prt's GI into an engine, and what `prt render` draws. It shades
//! a glTF scene (loaded by `prt_scene`, as the bake loads it: same triangles, materials and
//! textures) with direct light from many punctual lights plus indirect diffuse from the
//! runtime's probe volume, recording into the caller's command encoder like
//! `PrtRuntime::update`:
//!
//! 1. **depth pre-pass** ([`raster`]): the scene's depth, nothing else.
//! 2. **tiled light culling** ([`cull`], one compute dispatch, one workgroup per square tile of
//!    [`RenderSettings::tile`] pixels): each tile's min/max depth bounds a view-space box; the
//!    point and spot lights whose range sphere touches it are listed in light order, at most
//!    [`RenderSettings::max_lights_per_tile`], overflow counted in [`CullStats`].
//! 3. **shading** ([`raster`]): the scene again, LessEqual against the pre-pass depth; each
//!    pixel sums the directional lights (looped directly: they reach every tile) and its tile's
//!    list (or every light with [`Culling::None`], the brute-force reference) with the runtime's
//!    own light model (`light_sample`, docs/conventions.md section 3), each light shadowed by an
//!    any-hit ray through the asset's BVH, then adds `albedo / pi * sample_irradiance(p, n)`
//!    (surfaces as docs/conventions.md section 4 defines them: flat normals, Lambertian albedo,
//!    double-sided materials lit from both sides).
//!
//! **Why Forward+ tiles.** A rig may hold thousands of point and spot lights, each reaching a
//! small part of the screen. Looping over every light at every pixel costs pixels x lights.
//! Culling once per tile (Harada et al. 2012; Olsson & Assarsson 2011) costs tiles x lights and leaves each pixel
//! only its tile's lights; the pre-pass depth lets the culling drop lights in front of or behind
//! everything a tile shows (2.5D culling), and lets shading run once per visible pixel; unlike
//! deferred shading, no G-buffer of material inputs is needed, only depth. Tiles
//! list lights in rig order, and every culling test is conservative, so a tiled frame equals
//! the brute-force one ([`Culling::None`]) exactly; tests check it.
//!
//! **Shadows are rays, not shadow maps**: the asset already carries the BVH the GI's surfels are
//! shadowed with, so direct light and GI agree exactly on what blocks a light, with no resolution,
//! bias or per-light map to manage for a thousand lights; `prt-bench render` measures their cost.
//!
//! **Rust and WGSL share one source of truth for each fact**: binding numbers live only in the
//! WGSL, read with naga and bound by name ([`bindings`]); constants are generated from
//! [`layout`] into every stage's source ([`shaders`]); each GPU struct is a `Pod` Rust twin of a
//! WGSL struct with a compile-time size assert, and unit tests check both against naga's layout
//! without a GPU.
//!
//! The frame is read back as linear radiance ([`Frame`]); [`image`] tone-maps it (Khronos PBR
//! Neutral), draws the tile heat map and writes PNG and EXR files. [`job`] is `prt render` as a
//! library call.

pub mod bindings;
pub mod camera;
pub mod cull;
pub mod gpu_scene;
pub mod image;
pub mod job;
pub mod layout;
pub mod raster;
mod renderer;
pub mod shaders;

pub use camera::Camera;
pub use layout::CullStats;
pub use renderer::{Frame, Renderer};

/// What the shading pass writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum View {
    /// `direct + indirect`: the final image.
    #[default]
    Lit,
    /// Emission plus direct light from every light, shadowed.
    Direct,
    /// Indirect diffuse from the probe volume only.
    Indirect,
    /// The surface albedo.
    Albedo,
}

/// How the shading pass finds the point and spot lights of a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Culling {
    /// Per-tile lists from the culling stage.
    #[default]
    Tiled,
    /// Every light at every pixel: the reference the tiled result must equal.
    None,
}

/// Renderer options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Tile side in pixels (16 to 256). Smaller tiles list fewer lights per pixel at the cost of
    /// more culling work and list memory.
    pub tile: u32,
    /// Most lights listed per tile; more are dropped and counted in [`CullStats`].
    pub max_lights_per_tile: u32,
    pub culling: Culling,
    /// Shadow rays for direct light (off only to measure their cost or to compare with an
    /// unshadowed reference).
    pub shadows: bool,
}

impl Default for RenderSettings {
    /// 1280x720, 16-pixel tiles (the fewest light evaluations per pixel in `prt-bench render`),
    /// up to 512 lights per tile, tiled culling, shadows on.
    fn default() -> Self {
        RenderSettings {
            width: 1280,
            height: 720,
            tile: 16,
            max_lights_per_tile: 512,
            culling: Culling::Tiled,
            shadows: true,
        }
    }
}

/// Why the renderer could not start or draw.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("the scene has no triangles to render")]
    NoTriangles,
    #[error("scene: {0}")]
    Scene(String),
    #[error("camera: {0}")]
    Camera(String),
    #[error("--size {width}x{height}: {why}")]
    Size {
        width: u32,
        height: u32,
        why: String,
    },
    #[error("--tile {0}: tiles are 16 to 256 pixels")]
    Tile(u32),
    #[error("max lights per tile {0}: must be 1 to {max}", max = layout::MAX_OTHER_LIGHTS)]
    MaxPerTile(u32),
    #[error("the rig has {count} {kind} lights; the renderer takes at most {max}")]
    TooManyLights {
        count: usize,
        kind: &'static str,
        max: usize,
    },
    #[error("the rig has {count} lights, but the lit and indirect views relight the GI on the GPU runtime, which takes at most {max}; use --view direct, albedo or heatmap, or fewer lights")]
    GiLights { count: usize, max: usize },
    #[error("{what} needs {needed} bytes, beyond the device limit {limit}")]
    Limit {
        what: &'static str,
        needed: u64,
        limit: u64,
    },
    #[error("writing {path}: {message}")]
    Write {
        path: std::path::PathBuf,
        message: String,
    },
    /// A stage's WGSL declares a binding the renderer cannot make or fill (a bug in the
    /// renderer: unit tests check every shader).
    #[error("{label}: {message}")]
    Shader {
        label: &'static str,
        message: String,
    },
    #[error(transparent)]
    Gpu(#[from] prt_runtime::gpu::GpuError),
}
