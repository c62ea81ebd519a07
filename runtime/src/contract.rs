//! GPU-side structs of the runtime (the asset's own arrays are uploaded as they are) and the
//! constants shared with WGSL. `shaders::prelude` injects the constants into every shader, and
//! a unit test checks every struct's size and field offsets against naga's layout of
//! `shaders/types.wgsl`, so the two sides cannot drift apart.

use bytemuck::{Pod, Zeroable};
use prt_format::{LightKind, TransferPrecision, BRICK_BACKFACE, PROBE_VALID, U8_SH_RANGE};

use crate::lights::{NormalBounds, PreparedLight};

/// Threads per workgroup of the per-brick, per-surfel and per-probe stages.
pub const WORKGROUP: u32 = 64;
/// Threads per workgroup of the gather (one workgroup per probe): one NVIDIA warp. Measured on
/// lavapipe at 13.8k probes, 74 factors each: 64 threads 243 ms, 32 threads 151 ms, 16 threads
/// 133 ms per gather; 32 keeps hardware GPUs busy.
pub const GATHER_WORKGROUP: u32 = 32;
/// Most lights a runtime can be built for ([`super::RuntimeSettings::max_lights`]): what sets
/// it is the per-brick light mask, `max_lights / 32` words per brick (twice: this update's and
/// the last), 64 MiB for 64k bricks at this limit, and the CPU reference's own limit
/// ([`crate::relight::MAX_CPU_LIGHTS`]), which every GPU result is checked against.
pub const MAX_LIGHTS: usize = 4096;
/// A brick without room in the visibility pool (its lights are traced whenever it is relit).
pub const NO_CACHE: u32 = u32::MAX;
/// Workgroups along x of every dispatch; more work continues along y.
pub const DISPATCH_WIDTH: u32 = 32768;
/// `Params::sky_mode` values.
pub const SKY_BLACK: u32 = 0;
pub const SKY_CONSTANT: u32 = 1;
pub const SKY_DIRECTIONS: u32 = 2;
/// Largest finite IEEE half: texels of half-float volumes are clamped to +-this.
pub const HALF_MAX: f32 = 65504.0;

/// A light as the shaders read it (see `PreparedLight`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuLight {
    pub position: [f32; 3],
    pub kind: u32,
    pub direction: [f32; 3],
    pub inv_range_sq: f32,
    pub radiant: [f32; 3],
    pub cos_outer: f32,
    pub cone_scale: f32,
    /// Range, `f32::MAX` without one.
    pub range: f32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<GpuLight>() == 64);

/// WGSL code of a light kind.
pub fn light_kind_code(kind: LightKind) -> u32 {
    match kind {
        LightKind::Directional => 0,
        LightKind::Point => 1,
        LightKind::Spot => 2,
    }
}

impl From<&PreparedLight> for GpuLight {
    fn from(l: &PreparedLight) -> Self {
        GpuLight {
            position: l.position.to_array(),
            kind: light_kind_code(l.kind),
            direction: l.direction.to_array(),
            inv_range_sq: l.inv_range_sq,
            radiant: l.radiant.to_array(),
            cos_outer: l.cos_outer,
            cone_scale: l.cone_scale,
            range: l.range.min(f32::MAX),
            _pad: [0; 2],
        }
    }
}

/// One storage binding's worth of factor tables (`FactorChunk` in WGSL).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct FactorChunk {
    pub first_factor: u32,
    pub probe_begin: u32,
    pub probe_end: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<FactorChunk>() == 16);

/// One storage binding's worth of surfels: whole bricks `brick_begin..brick_end`, whose
/// surfels are `surfel_begin..surfel_end` (`SurfelChunk` in WGSL). The per-surfel arrays
/// (surfels, direct and bounce radiance) are split alike.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct SurfelChunk {
    pub brick_begin: u32,
    pub brick_end: u32,
    pub surfel_begin: u32,
    pub surfel_end: u32,
}
const _: () = assert!(std::mem::size_of::<SurfelChunk>() == 16);

/// Component-wise bounds of a brick's surfel normals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuNormalBounds {
    pub min: [f32; 3],
    pub _pad0: u32,
    pub max: [f32; 3],
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<GpuNormalBounds>() == 32);

