// Stage 6, one thread per near group of the surface lookup: what its surfels' near-field rays
// bring, the weighted sum of the radiance of the groups they hit (stage 4's group radiance;
// twin of prt_runtime::surface::near_radiance). The sampling snippet reads it as prt_near.

@group(0) @binding(0) var<uniform> params: Params;
// Group count, per group its first entry (in this array) and entry count, then the entries:
// the group hit above NEAR_WEIGHT_BITS, its weight in 255ths below.
@group(0) @binding(1) var<storage, read> surface_near: array<u32>;
@group(0) @binding(2) var<storage, read> group_radiance: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> near_radiance: array<vec4<f32>>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let g = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if g >= surface_near[0] {
        return;
    }
    let first = surface_near[1u + 2u * g];
    let unit = f32((1u << NEAR_WEIGHT_BITS) - 1u);
    var sum = vec3<f32>(0.0);
    for (var e = first; e < first + surface_near[2u + 2u * g]; e = e + 1u) {
        let entry = surface_near[e];
        let w = f32(entry & ((1u << NEAR_WEIGHT_BITS) - 1u)) / unit;
        sum = sum + w * group_radiance[entry >> NEAR_WEIGHT_BITS].xyz;
    }
    near_radiance[g] = vec4<f32>(sum, 0.0);
}
