// Stage 3 (multi-bounce only), one thread per surfel of a front-face brick: the irradiance of
// the current volume at the surfel, through the engine's own lookup (`sample_irradiance`, bind
// group 1: the same surface lookup at the same surface bias where the surfel has terms, the
// volume's weights and normal bias elsewhere), turned into exitant radiance albedo / pi * damping * E. Stage 4 adds it to the
// direct radiance, so each pass of the gather over the probes adds one bounce (twin of
// CpuRelighter::relight_with, bounces > 1). Every front-face brick becomes dirty.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> bricks: array<Brick>;
@group(0) @binding(2) var<storage, read> surfels: array<u32>;
@group(0) @binding(3) var<storage, read_write> surfel_bounce: array<u32>;
@group(0) @binding(4) var<storage, read_write> brick_dirty: array<u32>;
// surfels and surfel_bounce hold this chunk's surfels only (dispatched once per chunk).
@group(0) @binding(5) var<uniform> chunk: SurfelChunk;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if c >= chunk.surfel_end - chunk.surfel_begin {
        return;
    }
    let surfel = surfel_at(c);
    if (bricks[surfel.brick].flags & BRICK_BACKFACE) != 0u {
        return;
    }
    let e = sample_irradiance(surfel.position, surfel.normal);
    let l = surfel.albedo * (params.bounce_damping / PI) * e;
    // RADIANCE_WORDS a surfel, as relight_surfels.wgsl writes surfel_radiance.
    let w = encode_radiance(l);
    for (var i = 0u; i < RADIANCE_WORDS; i = i + 1u) {
        surfel_bounce[RADIANCE_WORDS * c + i] = w[i];
    }
    brick_dirty[surfel.brick] = 1u;
}
