// Shared by every prt compute stage: the GPU twins of the Rust structs (prt_format::asset and
// prt_runtime::contract; a unit test checks that sizes and offsets agree) and the functions
// whose CPU reference lives in prt_runtime::relight. Constants such as
// MASK_STRIDE, NO_CACHE, WORKGROUP and the flag bits are injected from Rust before this file.

struct Probe {
    position: vec3<f32>,
    flags: u32,
    first_factor: u32,
    factor_count: u32,
    sky_rays: u32,
    // Where its sky mask, sky transfer and visibility map sit (prt_format::Probe::slot).
    slot: u32,
}

struct Brick {
    bmin: vec3<f32>,
    first_surfel: u32,
    bmax: vec3<f32>,
    surfel_count: u32,
    centroid: vec3<f32>,
    flags: u32,
}

// A coarse brick over bricks, for far hits (prt_format::coarse): indexed after the bricks.
struct CoarseBrick {
    first_child: u32,
    child_count: u32,
    weight: f32,
    level: u32,
    centroid: vec3<f32>,
    pad0: u32,
    // 2^level (C + eps I)^-1, symmetric: xx, xy, xz, yy, yz, zz.
    inverse: array<f32, 6>,
    pad1: u32,
    pad2: u32,
}

// A brick's weight and regularised position moment, for the coarse bricks over it.
struct BrickMoments {
    weight: f32,
    moment: array<f32, 6>,
    pad: u32,
}

// m x for a symmetric 3x3 matrix stored as xx, xy, xz, yy, yz, zz.
fn symmetric_times(m: array<f32, 6>, x: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        m[0] * x.x + m[1] * x.y + m[2] * x.z,
        m[1] * x.x + m[3] * x.y + m[4] * x.z,
        m[2] * x.x + m[4] * x.y + m[5] * x.z,
    );
}

struct Surfel {
    position: vec3<f32>,
    brick: u32,
    normal: vec3<f32>,
    weight: f32,
    albedo: vec3<f32>,
    flags: u32,
    emission: vec3<f32>,
    pad0: u32,
    gradient: vec3<f32>,
    pad1: u32,
}

struct BvhNode {
    bmin: vec3<f32>,
    count: u32,
    bmax: vec3<f32>,
    first: u32,
}

struct Triangle {
    v0: vec3<f32>,
    pad0: u32,
    v1: vec3<f32>,
    pad1: u32,
    v2: vec3<f32>,
    pad2: u32,
}

struct Light {
    position: vec3<f32>,
    kind: u32,
    direction: vec3<f32>,
    inv_range_sq: f32,
    radiant: vec3<f32>,
    cos_outer: f32,
    cone_scale: f32,
    range: f32,
    pad0: u32,
    pad1: u32,
}

// One binding's worth of factor tables: probes probe_begin..probe_end, whose factors start at
// first_factor (factor f of the asset is element f - first_factor of the chunk's buffer).
struct FactorChunk {
    first_factor: u32,
    probe_begin: u32,
    probe_end: u32,
    pad0: u32,
}

// Whole bricks brick_begin..brick_end and their surfels surfel_begin..surfel_end: the slice of
// the surfel arrays bound to this dispatch (indexed from surfel_begin).
struct SurfelChunk {
    brick_begin: u32,
    brick_end: u32,
    surfel_begin: u32,
    surfel_end: u32,
}

struct NormalBounds {
    nmin: vec3<f32>,
    pad0: u32,
    nmax: vec3<f32>,
    pad1: u32,
}

struct Counters {
    bricks_relit: atomic<u32>,
    surfels_relit: atomic<u32>,
    shadow_rays: atomic<u32>,
    probes_gathered: atomic<u32>,
    probes_clamped: atomic<u32>,
    // Light-brick reach tests of stage 1 (changed lights x front-face bricks).
    light_tests: atomic<u32>,
    // Shadow-ray cache words handed out this update (stage 1).
    shadow_cache_words: atomic<u32>,
    // Bricks with lights left out of the shadow-ray cache (it was full).
    bricks_uncached: atomic<u32>,
}

