//! # The contract between Rust and WGSL: every constant, flag and struct both sides read
//!
//! The CPU reference ([`crate::relight`], [`crate::sample`], [`crate::shadow_rays`]) and the GPU
//! runtime ([`crate::gpu`]) take their shared numbers from here, and the WGSL gets them
//! generated from here: [`wgsl_constants`] is prepended to every compute stage,
//! [`snippet_constants`] to the engine-side sampling snippet. The structs are the GPU twins
//! of WGSL structs in `shaders/types.wgsl` and `shaders/sample_irradiance.wgsl` (the asset's own
//! arrays are uploaded as they are); a unit test of `gpu::shaders` checks every struct's size
//! and field offsets against naga's layout of the WGSL, so the two sides cannot drift apart.
//! This module imports no other module of the crate.

use bytemuck::{Pod, Zeroable};
use prt_format::depth::{DEVIATION_STEP, MEAN_STEP, TOP};
use prt_format::surface::{BLOCKED_WEIGHT, NO_SURFEL, SIDE_BIT, SLOT_AXIS_SHIFT};
use prt_format::surfel_terms::{
    CENTRE_SHIFT, HITS_AT, NORMAL_BITS, OPEN_AT, OPEN_BITS, OPEN_RANGE,
};
use prt_format::{
    LightKind, TransferPrecision, BRICK_BACKFACE, DEPTH_MAP_SIDE, DEPTH_WORDS, PROBE_VALID,
};

/// Threads per workgroup of the per-brick, per-surfel and per-probe stages.
pub const WORKGROUP: u32 = 64;
/// Threads per workgroup of the gather (one workgroup per probe): one NVIDIA warp. Measured on
/// lavapipe at 13.8k probes, 74 factors each: 64 threads 243 ms, 32 threads 151 ms, 16 threads
/// 133 ms per gather; 32 keeps hardware GPUs busy.
pub const GATHER_WORKGROUP: u32 = 32;
/// Most lights a runtime can be built for ([`crate::gpu::RuntimeSettings::max_lights`]): what sets
/// it is the per-brick light mask, `max_lights / 32` words per brick (twice: this update's and
/// the last), 64 MiB for 64k bricks at this limit, and the CPU reference's own limit
/// ([`crate::relight::MAX_CPU_LIGHTS`]), which every GPU result is checked against.
pub const MAX_LIGHTS: usize = 4096;
/// Floats per entry of the runtime's `probe_sh` buffer: the nine SH coefficients, rgb each,
/// unpadded (`store_probe.wgsl` writes them, `fill.wgsl` and `PrtRuntime::read_probe_sh` read
/// them; a vec4 per coefficient spent a quarter on padding). One entry per probe with data, at
/// its slot ([`probe_sh_entry`]), not per grid point.
pub const PROBE_SH_FLOATS: u32 = 27;
/// Radiance words (`crate::radiance_word`, `pack_radiance` in `shaders/types.wgsl`): what
/// turns `e` (a colour's largest channel is below 2^e) into the stored exponent byte, whose
/// f32 bits `byte << 23` are the 8-bit mantissas' step `2^(e - 8)`.
pub const RADIANCE_EXPONENT_BIAS: i32 = 119;
/// Radiance words: the lowest `floor(log2)` of a colour's largest channel the exponent follows;
/// below it the step stays 2^-107, so that subnormals (which a GPU may flush) round to zero.
pub const RADIANCE_LOWEST_LOG2: i32 = -100;
/// Radiance words: f32 bits of the largest channel a word holds, `255 * 2^120`; brighter
/// channels are clamped to it, so that no word decodes to infinity.
pub const RADIANCE_MAX_BITS: u32 = 0x7f7f_0000;
/// A brick without room in the shadow-ray cache (its lights are traced whenever it is relit).
pub const NO_CACHE: u32 = u32::MAX;
/// Workgroups along x of every dispatch; more work continues along y.
pub const DISPATCH_WIDTH: u32 = 32768;
/// `Params::sky_mode` values.
pub const SKY_BLACK: u32 = 0;
pub const SKY_CONSTANT: u32 = 1;
pub const SKY_DIRECTIONS: u32 = 2;
/// Largest finite IEEE half: texels of half-float volumes are clamped to +-this.
pub const HALF_MAX: f32 = 65504.0;
/// Deepest BVH the shadow-ray traversal stack holds (the GPU kernel has a fixed-size stack,
/// `BVH_STACK`); the asset format guarantees it (`prt_format::validate::MAX_BVH_STACK`).
pub const MAX_STACK: usize = prt_format::validate::MAX_BVH_STACK;
/// Shadow-ray origin offset per unit of coordinate magnitude
/// ([`crate::shadow_rays::ray_offset`]).
pub const RAY_OFFSET_MAGNITUDE: f32 = 1e-6;
/// Shadow-ray origin offset per unit of the scene's length scale
/// ([`crate::shadow_rays::ray_offset`]).
pub const RAY_OFFSET_SCALE: f32 = 1e-4;
/// Floor of the squared distance in the inverse-square law, in m^2: only a guard against
/// dividing by zero at the light itself. docs/conventions.md section 3 has the seed's 1e-5 m^2 (a
/// 3 mm radius), which capped the light of every surface in a millimetre-sized scene (issue 8:
/// 122% error at a scale of 0.001); 1e-16 m^2 keeps scenes down to 10 micrometres exact.
pub const MIN_DISTANCE_SQ: f32 = 1e-16;

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

