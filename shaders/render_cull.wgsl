// Forward+ stage 2, one workgroup per screen tile (Harada et al. 2012, Olsson & Assarsson 2011):
// 1. the tile's min/max depth over its covered pixels (sky pixels are not shaded, so ignored),
//    then a 32-bin mask of the linear depths its pixels occupy between the two ("2.5D culling",
//    Harada 2012): a light in the gap between a near object and the far wall touches no pixel;
// 2. the tile's bounds in view space: the box of the eight corners of its frustum slice between
//    those depths, and the slice's four side planes;
// 3. each point or spot light (one thread per light, strided) sets its bit in a workgroup mask
//    when its bounding sphere touches the box, is inside all four side planes and overlaps an
//    occupied depth bin. The sphere is the range sphere, or for a spot of half-angle below 45
//    degrees the smaller sphere around its cone sector; lights without a range touch every tile;
// 4. the mask is compacted in light order (deterministic lists, so tiled shading sums lights in
//    the same order as brute force) into [count, index...]; lights past the tile's maximum are
//    dropped, counted in `stats` and flagged in the count word (TILE_OVERFLOW), never silently.
// Every test bounds the pixels conservatively, so a culled light's range window or cone factor is
// exactly zero at every pixel of the tile: spheres are inflated by CULL_RANGE_MARGIN against
// rounding, and by CULL_DEPTH_MARGIN of the tile's far depth against the depth buffer's
// quantisation (the tile's bounds come from stored depths, shading from interpolated positions).

// The renderer reads these declarations (render/src/bindings.rs) and binds each by its name.
@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var depth_tex: texture_depth_2d;
@group(0) @binding(3) var<storage, read_write> tile_lists: array<u32>;
@group(0) @binding(4) var<storage, read_write> stats: CullStats;

var<workgroup> depth_min: atomic<u32>;
var<workgroup> depth_max: atomic<u32>;
var<workgroup> depth_bins: atomic<u32>;
var<workgroup> mask: array<atomic<u32>, CULL_MASK_WORDS>;

fn view_corner(ndc: vec2<f32>, depth: f32) -> vec3<f32> {
    let v = frame.inv_proj * vec4<f32>(ndc, depth, 1.0);
    return v.xyz / v.w;
}

// Distance in front of the eye of a depth-buffer value.
fn linear_depth(depth: f32) -> f32 {
    let v = frame.inv_proj * vec4<f32>(0.0, 0.0, depth, 1.0);
    return -v.z / v.w;
}

struct TileBounds {
    bmin: vec3<f32>,
    bmax: vec3<f32>,
    planes: array<vec3<f32>, 4>,
    near: f32,
    far: f32,
}

// Centre (xyz) and radius (w) of a light's bounding sphere in view space.
fn light_sphere(light: Light) -> vec4<f32> {
    var centre = light.position;
    var radius = light.range;
    if light.kind == LIGHT_SPOT && light.cos_outer > SPOT_SPHERE_COS {
        // Sphere through the apex around the sector {d <= range, angle <= outer}.
        radius = light.range / (2.0 * light.cos_outer);
        centre = light.position + light.direction * radius;
    }
    return vec4<f32>((frame.view * vec4<f32>(centre, 1.0)).xyz, radius * CULL_RANGE_MARGIN);
}

fn bin_of(z: f32, near: f32, far: f32) -> u32 {
    let t = (z - near) / max(far - near, 1e-30);
    let bins = f32(CULL_DEPTH_BINS);
    return u32(clamp(t * bins, 0.0, bins - 1.0));
}

fn touches(light: Light, b: TileBounds, bins: u32) -> bool {
    if max(max(light.radiant.x, light.radiant.y), light.radiant.z) <= 0.0 {
        return false;
    }
    if light.range >= UNBOUNDED_RANGE {
        return true;
    }
    let s = light_sphere(light);
    let c = s.xyz;
    // The sphere grows by the depth-quantisation margin of the tile (layout.rs).
    let r = s.w + CULL_DEPTH_MARGIN * b.far;
    let nearest = clamp(c, b.bmin, b.bmax);
    if dot(c - nearest, c - nearest) > r * r {
        return false;
    }
    for (var i = 0u; i < 4u; i = i + 1u) {
        if dot(b.planes[i], c) < -r {
            return false;
        }
    }
    let z = -c.z;
    if z + r < b.near || z - r > b.far {
        return false;
    }
    let lo = bin_of(z - r, b.near, b.far);
    let hi = bin_of(z + r, b.near, b.far);
    let span = (0xffffffffu >> (31u - (hi - lo))) << lo;
    return (span & bins) != 0u;
}

