// Stage 9, one thread per grid point a coarse level fills (prt_format::tier; CPU twin
// prt_runtime::fill): after the gather, its SH is the trilinear interpolation of the points of
// its level (its flags' FILL_LEVEL_SHIFT bits) around it, each weighted by its trilinear weight
// times its validity and renormalised (corners in its FILL_HIDDEN_SHIFT bits left out: the bake
// found a wall between them and the point), written to its seven texels as the gather writes a
// probe's (store_texels in store_probe.wgsl, validity 1). probe_sh has no entry for it
// (prt_runtime::contract::probe_sh_entry: the CPU fills it from its corners on readback).
// Validation guarantees that a filled point reads no filled point, so the threads are
// independent. Every recorded update runs a thread per filled point, but only a point with a
// corner this update gathered (its dirty word holds the update's serial) reads and writes SH:
// an amortised update redoes the points beside its window, and a point's texels follow its
// corners' latest gather.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> probes: array<Probe>;
// Read only here, but read_write: store_probe.wgsl, included whole, has store_probe(), which
// writes it, and naga validates every function.
@group(0) @binding(2) var<storage, read_write> probe_sh: array<f32>;
// The filled grid points, in grid order.
@group(0) @binding(3) var<storage, read> fill_list: array<u32>;
// Per probe: 1 while it waits for a gather, else the serial of the update that last gathered it.
@group(0) @binding(4) var<storage, read> probe_dirty: array<u32>;

// Corner `corner` of a cell takes the upper end along axis a when bit a is set
// (prt_format::tier::corners' order).
fn corner_upper(corner: u32) -> vec3<bool> {
    return vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u);
}

// Grid index of grid point `at` (prt_format::Grid::index).
fn grid_index(at: vec3<u32>) -> u32 {
    let n = params.grid_counts;
    return at.x + n.x * (at.y + n.y * at.z);
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
        let q = grid_index(select(lo, hi, corner_upper(corner)));
        changed = changed || probe_dirty[q] == params.update_serial;
    }
    if !changed {
        return;
    }
    var c: array<vec3<f32>, 9>;
    var total = 0.0;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let upper = corner_upper(corner);
        let w3 = select(1.0 - t, t, upper);
        let w = w3.x * w3.y * w3.z;
        let q = grid_index(select(lo, hi, upper));
        let hidden = (((probes[p].flags >> FILL_HIDDEN_SHIFT) >> corner) & 1u) != 0u;
        if w <= 0.0 || hidden || (probes[q].flags & PROBE_VALID) == 0u {
            continue;
        }
        total = total + w;
        for (var k = 0u; k < 9u; k = k + 1u) {
            // A corner is a valid probe: its entry is its slot (store_probe.wgsl).
            let at = PROBE_SH_FLOATS * probes[q].slot + 3u * k;
            c[k] = c[k] + w * vec3<f32>(probe_sh[at], probe_sh[at + 1u], probe_sh[at + 2u]);
        }
    }
    if total <= 0.0 {
        return;
    }
    for (var k = 0u; k < 9u; k = k + 1u) {
        c[k] = c[k] / total;
    }
    store_texels(p, c);
}
