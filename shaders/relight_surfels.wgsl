// Stage 2, one thread per surfel of a front-face brick. For a dirty brick: direct irradiance
// from every light in the brick's mask, shadowed by an any-hit ray through the BVH, then the
// surfel's exitant radiance emission + albedo / pi * E (twin of CpuRelighter::direct_irradiance).
// Shadow rays are cached per (surfel, reaching light) pair, one bit each in this update's half
// of the shadow-ray cache (stage 1 placed the brick there), and traced again only for lights that
// moved, lights new to the brick, and bricks left uncached. For a brick that is not dirty the
// bits only move from the other half (its mask did not change, so neither did their layout).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> surfels: array<u32>;
@group(0) @binding(3) var<storage, read> bricks: array<Brick>;
@group(0) @binding(4) var<storage, read> brick_lights: array<u32>;
@group(0) @binding(5) var<storage, read> brick_dirty: array<u32>;
@group(0) @binding(6) var<storage, read> brick_cache: array<u32>;
@group(0) @binding(7) var<storage, read_write> shadow_cache: array<u32>;
@group(0) @binding(8) var<storage, read> light_changes: array<u32>;
@group(0) @binding(9) var<storage, read_write> surfel_radiance: array<u32>;
@group(0) @binding(10) var<storage, read_write> counters: Counters;
// surfels and surfel_radiance hold this chunk's surfels only (dispatched once per chunk).
@group(0) @binding(11) var<uniform> chunk: SurfelChunk;

// One entry point over the ~80-line guide (89 lines): the walk over the brick's light mask
// carries the surfel's irradiance, its shadow-ray count, the cache word and its bit ranks from
// light to light; it reads top to bottom as the CPU twin does.
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if c >= chunk.surfel_end - chunk.surfel_begin {
        return;
    }
    let s = chunk.surfel_begin + c;
    let surfel = surfel_at(c);
    let b = surfel.brick;
    let brick = bricks[b];
    if (brick.flags & BRICK_BACKFACE) != 0u {
        return;
    }
    let local = s - brick.first_surfel;
    let base = b * MASK_STRIDE;
    let prev = params.brick_count * MASK_STRIDE + base;
    var n_new = 0u;
    var n_old = 0u;
    for (var w = 0u; w < params.light_words; w = w + 1u) {
        n_new = n_new + countOneBits(brick_lights[base + w]);
        n_old = n_old + countOneBits(brick_lights[prev + w]);
    }
    let new_words = (n_new + 31u) / 32u;
    let old_words = (n_old + 31u) / 32u;
    let new_at = brick_cache[2u * b + params.cache_parity];
    let old_at = brick_cache[2u * b + 1u - params.cache_parity];
    let new_first = new_at + local * new_words;
    let old_first = old_at + local * old_words;
    if brick_dirty[b] == 0u {
        if new_at != NO_CACHE && old_at != NO_CACHE {
            for (var w = 0u; w < new_words; w = w + 1u) {
                shadow_cache[new_first + w] = shadow_cache[old_first + w];
            }
        }
        return;
    }
    var e = vec3<f32>(0.0);
    var rays = 0u;
    var rank_new = 0u;
    var rank_old = 0u;
    var word = 0u;
    for (var w = 0u; w < params.light_words; w = w + 1u) {
        var bits = brick_lights[base + w];
        let old_bits = brick_lights[prev + w];
        let moved_bits = light_changes[w];
        while bits != 0u {
            let t = firstTrailingBit(bits);
            let bit = 1u << t;
            bits = bits & ~bit;
            let i = w * 32u + t;
            // The light's slot among the brick's previous lights, if it was one.
            let r_old = rank_old + countOneBits(old_bits & (bit - 1u));
            let cached = (old_bits & bit) != 0u && (moved_bits & bit) == 0u && old_at != NO_CACHE;
            let ls = light_sample(lights[i], surfel.position, surfel.normal, params.surfel_spread_sq);
            var unshadowed = false;
            if cached {
                unshadowed = ((shadow_cache[old_first + r_old / 32u] >> (r_old % 32u)) & 1u) != 0u;
            } else if max(max(ls.irradiance.x, ls.irradiance.y), ls.irradiance.z) > 0.0 {
                let off = ray_offset(surfel.position, params.ray_scale);
                let o = surfel.position + surfel.normal * off;
                var tmax = INFINITE_DISTANCE;
                if lights[i].kind != LIGHT_DIRECTIONAL {
                    tmax = length(lights[i].position - o) - off;
                }
                rays = rays + 1u;
                unshadowed = !occluded(o, ls.to_light, tmax);
            }
            if unshadowed {
                e = e + ls.irradiance;
                word = word | (1u << (rank_new % 32u));
            }
            rank_new = rank_new + 1u;
            if rank_new % 32u == 0u {
                if new_at != NO_CACHE {
                    shadow_cache[new_first + rank_new / 32u - 1u] = word;
                }
                word = 0u;
            }
        }
        rank_old = rank_old + countOneBits(old_bits);
    }
    if rank_new % 32u != 0u && new_at != NO_CACHE {
        shadow_cache[new_first + rank_new / 32u] = word;
    }
    let l = surfel.emission + surfel.albedo * (1.0 / PI) * e;
    // RADIANCE_WORDS a surfel (encode_radiance, types.wgsl).
    let w = encode_radiance(l);
    for (var i = 0u; i < RADIANCE_WORDS; i = i + 1u) {
        surfel_radiance[RADIANCE_WORDS * c + i] = w[i];
    }
    atomicAdd(&counters.surfels_relit, 1u);
    if rays > 0u {
        atomicAdd(&counters.shadow_rays, rays);
    }
}