fn tile_bounds(origin: vec2<u32>, end: vec2<u32>, dmin: f32, dmax: f32) -> TileBounds {
    var b: TileBounds;
    let size = vec2<f32>(f32(frame.width), f32(frame.height));
    let ndc_lo = vec2<f32>(f32(origin.x) / size.x * 2.0 - 1.0, 1.0 - f32(end.y) / size.y * 2.0);
    let ndc_hi = vec2<f32>(f32(end.x) / size.x * 2.0 - 1.0, 1.0 - f32(origin.y) / size.y * 2.0);
    b.bmin = vec3<f32>(3.0e38);
    b.bmax = vec3<f32>(-3.0e38);
    var far: array<vec3<f32>, 4>;
    for (var c = 0u; c < 8u; c = c + 1u) {
        let ndc = vec2<f32>(select(ndc_lo.x, ndc_hi.x, (c & 1u) != 0u), select(ndc_lo.y, ndc_hi.y, (c & 2u) != 0u));
        let p = view_corner(ndc, select(dmin, dmax, (c & 4u) != 0u));
        b.bmin = min(b.bmin, p);
        b.bmax = max(b.bmax, p);
        if c >= 4u {
            far[c - 4u] = p;
        }
    }
    // Side planes through the eye, normals pointing into the tile: corners 0 (lo,lo), 1 (hi,lo),
    // 3 (hi,hi), 2 (lo,hi) go round the tile.
    let ring = array<u32, 5>(0u, 1u, 3u, 2u, 0u);
    let inside = far[0] + far[1] + far[2] + far[3];
    for (var i = 0u; i < 4u; i = i + 1u) {
        var n = normalize(cross(far[ring[i]], far[ring[i + 1u]]));
        if dot(n, inside) < 0.0 {
            n = -n;
        }
        b.planes[i] = n;
    }
    b.near = linear_depth(dmin);
    b.far = linear_depth(dmax);
    return b;
}

// One entry point over the ~80-line guide (84 lines): its numbered phases (depth bounds, then
// occupied depth bins; light bits; compaction) are separated by workgroup barriers over the
// tile's shared memory, and read top to bottom in that order.
@compute @workgroup_size(CULL_GROUP, CULL_GROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let threads = CULL_GROUP * CULL_GROUP;
    if lid == 0u {
        atomicStore(&depth_min, bitcast<u32>(1.0));
        atomicStore(&depth_max, 0u);
        atomicStore(&depth_bins, 0u);
    }
    for (var w = lid; w < CULL_MASK_WORDS; w = w + threads) {
        atomicStore(&mask[w], 0u);
    }
    workgroupBarrier();

    // 1. Depth bounds (non-negative floats order like their bits), then occupied depth bins.
    let origin = wg.xy * frame.tile;
    let end = min(origin + vec2<u32>(frame.tile), vec2<u32>(frame.width, frame.height));
    for (var y = origin.y + local.y; y < end.y; y = y + CULL_GROUP) {
        for (var x = origin.x + local.x; x < end.x; x = x + CULL_GROUP) {
            let d = textureLoad(depth_tex, vec2<u32>(x, y), 0);
            if d < 1.0 {
                atomicMin(&depth_min, bitcast<u32>(d));
                atomicMax(&depth_max, bitcast<u32>(d));
            }
        }
    }
    workgroupBarrier();
    let dmin = bitcast<f32>(atomicLoad(&depth_min));
    let dmax = bitcast<f32>(atomicLoad(&depth_max));
    let covered = dmin <= dmax;
    let b = tile_bounds(origin, end, dmin, dmax);
    if covered {
        for (var y = origin.y + local.y; y < end.y; y = y + CULL_GROUP) {
            for (var x = origin.x + local.x; x < end.x; x = x + CULL_GROUP) {
                let d = textureLoad(depth_tex, vec2<u32>(x, y), 0);
                if d < 1.0 {
                    atomicOr(&depth_bins, 1u << bin_of(linear_depth(d), b.near, b.far));
                }
            }
        }
    }
    workgroupBarrier();
    let bins = atomicLoad(&depth_bins);

    // 3. Light bits.
    if covered {
        for (var i = lid; i < frame.other_count; i = i + threads) {
            if touches(lights[i], b, bins) {
                atomicOr(&mask[i / 32u], 1u << (i % 32u));
            }
        }
    }
    workgroupBarrier();

    // 4. Compaction in light order: thread w owns mask word w.
    let tile = wg.y * frame.tiles_x + wg.x;
    let base = tile * tile_stride();
    let words = (frame.other_count + 31u) / 32u;
    var total = 0u;
    for (var w = 0u; w < words; w = w + 1u) {
        total = total + countOneBits(atomicLoad(&mask[w]));
    }
    for (var w = lid; w < words; w = w + threads) {
        var slot = 0u;
        for (var v = 0u; v < w; v = v + 1u) {
            slot = slot + countOneBits(atomicLoad(&mask[v]));
        }
        var bits = atomicLoad(&mask[w]);
        while bits != 0u && slot < frame.max_per_tile {
            let bit = firstTrailingBit(bits);
            tile_lists[base + 1u + slot] = w * 32u + bit;
            slot = slot + 1u;
            bits = bits & (bits - 1u);
        }
    }
    if lid == 0u {
        let kept = min(total, frame.max_per_tile);
        tile_lists[base] = kept | select(0u, TILE_OVERFLOW, total > kept);
        atomicAdd(&stats.listed, kept);
        if total > kept {
            atomicAdd(&stats.overflow_tiles, 1u);
            atomicAdd(&stats.dropped, total - kept);
        }
    }
}
