//! GPU-side layouts of the renderer and the constants its WGSL shares with Rust (generated into
//! every stage's source, never copied by hand). A unit test checks every struct against naga's
//! layout of its WGSL twin.

use bytemuck::{Pod, Zeroable};

/// Most point and spot lights a frame takes: the culling stage keeps one bit per light in
/// workgroup memory (`MAX_OTHER_LIGHTS / 32` words, 512 bytes).
pub const MAX_OTHER_LIGHTS: usize = 4096;
/// Most directional lights a frame takes (each is evaluated at every pixel).
pub const MAX_DIRECTIONAL_LIGHTS: usize = 64;
/// Culling threads per tile side (the workgroup is CULL_GROUP x CULL_GROUP; a tile larger than
/// this is covered by strided loops).
pub const CULL_GROUP: u32 = 16;
/// Ranges are inflated by this factor in the culling test: the view-space box of a tile comes
/// from an inverse projection whose rounding could otherwise drop a light whose window is not
/// yet zero at the very edge of its range (conservative, never lossy).
pub const CULL_RANGE_MARGIN: f32 = 1.001;
/// Depth margin of the culling tests, relative to the tile's farthest linear depth: the tile's
/// bounds come from the depth buffer (32-bit float depth with near = far / 1000 quantises view
/// depth to about 6e-5 of the far distance), while shading uses the interpolated position.
pub const CULL_DEPTH_MARGIN: f32 = 2e-4;
/// Depth bins of the 2.5D culling mask (one bit each in a u32).
pub const CULL_DEPTH_BINS: u32 = 32;
/// Spots whose outer cone is narrower than this cosine's angle (45 degrees) are bounded by the
/// sphere around their cone sector instead of their range sphere (smaller below 45 degrees).
pub const SPOT_SPHERE_COS: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// Ranges at or above this mean "no range" (the runtime stores `f32::MAX`).
pub const UNBOUNDED_RANGE: f32 = 1.0e30;
/// Bit of a tile list's count word set when the tile had more lights than its list holds.
pub const TILE_OVERFLOW: u32 = 1 << 31;
/// Words of one tile's light list, `[count, index, index, ...]`: the Rust twin of
/// `tile_stride()` in `shaders/render_types.wgsl`.
pub fn tile_list_words(max_per_tile: u32) -> u32 {
    max_per_tile + 1
}

/// `Material::base_image` / `emissive_image` of a material without that texture.
pub const NO_IMAGE: u32 = u32::MAX;

/// Sampler bits of a texture reference: wrap S (bits 0-1), wrap T (bits 2-3), nearest, UV set.
pub const WRAP_REPEAT: u32 = 0;
pub const WRAP_CLAMP: u32 = 1;
pub const WRAP_MIRROR: u32 = 2;
pub const SAMPLER_NEAREST: u32 = 1 << 4;
pub const SAMPLER_UV1: u32 = 1 << 5;

/// `Frame::flags`.
pub const FLAG_SHADOWS: u32 = 1;
pub const FLAG_TILED: u32 = 2;

/// `Frame::mode`: which terms the shading pass writes.
pub const MODE_LIT: u32 = 0;
pub const MODE_DIRECT: u32 = 1;
pub const MODE_INDIRECT: u32 = 2;
pub const MODE_ALBEDO: u32 = 3;

/// The per-frame uniform (`Frame` in `shaders/render_types.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct FrameUniform {
    pub view_proj: [[f32; 4]; 4],
    pub view: [[f32; 4]; 4],
    pub inv_proj: [[f32; 4]; 4],
    pub eye: [f32; 3],
    pub mode: u32,
    pub width: u32,
    pub height: u32,
    pub tile: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub max_per_tile: u32,
    pub other_count: u32,
    pub directional_count: u32,
    pub flags: u32,
    /// The scene's length scale for shadow-ray offsets (the asset's probe spacing).
    pub ray_scale: f32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<FrameUniform>() == 256);

/// Culling counters (`CullStats`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct CullStats {
    /// Tiles that had more lights than the per-tile maximum.
    pub overflow_tiles: u32,
    /// Light entries dropped from those tiles.
    pub dropped: u32,
    /// Light entries listed over all tiles.
    pub listed: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<CullStats>() == 16);

/// One vertex of the flat-shaded, non-indexed triangle list.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Vertex {
    pub position: [f32; 3],
    pub material: u32,
    /// The triangle's geometric normal (the bake's reference normal, docs/conventions.md section 4).
    pub normal: [f32; 3],
    pub _pad: u32,
    pub uv0: [f32; 2],
    pub uv1: [f32; 2],
    pub color: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Vertex>() == 64);

/// A material as the shading pass reads it (`Material`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuMaterial {
    pub base_color: [f32; 3],
    pub flags: u32,
    pub emissive: [f32; 3],
    pub base_image: u32,
    pub base_sampler: u32,
    pub emissive_image: u32,
    pub emissive_sampler: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuMaterial>() == 48);

/// Where an image's RGBA8 texels start in the texel buffer (`ImageInfo`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct ImageInfo {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<ImageInfo>() == 16);

/// `const NAME = value;` for every constant above, for the WGSL prelude.
pub fn wgsl_constants() -> String {
    let consts = [
        ("CULL_GROUP", format!("{CULL_GROUP}u")),
        (
            "CULL_MASK_WORDS",
            format!("{}u", MAX_OTHER_LIGHTS.div_ceil(32)),
        ),
        ("CULL_RANGE_MARGIN", format!("{CULL_RANGE_MARGIN:?}")),
        ("CULL_DEPTH_MARGIN", format!("{CULL_DEPTH_MARGIN:?}")),
        ("CULL_DEPTH_BINS", format!("{CULL_DEPTH_BINS}u")),
        ("SPOT_SPHERE_COS", format!("{SPOT_SPHERE_COS:?}")),
        ("TILE_OVERFLOW", format!("{TILE_OVERFLOW}u")),
        ("UNBOUNDED_RANGE", format!("{UNBOUNDED_RANGE:e}")),
        ("NO_IMAGE", format!("{NO_IMAGE}u")),
        ("WRAP_CLAMP", format!("{WRAP_CLAMP}u")),
        ("WRAP_MIRROR", format!("{WRAP_MIRROR}u")),
        ("SAMPLER_NEAREST", format!("{SAMPLER_NEAREST}u")),
        ("SAMPLER_UV1", format!("{SAMPLER_UV1}u")),
        ("FLAG_SHADOWS", format!("{FLAG_SHADOWS}u")),
        ("FLAG_TILED", format!("{FLAG_TILED}u")),
        ("MODE_LIT", format!("{MODE_LIT}u")),
        ("MODE_DIRECT", format!("{MODE_DIRECT}u")),
        ("MODE_INDIRECT", format!("{MODE_INDIRECT}u")),
        ("MODE_ALBEDO", format!("{MODE_ALBEDO}u")),
    ];
    consts
        .iter()
        .map(|(n, v)| format!("const {n} = {v};\n"))
        .collect()
}