impl From<&NormalBounds> for GpuNormalBounds {
    fn from(n: &NormalBounds) -> Self {
        GpuNormalBounds {
            min: n.min.to_array(),
            max: n.max.to_array(),
            ..Default::default()
        }
    }
}

/// Work counters the stages increment (read back for reports and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct Counters {
    pub bricks_relit: u32,
    pub surfels_relit: u32,
    pub shadow_rays: u32,
    pub probes_gathered: u32,
    /// Probes whose SH exceeded the volume texture's range (`VolumeFormat::F16`: +-65504) and
    /// were clamped in it (the probes' f32 SH stay exact); `plus` keeps the larger.
    pub probes_clamped: u32,
    /// Light-brick reach tests of the cull stage: changed lights x front-face bricks.
    pub light_tests: u32,
    /// Visibility pool words handed out (one bit per surfel and reaching light, rounded to
    /// words per surfel); `plus` keeps the larger.
    pub visibility_words: u32,
    /// Bricks with lights left uncached because the pool was full
    /// ([`super::RuntimeSettings::visibility_words`]): from the next relight on they trace all
    /// their lights whenever relit; `plus` keeps the larger.
    pub bricks_uncached: u32,
}
const _: () = assert!(std::mem::size_of::<Counters>() == 32);

impl Counters {
    /// Field-wise sum (saturating), for work over several updates.
    pub fn plus(&self, o: &Counters) -> Counters {
        Counters {
            bricks_relit: self.bricks_relit.saturating_add(o.bricks_relit),
            surfels_relit: self.surfels_relit.saturating_add(o.surfels_relit),
            shadow_rays: self.shadow_rays.saturating_add(o.shadow_rays),
            probes_gathered: self.probes_gathered.saturating_add(o.probes_gathered),
            probes_clamped: self.probes_clamped.max(o.probes_clamped),
            light_tests: self.light_tests.saturating_add(o.light_tests),
            visibility_words: self.visibility_words.max(o.visibility_words),
            bricks_uncached: self.bricks_uncached.max(o.bricks_uncached),
        }
    }
}

/// The uniform block of every stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Params {
    pub probe_count: u32,
    pub brick_count: u32,
    /// 1 when every front-face brick's radiance is rebuilt (a fixed bounce count restarts).
    pub all_radiance_dirty: u32,
    pub ray_count: u32,
    pub light_count: u32,
    /// Changed lights listed in the light-changes buffer after its moved-lights bitset.
    pub changed_count: u32,
    pub sky_mode: u32,
    pub all_probes_dirty: u32,
    pub sky_color: [f32; 3],
    pub ray_weight: f32,
    pub grid_counts: [u32; 3],
    pub window_start: u32,
    pub window_count: u32,
    pub texel_limit: f32,
    pub dispatch_width: u32,
    /// Words of the light masks in use: `ceil(max(previous, current light count) / 32)`. The
    /// previous count matters: removed lights' bits must be cleared and the old masks counted
    /// in full, or cached-visibility slots shift (`tests/tests/lights.rs`).
    pub light_words: u32,
    pub offset_scale: f32,
    pub all_bricks_dirty: u32,
    /// The scene's length scale for shadow-ray offsets (`visibility::ray_offset`): the spacing.
    pub ray_scale: f32,
    /// Factor on the fed-back bounce light (`shaders/bounce_surfels.wgsl`): 1 for
    /// [`super::Bounces::Fixed`], the damping of [`super::Bounces::Feedback`].
    pub bounce_damping: f32,
    /// This update's half of the visibility pool (0 or 1).
    pub vis_parity: u32,
    /// Words in each half of the visibility pool.
    pub vis_capacity: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<Params>() == 112);

/// The uniform of the engine-side sampling snippet (`PrtVolumeInfo` in
/// `shaders/sample_irradiance.wgsl`): the grid the volume covers and the sampling bias.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct VolumeInfo {
    pub origin: [f32; 3],
    /// The grid's spacing: the unit of the visibility maps' distances.
    pub spacing: f32,
    /// Probe counts along x, y, z, as floats.
    pub counts: [f32; 3],
    /// Metres along the normal the snippet moves a point before sampling (`prt_sample_sh`).
    pub normal_bias: f32,
    /// The lattice step along x, y, z (`prt_format::Grid::step`).
    pub step: [f32; 3],
    /// [`VOLUME_VISIBILITY`]: weight each of the eight probes by whether the point is visible
    /// from it (eight manual fetches); without it, one hardware trilinear fetch per texture.
    pub flags: u32,
}
const _: () = assert!(std::mem::size_of::<VolumeInfo>() == 48);