/// Where a grid point's SH sits in the runtime's `probe_sh` buffer, in entries of
/// [`PROBE_SH_FLOATS`]: a probe with data at its slot (`prt_format::Probe::slot`; every valid
/// probe has one), any other point `None`. A filled point's SH goes to its texels only
/// (`fill.wgsl` reads its corners, which all have data; `PrtRuntime::read_probe_sh` fills it on
/// the CPU from them): on an open level most grid points are filled (457,398 of the 110 m
/// plaza's 526,848 at 1 m, 49 MB as entries).
pub fn probe_sh_entry(probe: &prt_format::Probe) -> Option<u32> {
    probe.has_data().then_some(probe.slot)
}

/// WGSL code of a light kind.
pub fn light_kind_code(kind: LightKind) -> u32 {
    match kind {
        LightKind::Directional => 0,
        LightKind::Point => 1,
        LightKind::Spot => 2,
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
    /// Shadow-ray cache words handed out (one bit per surfel and reaching light, rounded to
    /// words per surfel); `plus` keeps the larger.
    pub shadow_cache_words: u32,
    /// Bricks with lights left uncached because the pool was full
    /// ([`crate::gpu::RuntimeSettings::shadow_cache_words`]): from the next relight on they trace all
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
            shadow_cache_words: self.shadow_cache_words.max(o.shadow_cache_words),
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
    /// in full, or cached shadow-ray slots shift (`tests/tests/lights.rs`).
    pub light_words: u32,
    pub offset_scale: f32,
    pub all_bricks_dirty: u32,
    /// The scene's length scale for shadow-ray offsets (`shadow_rays::ray_offset`): the spacing.
    pub ray_scale: f32,
    /// Factor on the fed-back bounce light (`shaders/bounce_surfels.wgsl`): 1 for
    /// [`crate::settings::Bounces::Fixed`], the damping of
    /// [`crate::settings::Bounces::Feedback`].
    pub bounce_damping: f32,
    /// This update's half of the shadow-ray cache (0 or 1).
    pub cache_parity: u32,
    /// Words in each half of the shadow-ray cache.
    pub cache_capacity: u32,
    /// Coarse bricks (`prt_format::coarse`), numbered after the `brick_count` bricks.
    pub coarse_count: u32,
    /// What a surfel's inverse square is softened by (`crate::lights::surfel_spread_sq`).
    pub surfel_spread_sq: f32,
    /// Probes the gather visits (`gather_list`: the valid ones); its window wraps around it.
    pub gather_count: u32,
    /// Grid points the coarse levels fill (`fill_list`, `prt_format::tier`).
    pub fill_count: u32,
    /// This update's number: the gather leaves it in the dirty word of each probe it gathers,
    /// and the fill redoes only the points with such a probe among their corners.
    pub update_serial: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 128);

/// The uniform of the engine-side sampling snippet (`PrtVolumeInfo` in
/// `shaders/sample_irradiance.wgsl`): the grid the volume covers and the sampling biases.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct VolumeInfo {
    pub origin: [f32; 3],
    /// The grid's spacing: the unit of the depth moments' distances.
    pub spacing: f32,
    /// Probe counts along x, y, z, as floats.
    pub counts: [f32; 3],
    /// Metres along the normal the snippet moves a point before sampling (`prt_sample_sh`).
    pub normal_bias: f32,
    /// The lattice step along x, y, z (`prt_format::Grid::step`).
    pub step: [f32; 3],
    /// [`VOLUME_DEPTH_MOMENTS`]: weight each of the eight probes by its depth moments (whether
    /// the point is visible from it; eight manual fetches); without it, one hardware trilinear
    /// fetch per texture. [`VOLUME_SURFACE`]: the surface lookup decides where it can.
    pub flags: u32,
    /// The surface lookup's brick lattice (`prt_format::surface::SurfelTermsHeader`).
    pub surface_anchor: [f32; 3],
    pub brick_size: f32,
    /// Slots of the brick table minus one, and its longest search.
    pub slot_mask: u32,
    pub max_probe: u32,
    /// Word offsets in the snippet's `prt_surface` array ([`SurfaceLayout`]).
    pub cells_at: u32,
    pub terms_at: u32,
    pub bricks_at: u32,
    /// Near-field rays per surfel.
    pub near_rays: f32,
    /// Word offset of the sky terms in `prt_surface` ([`SurfaceLayout`]).
    pub sky_at: u32,
    /// Word offset of the sides in `prt_surface` ([`SurfaceLayout`]): their count, then four
    /// words each (`prt_format::surface::SurfaceSide`).
    pub sides_at: u32,
    /// Pi times the sky's mean radiance (`crate::SkyModel::mean_radiance`): the irradiance a
    /// surfel's sky term of 1 adds (`prt_format::surface::sky_term`); set by every update
    /// whose sky changed.
    pub sky_irradiance: [f32; 3],
    /// Metres along the normal the surface lookup moves a point before weighting its probes
    /// (`LookupSettings::surface_bias`; `prt_sample_surface`).
    pub surface_bias: f32,
    /// The surface lookup's floor under L2's ringing (`LookupSettings::ringing_floor`, a
    /// share of the non-linear L1 model's irradiance; `prt_sample_surface`).
    pub ringing_floor: f32,
    pub _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<VolumeInfo>() == 128);

