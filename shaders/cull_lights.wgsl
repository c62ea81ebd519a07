// Stage 1, one thread per brick: which lights can reach the brick (range, cone and facing tests
// in world space against the brick's bounds and normal bounds, twin of PreparedLight::cull), and
// whether a changed light reaches it now or reached it before (then the brick must be relit; on
// the first update every brick is, so that emissive bricks no light reaches get their radiance).
// Back-face bricks are black: they cost nothing and are never dirty.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> bricks: array<Brick>;
@group(0) @binding(3) var<storage, read> normal_bounds: array<NormalBounds>;
@group(0) @binding(4) var<storage, read_write> brick_light_mask: array<u32>;
@group(0) @binding(5) var<storage, read_write> brick_dirty: array<u32>;
@group(0) @binding(6) var<storage, read_write> counters: Counters;

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
    var mask = 0u;
    for (var i = 0u; i < params.light_count; i = i + 1u) {
        if reaches(lights[i], brick, normal_bounds[b]) {
            mask = mask | (1u << i);
        }
    }
    let old = brick_light_mask[b];
    brick_light_mask[b] = mask;
    let dirty = ((old | mask) & params.changed_lights) != 0u || params.all_bricks_dirty != 0u;
    brick_dirty[b] = select(0u, 1u, dirty);
    if dirty {
        atomicAdd(&counters.bricks_relit, 1u);
    }
}