/// `VolumeInfo::flags`: visibility-aware sampling.
pub const VOLUME_VISIBILITY: u32 = 1;

impl From<&prt_format::Grid> for VolumeInfo {
    fn from(g: &prt_format::Grid) -> Self {
        VolumeInfo {
            origin: g.origin,
            spacing: g.spacing,
            counts: g.counts.map(|c| c as f32),
            normal_bias: 0.0,
            step: g.step,
            flags: 0,
        }
    }
}

/// `(name, value)` of every constant the WGSL side uses, as WGSL source text.
pub fn wgsl_constants() -> Vec<(&'static str, String)> {
    use prt_format::sh::{Y00, Y1, Y20, Y22, Y2_OFF};
    vec![
        ("WORKGROUP", format!("{WORKGROUP}u")),
        ("NO_CACHE", format!("{NO_CACHE}u")),
        ("GATHER_WORKGROUP", format!("{GATHER_WORKGROUP}u")),
        ("BVH_STACK", format!("{}u", crate::visibility::MAX_STACK)),
        (
            "LIGHT_DIRECTIONAL",
            format!("{}u", light_kind_code(LightKind::Directional)),
        ),
        (
            "LIGHT_POINT",
            format!("{}u", light_kind_code(LightKind::Point)),
        ),
        (
            "LIGHT_SPOT",
            format!("{}u", light_kind_code(LightKind::Spot)),
        ),
        ("INFINITE_DISTANCE", format!("{:e}", f32::MAX)),
        (
            "RAY_OFFSET_MAGNITUDE",
            format!("{:e}", crate::visibility::RAY_OFFSET_MAGNITUDE),
        ),
        (
            "RAY_OFFSET_SCALE",
            format!("{:e}", crate::visibility::RAY_OFFSET_SCALE),
        ),
        (
            "EDGE_TOLERANCE",
            format!("{:e}", prt_format::EDGE_TOLERANCE),
        ),
        (
            "MIN_DISTANCE_SQ",
            format!("{:e}", crate::lights::MIN_DISTANCE_SQ),
        ),
        ("BRICK_BACKFACE", format!("{BRICK_BACKFACE}u")),
        ("PROBE_VALID", format!("{PROBE_VALID}u")),
        ("PROBE_NONE", format!("{}u", u32::MAX)),
        ("SKY_BLACK", format!("{SKY_BLACK}u")),
        ("SKY_CONSTANT", format!("{SKY_CONSTANT}u")),
        ("SKY_DIRECTIONS", format!("{SKY_DIRECTIONS}u")),
        (
            "FACTOR_F32",
            format!("{}u", factor_format_code(TransferPrecision::F32)),
        ),
        (
            "FACTOR_F16",
            format!("{}u", factor_format_code(TransferPrecision::F16)),
        ),
        (
            "FACTOR_U8",
            format!("{}u", factor_format_code(TransferPrecision::U8)),
        ),
        ("U8_SH_RANGE", format!("{U8_SH_RANGE:?}")),
        ("SH_Y00", format!("{Y00:?}")),
        ("SH_Y1", format!("{Y1:?}")),
        ("SH_Y2_OFF", format!("{Y2_OFF:?}")),
        ("SH_Y20", format!("{Y20:?}")),
        ("SH_Y22", format!("{Y22:?}")),
    ]
}

/// Size in u32 words of one factor of each precision.
pub fn factor_words(precision: TransferPrecision) -> u32 {
    let bytes = match precision {
        TransferPrecision::F32 => std::mem::size_of::<prt_format::FactorF32>(),
        TransferPrecision::F16 => std::mem::size_of::<prt_format::FactorF16>(),
        TransferPrecision::U8 => std::mem::size_of::<prt_format::FactorU8>(),
    };
    (bytes / 4) as u32
}

/// WGSL `FACTOR_FORMAT` code of each precision (`FACTOR_F32`, `FACTOR_F16`, `FACTOR_U8`).
pub fn factor_format_code(precision: TransferPrecision) -> u32 {
    match precision {
        TransferPrecision::F32 => 0,
        TransferPrecision::F16 => 1,
        TransferPrecision::U8 => 2,
    }
}