/// `VolumeInfo::flags`: weight probes by their depth moments (`LookupSettings::depth_moments`).
pub const VOLUME_DEPTH_MOMENTS: u32 = 1;
/// `VolumeInfo::flags`: the surface lookup (`LookupSettings::surface_terms`, and the asset has
/// surface terms).
pub const VOLUME_SURFACE: u32 = 2;

/// Words of a surfel's terms in `prt_surface` (`prt_format::surfel_terms::SurfelTerms`).
pub const TERMS_WORDS: u32 = (std::mem::size_of::<prt_format::surface::SurfelTerms>() / 4) as u32;

/// Words per brick in `prt_surface`: first surfel, first near group, centre probe.
pub const BRICK_WORDS: u32 = 3;

/// Where each table of the surface lookup starts in the snippet's one array of words
/// (`prt_surface`): the brick table's slots (4 words each), the cells (16 words a brick), the
/// surfel terms (4 words each, `prt_format::surfel_terms`), per brick its first surfel, first
/// near group and the grid index of its key's centre probe (`SurfaceTerms::brick_centre`,
/// computed here once so that the GPU reads what the CPU twin computes), the sky terms
/// (two halves a word, `prt_format::surface::SurfaceTerms::sky`), then the sides' count and
/// the sides (four words each, `prt_format::surface::SurfaceSide`; format 18).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SurfaceLayout {
    pub cells_at: u32,
    pub terms_at: u32,
    pub bricks_at: u32,
    pub sky_at: u32,
    pub sides_at: u32,
}

impl SurfaceLayout {
    /// The layout for `asset`'s terms.
    pub fn of(asset: &prt_format::Asset) -> SurfaceLayout {
        let t = &asset.surface;
        let slots = 4 * t.slots.len() as u64;
        let cells = t.cells.len() as u64;
        let terms = TERMS_WORDS as u64 * t.surfels.len() as u64;
        let bricks = BRICK_WORDS as u64 * t.groups.len() as u64;
        SurfaceLayout {
            cells_at: slots as u32,
            terms_at: (slots + cells) as u32,
            bricks_at: (slots + cells + terms) as u32,
            sky_at: (slots + cells + terms + bricks) as u32,
            sides_at: (slots + cells + terms + bricks + t.sky.len() as u64) as u32,
        }
    }

