// Stage 1, one thread per brick: which lights reach the brick (range, cone and facing tests
// in world space against the brick's bounds and normal bounds, twin of PreparedLight::cull),
// kept as a bit per light in the brick's light mask (MASK_STRIDE words; lights that reach no
// part of the brick cost its surfels one bit test, nothing more). Only the lights that changed
// since the last update are tested again (light_changes: the moved bitset, then the changed
// indices), so moving one light of a thousand costs one test per brick. The brick
// is dirty (relit) when a changed light reaches it now or did before (every brick on the first
// update, so that emissive bricks no light reaches get their radiance).
//
// Each brick then takes room in this update's half of the shadow-ray cache for one bit per
// (surfel, reaching light) pair, rounded to words per surfel: the cache is sized by the pairs
// that can see each other, not by surfels x lights. Past the pool's capacity a brick is left
// uncached (NO_CACHE: its lights are traced every time it is relit; counted). Back-face bricks
// are black: they cost nothing and are never dirty.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> bricks: array<Brick>;
@group(0) @binding(3) var<storage, read> normal_bounds: array<NormalBounds>;
// Per brick MASK_STRIDE words of the current mask, then (from brick_count * MASK_STRIDE) the
// previous update's.
@group(0) @binding(4) var<storage, read_write> brick_lights: array<u32>;
@group(0) @binding(5) var<storage, read_write> brick_dirty: array<u32>;
@group(0) @binding(6) var<storage, read_write> counters: Counters;
@group(0) @binding(7) var<storage, read> light_changes: array<u32>;
// Per brick two shadow-ray cache offsets, one per half (params.cache_parity is this update's).
@group(0) @binding(8) var<storage, read_write> brick_cache: array<u32>;

// Upper bound of dot(n, v) for n in the normal box and v in the box [a, b] (per-axis interval
// arithmetic).
fn max_dot(nb: NormalBounds, a: vec3<f32>, b: vec3<f32>) -> f32 {
    let lo = min(a, b);
    let hi = max(a, b);
    let c = max(max(nb.nmin * lo, nb.nmin * hi), max(nb.nmax * lo, nb.nmax * hi));
    return c.x + c.y + c.z;
}

fn reaches(light: Light, brick: Brick, nb: NormalBounds) -> bool {
    if max(max(light.radiant.x, light.radiant.y), light.radiant.z) <= 0.0 {
        return false;
    }
    if light.kind == LIGHT_DIRECTIONAL {
        return max_dot(nb, -light.direction, -light.direction) > 0.0;
    }
    let nearest = clamp(light.position, brick.bmin, brick.bmax);
    if distance(nearest, light.position) >= light.range {
        return false;
    }
    if max_dot(nb, light.position - brick.bmax, light.position - brick.bmin) <= 0.0 {
        return false;
    }
    if light.kind == LIGHT_SPOT {
        let centre = (brick.bmin + brick.bmax) * 0.5;
        let radius = length(brick.bmax - brick.bmin) * 0.5;
        let v = centre - light.position;
        let dist = length(v);
        if dist > radius {
            let cos_axis = clamp(dot(light.direction, v) / dist, -1.0, 1.0);
            let half_angle = asin(clamp(radius / dist, -1.0, 1.0));
            if acos(cos_axis) - half_angle >= acos(clamp(light.cos_outer, -1.0, 1.0)) {
                return false;
            }
        }
    }
    return true;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let b = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if b >= params.brick_count {
        return;
    }
    let brick = bricks[b];
    if (brick.flags & BRICK_BACKFACE) != 0u {
        brick_dirty[b] = 0u;
        return;
    }
    let base = b * MASK_STRIDE;
    let prev = params.brick_count * MASK_STRIDE + base;
    // The words in use (params.light_words covers the old lights and the new).
    for (var w = 0u; w < params.light_words; w = w + 1u) {
        brick_lights[prev + w] = brick_lights[base + w];
    }
    var dirty = params.all_bricks_dirty != 0u;
    let changed_list = MASK_STRIDE;
    for (var k = 0u; k < params.changed_count; k = k + 1u) {
        let i = light_changes[changed_list + k];
        let bit = 1u << (i & 31u);
        let w = base + (i >> 5u);
        let was = (brick_lights[w] & bit) != 0u;
        let now = i < params.light_count && reaches(lights[i], brick, normal_bounds[b]);
        dirty = dirty || was || now;
        brick_lights[w] = select(brick_lights[w] & ~bit, brick_lights[w] | bit, now);
    }
    atomicAdd(&counters.light_tests, params.changed_count);
    brick_dirty[b] = select(0u, 1u, dirty);
    if dirty {
        atomicAdd(&counters.bricks_relit, 1u);
    }
    var n = 0u;
    for (var w = 0u; w < params.light_words; w = w + 1u) {
        n = n + countOneBits(brick_lights[base + w]);
    }
    // A brick uncached before and not relit now has nothing to keep: it stays uncached.
    let old = brick_cache[2u * b + 1u - params.cache_parity];
    var offset = NO_CACHE;
    if old != NO_CACHE || dirty {
        // A compare-and-swap loop, not atomicAdd: failed requests must not move the counter
        // (it would wrap past 2^32 on a huge asset and hand out overlapping room).
        let words = brick.surfel_count * ((n + 31u) / 32u);
        var at = atomicLoad(&counters.shadow_cache_words);
        loop {
            if at > params.cache_capacity || words > params.cache_capacity - at {
                break;
            }
            let r = atomicCompareExchangeWeak(&counters.shadow_cache_words, at, at + words);
            if r.exchanged {
                offset = params.cache_parity * params.cache_capacity + at;
                break;
            }
            at = r.old_value;
        }
    }
    if offset == NO_CACHE && n > 0u {
        atomicAdd(&counters.bricks_uncached, 1u);
    }
    brick_cache[2u * b + params.cache_parity] = offset;
}
