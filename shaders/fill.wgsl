// Stage 9, one thread per grid point a coarse level fills (prt_format::tier; CPU twin
// prt_runtime::fill): after the gather, its SH is the trilinear interpolation of the points of
// its level (its flags' FILL_LEVEL_SHIFT bits) around it, each weighted by its trilinear weight
// times its validity and renormalised, written to probe_sh and, with validity 1, to its seven
// volume texels in the gather's layout. Validation guarantees that a filled point reads no
// filled point, so the threads are independent. Every recorded update runs a thread per filled
// point, but only a point with a corner this update gathered (its dirty word holds the update's
// serial) reads and writes SH: an amortised update redoes the points beside its window, and a
// point's texels follow its corners' latest gather.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> probes: array<Probe>;
@group(0) @binding(2) var<storage, read_write> probe_sh: array<vec4<f32>>;
// The filled grid points, in grid order.
@group(0) @binding(3) var<storage, read> fill_list: array<u32>;
// Per probe: 1 while it waits for a gather, else the serial of the update that last gathered it.
@group(0) @binding(4) var<storage, read> probe_dirty: array<u32>;

@group(1) @binding(0) var volume0: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(1) var volume1: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(2) var volume2: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(3) var volume3: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(4) var volume4: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(5) var volume5: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(6) var volume6: texture_storage_3d<VOLUME_FORMAT, write>;

fn fill_texel(v: vec4<f32>) -> vec4<f32> {
    return clamp(v, vec4<f32>(-params.texel_limit), vec4<f32>(params.texel_limit));
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if i >= params.fill_count {
        return;
    }
    let p = fill_list[i];
    let n = params.grid_counts;
    let ijk = vec3<u32>(p % n.x, (p / n.x) % n.y, p / (n.x * n.y));
    // prt_format::tier::span along each axis, at the point's level.
    let stride = 1u << ((probes[p].flags >> FILL_LEVEL_SHIFT) & FILL_LEVEL_MASK);
    let last = n - 1u;
    let lo = min(ijk / stride * stride, last);
    let hi = min(lo + stride, last);
    let t = vec3<f32>(ijk - lo) / vec3<f32>(max(hi - lo, vec3<u32>(1u)));
    // Only a point beside a probe this update gathered can change.
    var changed = false;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let upper = vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u);
        let at = select(lo, hi, upper);
        changed = changed || probe_dirty[at.x + n.x * (at.y + n.y * at.z)] == params.update_serial;
    }
    if !changed {
        return;
    }
    var c: array<vec3<f32>, 9>;
    var total = 0.0;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let upper = vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u);
        let w3 = select(1.0 - t, t, upper);
        let w = w3.x * w3.y * w3.z;
        let at = select(lo, hi, upper);
        let q = at.x + n.x * (at.y + n.y * at.z);
        if w <= 0.0 || (probes[q].flags & PROBE_VALID) == 0u {
            continue;
        }
        total = total + w;
        for (var k = 0u; k < 9u; k = k + 1u) {
            c[k] = c[k] + w * probe_sh[9u * q + k].xyz;
        }
    }
    if total <= 0.0 {
        return;
    }
    for (var k = 0u; k < 9u; k = k + 1u) {
        c[k] = c[k] / total;
        probe_sh[9u * p + k] = vec4<f32>(c[k], 0.0);
    }
    let at = vec3<i32>(ijk);
    textureStore(volume0, at, fill_texel(vec4<f32>(c[0], 1.0)));
    textureStore(volume1, at, fill_texel(vec4<f32>(c[1], c[2].x)));
    textureStore(volume2, at, fill_texel(vec4<f32>(c[2].yz, c[3].xy)));
    textureStore(volume3, at, fill_texel(vec4<f32>(c[3].z, c[4])));
    textureStore(volume4, at, fill_texel(vec4<f32>(c[5], c[6].x)));
    textureStore(volume5, at, fill_texel(vec4<f32>(c[6].yz, c[7].xy)));
    textureStore(volume6, at, fill_texel(vec4<f32>(c[7].z, c[8])));
}