    /// The words themselves.
    pub fn words(asset: &prt_format::Asset) -> Vec<u32> {
        let t = &asset.surface;
        // `of` counts a brick entry per group start: validation holds one per brick.
        debug_assert_eq!(t.groups.len(), asset.bricks.len());
        let mut w: Vec<u32> = bytemuck::cast_slice(&t.slots).to_vec();
        w.extend_from_slice(&t.cells);
        w.extend_from_slice(bytemuck::cast_slice(&t.surfels));
        let grid = &asset.header.grid;
        for (b, g) in asset.bricks.iter().zip(&t.groups) {
            let [i, j, k] = t.brick_centre(grid, b).map(|v| v as u32);
            w.extend([b.first_surfel, *g, grid.index(i, j, k) as u32]);
        }
        w.extend_from_slice(&t.sky);
        w.push(t.sides.len() as u32);
        w.extend_from_slice(bytemuck::cast_slice(&t.sides));
        w
    }
}

impl From<&prt_format::Grid> for VolumeInfo {
    fn from(g: &prt_format::Grid) -> Self {
        VolumeInfo {
            origin: g.origin,
            spacing: g.spacing,
            counts: g.counts.map(|c| c as f32),
            normal_bias: 0.0,
            step: g.step,
            flags: 0,
            surface_anchor: [0.0; 3],
            brick_size: 0.0,
            slot_mask: 0,
            max_probe: 0,
            cells_at: 0,
            terms_at: 0,
            bricks_at: 0,
            near_rays: 1.0,
            sky_at: 0,
            sides_at: 0,
            sky_irradiance: [0.0; 3],
            surface_bias: 0.0,
            ringing_floor: 0.0,
            _pad: [0; 3],
        }
    }
}

/// `(name, value)` of every constant the WGSL side uses, as WGSL source text.
pub fn wgsl_constants() -> Vec<(&'static str, String)> {
    use prt_format::sh::{Y00, Y1, Y20, Y22, Y2_OFF};
    vec![
        ("WORKGROUP", format!("{WORKGROUP}u")),
        ("NO_CACHE", format!("{NO_CACHE}u")),
        ("PROBE_SH_FLOATS", format!("{PROBE_SH_FLOATS}u")),
        (
            "RADIANCE_EXPONENT_BIAS",
            format!("{RADIANCE_EXPONENT_BIAS}i"),
        ),
        ("RADIANCE_LOWEST_LOG2", format!("{RADIANCE_LOWEST_LOG2}i")),
        ("RADIANCE_MAX_BITS", format!("{RADIANCE_MAX_BITS:#x}u")),
        ("GATHER_WORKGROUP", format!("{GATHER_WORKGROUP}u")),
        ("BVH_STACK", format!("{MAX_STACK}u")),
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
        ("RAY_OFFSET_MAGNITUDE", format!("{RAY_OFFSET_MAGNITUDE:e}")),
        ("RAY_OFFSET_SCALE", format!("{RAY_OFFSET_SCALE:e}")),
        (
            "EDGE_TOLERANCE",
            format!("{:e}", prt_format::EDGE_TOLERANCE),
        ),
        ("MIN_DISTANCE_SQ", format!("{MIN_DISTANCE_SQ:e}")),
        ("BRICK_BACKFACE", format!("{BRICK_BACKFACE}u")),
        (
            "PACKED_BACKFACE",
            format!("{}u", prt_format::surfel::PACKED_BACKFACE),
        ),
        (
            "PACKED_POSITION_STEP",
            format!("{:e}", 1.0 / prt_format::surfel::POSITION_STEPS),
        ),
        (
            "RGB9E5_EXPONENT_OFFSET",
            format!("{}u", prt_format::surfel::RGB9E5_EXPONENT_OFFSET),
        ),
        (
            "NEAR_WEIGHT_BITS",
            format!("{}u", prt_format::surface::NEAR_WEIGHT_BITS),
        ),
        ("PROBE_VALID", format!("{PROBE_VALID}u")),
        ("PROBE_NONE", format!("{}u", u32::MAX)),
        (
            "FILL_LEVEL_SHIFT",
            format!("{}u", prt_format::FILL_LEVEL_SHIFT),
        ),
        (
            "FILL_LEVEL_MASK",
            format!("{}u", prt_format::FILL_LEVEL_MASK),
        ),
        (
            "FILL_HIDDEN_SHIFT",
            format!("{}u", prt_format::FILL_HIDDEN_SHIFT),
        ),
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
        ("SH_Y00", format!("{Y00:?}")),
        ("SH_Y1", format!("{Y1:?}")),
        ("SH_Y2_OFF", format!("{Y2_OFF:?}")),
        ("SH_Y20", format!("{Y20:?}")),
        ("SH_Y22", format!("{Y22:?}")),
    ]
    .into_iter()
    .chain(packed_factor_constants())
    .collect()
}

