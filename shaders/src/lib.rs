//! The WGSL sources of prt's GPU runtime and of its reference Forward+ renderer, embedded as
//! strings so that `prt-runtime` and `prt-render` build from their published packages (each
//! file lives in this crate's own folder). The sources are fragments: `prt_runtime::gpu::shaders`
//! prepends the constants generated from Rust and joins a stage's files; its unit tests
//! validate every assembled stage with naga and check struct layouts and `@binding` numbers
//! against the Rust side.

/// `bounce_surfels.wgsl`: Runtime stage 3 (multi-bounce): the volume's irradiance at surfels.
pub const BOUNCE_SURFELS: &str = include_str!("../bounce_surfels.wgsl");
/// `brick_radiance.wgsl`: Runtime stage 4: brick radiance (mean and gradient) from its surfels.
pub const BRICK_RADIANCE: &str = include_str!("../brick_radiance.wgsl");
/// `coarse_radiance.wgsl`: Runtime stage 5: coarse bricks' radiance from their bricks'.
pub const COARSE_RADIANCE: &str = include_str!("../coarse_radiance.wgsl");
/// `cull_lights.wgsl`: Runtime stage 1: per-brick light masks, dirty bricks, shadow-ray cache room.
pub const CULL_LIGHTS: &str = include_str!("../cull_lights.wgsl");
/// `fill.wgsl`: Runtime stage 9: grid points the coarse levels fill, from its probes.
pub const FILL: &str = include_str!("../fill.wgsl");
/// `gather.wgsl`: Runtime stage 8: factors and sky reduced into probe SH, written to the volume.
pub const GATHER: &str = include_str!("../gather.wgsl");
/// `gather_subgroup.wgsl`: Stage 8 entry point with subgroup reductions.
pub const GATHER_SUBGROUP: &str = include_str!("../gather_subgroup.wgsl");
/// `gather_tree.wgsl`: Stage 8 entry point with a shared-memory tree reduction.
pub const GATHER_TREE: &str = include_str!("../gather_tree.wgsl");
/// `light_sample.wgsl`: The light model (`light_sample`): a punctual light's unshadowed irradiance.
pub const LIGHT_SAMPLE: &str = include_str!("../light_sample.wgsl");
/// `mark_probes.wgsl`: Runtime stage 7: probes whose bricks changed.
pub const MARK_PROBES: &str = include_str!("../mark_probes.wgsl");
/// `near_radiance.wgsl`: Runtime stage 6: what each near group's near-field rays bring.
pub const NEAR_RADIANCE: &str = include_str!("../near_radiance.wgsl");
/// `oct_normal.wgsl`: `prt_decode_normal` and `prt_oct_unfold`, octahedral normals, for the snippet and the surfel stages.
pub const OCT_NORMAL: &str = include_str!("../oct_normal.wgsl");
/// `relight_surfels.wgsl`: Runtime stage 2: direct irradiance at surfels with cached shadow rays.
pub const RELIGHT_SURFELS: &str = include_str!("../relight_surfels.wgsl");
/// `render_cull.wgsl`: Reference renderer: tiled light culling (Forward+).
pub const RENDER_CULL: &str = include_str!("../render_cull.wgsl");
/// `render_shade.wgsl`: Reference renderer: shading with direct light and indirect diffuse.
pub const RENDER_SHADE: &str = include_str!("../render_shade.wgsl");
/// `render_types.wgsl`: Reference renderer: shared structs.
pub const RENDER_TYPES: &str = include_str!("../render_types.wgsl");
/// `sample_irradiance.wgsl`: The engine-side snippet: `sample_irradiance(world_pos, normal)` over the volume.
pub const SAMPLE_IRRADIANCE: &str = include_str!("../sample_irradiance.wgsl");
/// `store_probe.wgsl`: Stages 8 and 9: a probe's SH to `probe_sh` and a grid point's seven volume
/// texels.
pub const STORE_PROBE: &str = include_str!("../store_probe.wgsl");
/// `surfel.wgsl`: The asset's surfels as stored, decoded (`surfel_at`) for the stages that read them.
pub const SURFEL: &str = include_str!("../surfel.wgsl");
/// `types.wgsl`: Structs and helpers every runtime stage shares (Params, Counters, the asset's arrays).
pub const TYPES: &str = include_str!("../types.wgsl");
/// `shadow_rays.wgsl`: The any-hit shadow-ray BVH traversal (`occluded`, `ray_offset`).
pub const SHADOW_RAYS: &str = include_str!("../shadow_rays.wgsl");