struct Params {
    probe_count: u32,
    brick_count: u32,
    // 1 when every front-face brick's radiance is rebuilt (a fixed bounce count restarts: the
    // bounce light is cleared), whether or not a light reaches it.
    all_radiance_dirty: u32,
    ray_count: u32,
    light_count: u32,
    // Lights whose parameters changed since the last update: their indices follow the moved
    // lights' bitset (MASK_STRIDE words) in light_changes.
    changed_count: u32,
    // 0: black, 1: constant (sky_color), 2: per-direction radiance in sky_radiance.
    sky_mode: u32,
    // 1 when every valid probe must be re-gathered (sky changed, first update, a bounce, a fixed
    // bounce count restarting).
    all_probes_dirty: u32,
    sky_color: vec3<f32>,
    // Solid angle of one lattice direction, 4 pi / N.
    ray_weight: f32,
    grid_counts: vec3<u32>,
    window_start: u32,
    window_count: u32,
    // Largest magnitude a texel may hold (65504 for half-float textures).
    texel_limit: f32,
    // Workgroups along x of 2D dispatches (linear index = x + y * dispatch_width).
    dispatch_width: u32,
    // Words of the light masks in use: ceil(max(previous, current light count) / 32), at most
    // MASK_STRIDE (the previous count clears removed lights' bits and counts old masks in full).
    light_words: u32,
    // Metres per unit of packed factor offsets (FACTOR_U8 only).
    offset_scale: f32,
    // 1 on the first update: every brick is relit (emissive bricks no light reaches too).
    all_bricks_dirty: u32,
    // The scene's length scale for shadow-ray offsets (ray_offset): the probe spacing.
    ray_scale: f32,
    // Scales the fed-back bounce light (RuntimeSettings::bounces): 1 for fixed bounce counts.
    bounce_damping: f32,
    // This update's half of the shadow-ray cache (0 or 1), and the words in each half.
    cache_parity: u32,
    cache_capacity: u32,
    // Coarse bricks (prt_format::coarse), numbered after the brick_count bricks.
    coarse_count: u32,
    // What a surfel's inverse square is softened by (prt_runtime::lights::surfel_spread_sq).
    surfel_spread_sq: f32,
    // Probes the gather visits (gather_list: the valid ones); its window wraps around them.
    gather_count: u32,
    // Grid points the coarse levels fill (fill_list, prt_format::tier).
    fill_count: u32,
    // This update's number: the gather leaves it in the dirty word of each probe it gathers.
    update_serial: u32,
    _pad: u32,
}

const PI: f32 = 3.14159265358979;

// A surfel's radiance as one word: Ward's shared-exponent RGBE, three 8-bit mantissas (red from
// bit 0) and the exponent byte at bit 24, whose bits << 23 are the mantissas' step. Exact
// arithmetic, so it gives the word of its twin prt_runtime::radiance_word::pack_radiance
// (which says why, and what it keeps; the RADIANCE_ constants are its) for any finite colour.
// 2^(8 - e): the reciprocal of the step of exponent byte e + RADIANCE_EXPONENT_BIAS.
fn radiance_scale(e: i32) -> f32 {
    return bitcast<f32>(u32(254 - (e + RADIANCE_EXPONENT_BIAS)) << 23u);
}

fn pack_radiance(rgb: vec3<f32>) -> u32 {
    let top = vec3<f32>(bitcast<f32>(RADIANCE_MAX_BITS));
    let c = select(vec3<f32>(0.0), min(rgb, top), rgb > vec3<f32>(0.0));
    let largest = max(max(c.x, c.y), c.z);
    // Below the smallest normal float (its bits 0x00800000): black.
    if largest < bitcast<f32>(0x00800000u) {
        return 0u;
    }
    var e = max(i32(bitcast<u32>(largest) >> 23u) - 127, RADIANCE_LOWEST_LOG2) + 1;
    if round(largest * radiance_scale(e)) >= 256.0 {
        e = e + 1;
    }
    let m = vec3<u32>(round(c * radiance_scale(e)));
    return m.x | (m.y << 8u) | (m.z << 16u) | (u32(e + RADIANCE_EXPONENT_BIAS) << 24u);
}

fn unpack_radiance(w: u32) -> vec3<f32> {
    let step = bitcast<f32>((w >> 24u) << 23u);
    return vec3<f32>(vec3<u32>(w & 255u, (w >> 8u) & 255u, (w >> 16u) & 255u)) * step;
}

// A surfel's radiance as the RADIANCE_WORDS words the radiance buffers keep per surfel
// (prt_runtime::radiance_word::words_per_surfel): a radiance word for packed surfels, three
// f32 for the exact preset's f32 surfels (the unused words zero).
fn encode_radiance(l: vec3<f32>) -> vec3<u32> {
    if RADIANCE_WORDS == 1u {
        return vec3<u32>(pack_radiance(l), 0u, 0u);
    }
    return bitcast<vec3<u32>>(l);
}

fn decode_radiance(w: vec3<u32>) -> vec3<f32> {
    if RADIANCE_WORDS == 1u {
        return unpack_radiance(w.x);
    }
    return bitcast<vec3<f32>>(w);
}

// Real SH up to L2, docs/conventions.md section 2.
fn sh_basis(d: vec3<f32>) -> array<f32, 9> {
    return array<f32, 9>(
        SH_Y00,
        SH_Y1 * d.y,
        SH_Y1 * d.z,
        SH_Y1 * d.x,
        SH_Y2_OFF * d.x * d.y,
        SH_Y2_OFF * d.y * d.z,
        SH_Y20 * (3.0 * d.z * d.z - 1.0),
        SH_Y2_OFF * d.x * d.z,
        SH_Y22 * (d.x * d.x - d.y * d.y),
    );
}

// Linear index of a 2D dispatch.
fn linear_index(wg: vec3<u32>, lid: u32, size: u32, width: u32) -> u32 {
    return (wg.x + wg.y * width) * size + lid;
}