/// The fields of a packed factor slot (`prt_format::FactorSlot`) as `shaders/gather.wgsl`
/// decodes them: each SH term's range, bits and first bit in a continuation, the offsets'
/// bits, where a lobe's `R` and `A_2` sit and their top codes, and the full head's bit.
fn packed_factor_constants() -> [(&'static str, String); 9] {
    let array = |ty: &str, v: Vec<String>| format!("array<{ty}, {}>({})", v.len(), v.join(", "));
    [
        (
            "SH_RANGE",
            array(
                "f32",
                prt_format::SH_RANGE.map(|r| format!("{r:?}")).to_vec(),
            ),
        ),
        (
            "SH_BITS",
            array("u32", prt_format::SH_BITS.map(|b| format!("{b}u")).to_vec()),
        ),
        (
            "TERMS_AT",
            array(
                "u32",
                prt_format::TERMS_AT.map(|b| format!("{b}u")).to_vec(),
            ),
        ),
        ("OFFSET_BITS", format!("{}u", prt_format::OFFSET_BITS)),
        ("R_AT", format!("{}u", prt_format::R_AT)),
        ("R_TOP", format!("{}u", prt_format::lobe::R_TOP)),
        ("SLOT_FULL", format!("{}u", prt_format::SLOT_FULL)),
        ("A2_AT", format!("{}u", prt_format::A2_AT)),
        ("A2_TOP", format!("{}u", prt_format::lobe::A2_TOP)),
    ]
}

/// Size in u32 words of one factor of each precision (of u8 tables, one slot).
pub fn factor_words(precision: TransferPrecision) -> u32 {
    let bytes = match precision {
        TransferPrecision::F32 => std::mem::size_of::<prt_format::FactorF32>(),
        TransferPrecision::F16 => std::mem::size_of::<prt_format::FactorF16>(),
        TransferPrecision::U8 => std::mem::size_of::<prt_format::FactorSlot>(),
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

// The engine-side sampling snippet (`shaders/sample_irradiance.wgsl`) and its CPU twin.

/// Summed validity at or below which the sample is empty (as in the shader).
pub const MIN_VALIDITY: f32 = 1e-6;
/// Floor of the Chebyshev term (the probe's chance to see the point): a point that no probe sees still gets the least
/// occluded probes' light rather than nothing.
pub const MIN_CHEBYSHEV: f32 = 1e-5;
/// Spacings behind the surface's plane over which the facing term falls from 1 to its floor:
/// `clamp(1 + h / FACING_DEPTH, 0, 1)^2 + FACING_FLOOR`, `h` being the probe's signed distance
/// from the plane through the (unmoved) surface point, in spacings. Every probe in front of the
/// plane counts fully, however grazing: with probes on the bounds' faces, the layer just off a
/// wall (0.05 spacings in front, up to a step aside) sees what the wall sees, and DDGI's
/// angular term `((n . dir + 1) / 2)^2` gave it a quarter of the weight of the layer a step
/// inside. Measured (`prt-bench surface`, normal bias 0.2): Cornell mean error 5.6% with the
/// angular term, 4.0% with this one; two rooms at half spacing 6.1% and 4.6%, no leaks with either.
pub const FACING_DEPTH: f32 = 0.25;
/// Floor of the facing term: probes behind the surface's plane count less, not zero (a point
/// whose probes are all behind it still gets light). DDGI uses 0.2; prt's rooms are up to 500
/// times brighter than their neighbours (two rooms sharing a wall), where even 0.02 of a probe
/// behind the wall leaked at half spacing (7 of 300 points, normal bias 0.1, angular facing
/// term), so the floor is 0.002.
pub const FACING_FLOOR: f32 = 0.002;
/// Floor of the depth variance, in spacings squared (a perfectly flat hit distribution would
/// make the test a hard step).
pub const MIN_VARIANCE: f32 = 1e-4;
/// Distance in spacings below which a point counts as at the probe (visible).
pub const MIN_DISTANCE: f32 = 1e-4;

/// A Chebyshev term below this is crushed towards zero (DDGI's crush threshold): a probe that sees the
/// point only partly is most likely on the far side of a thin wall, and a room 500 times
/// brighter than the point leaks visibly even at a weight of 1/1000.
pub const CRUSH_THRESHOLD: f32 = 0.2;

/// `array<ty, N>(items...)` as WGSL source text.
fn wgsl_array(ty: &str, items: &[String]) -> String {
    format!("array<{ty}, {}>({})", items.len(), items.join(", "))
}

/// `(name, value)` of the constants the engine-side sampling snippet shares with its CPU twin
/// ([`crate::surface::SurfaceSampler`], [`crate::sample::VolumeSampler`]), as WGSL source text.
pub fn snippet_constants() -> Vec<(&'static str, String)> {
    vec![
        ("PRT_MIN_VALIDITY", format!("{MIN_VALIDITY:e}")),
        ("PRT_MIN_CHEBYSHEV", format!("{MIN_CHEBYSHEV:e}")),
        ("PRT_CRUSH_THRESHOLD", format!("{CRUSH_THRESHOLD:?}")),
        ("PRT_FACING_FLOOR", format!("{FACING_FLOOR:?}")),
        ("PRT_FACING_DEPTH", format!("{FACING_DEPTH:?}")),
        ("PRT_MIN_VARIANCE", format!("{MIN_VARIANCE:e}")),
        ("PRT_MIN_DISTANCE", format!("{MIN_DISTANCE:e}")),
        ("PRT_DEPTH_SIDE", format!("{DEPTH_MAP_SIDE}u")),
        ("PRT_DEPTH_WORDS", format!("{DEPTH_WORDS}u")),
        ("PRT_DEPTH_TOP", format!("{TOP}u")),
        ("PRT_DEPTH_MEAN_STEP", format!("{MEAN_STEP:?}")),
        ("PRT_DEPTH_DEVIATION_STEP", format!("{DEVIATION_STEP:?}")),
        ("PRT_FLAG_DEPTH_MOMENTS", format!("{VOLUME_DEPTH_MOMENTS}u")),
        ("PRT_FLAG_SURFACE", format!("{VOLUME_SURFACE}u")),
        ("PRT_NONE", format!("{}u", u32::MAX)),
        ("PRT_SLOT_AXIS_SHIFT", format!("{SLOT_AXIS_SHIFT}u")),
        ("PRT_TERMS_CENTRE_SHIFT", format!("{CENTRE_SHIFT}u")),
        ("PRT_NO_SURFEL", format!("{NO_SURFEL}u")),
        ("PRT_SIDE_BIT", format!("{SIDE_BIT}u")),
        ("PRT_TERMS_WORDS", format!("{TERMS_WORDS}u")),
        ("PRT_BRICK_WORDS", format!("{BRICK_WORDS}u")),
        ("PRT_TERMS_NORMAL_BITS", format!("{NORMAL_BITS}u")),
        ("PRT_TERMS_HITS_AT", format!("{HITS_AT}u")),
        (
            "PRT_OPEN_BITS",
            wgsl_array("u32", &OPEN_BITS.map(|v| format!("{v}u"))),
        ),
        (
            "PRT_OPEN_AT",
            wgsl_array("u32", &OPEN_AT.map(|v| format!("{v}u"))),
        ),
        (
            "PRT_OPEN_RANGE",
            wgsl_array("f32", &OPEN_RANGE.map(|v| format!("{v:?}"))),
        ),
        ("PRT_BLOCKED_WEIGHT", format!("{BLOCKED_WEIGHT:e}")),
        ("PRT_NO_SLOT", format!("{}u", prt_format::NO_SLOT)),
    ]
}
