// Stage 8 entry point without subgroup operations: a shared-memory tree reduction,
// log2(GATHER_WORKGROUP) barrier steps.

var<workgroup> partials: array<array<vec3<f32>, 9>, GATHER_WORKGROUP>;

@compute @workgroup_size(GATHER_WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = workgroup_probe(wg, lid);
    if p == PROBE_NONE {
        return;
    }
    partials[lid] = accumulate(p, lid);
    for (var stride = GATHER_WORKGROUP / 2u; stride > 0u; stride = stride / 2u) {
        workgroupBarrier();
        if lid < stride {
            for (var k = 0u; k < 9u; k = k + 1u) {
                partials[lid][k] = partials[lid][k] + partials[lid + stride][k];
            }
        }
    }
    if lid == 0u {
        finish(p, partials[0]);
    }
}
