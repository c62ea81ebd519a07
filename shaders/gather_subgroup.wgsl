// Stage 8 entry point where the adapter has subgroup operations: subgroupAdd reduces within a
// subgroup, one partial per subgroup goes to workgroup memory, thread 0 adds the partials.
// (Workgroup barriers are slow on lavapipe; subgroup adds are 10-20x faster.)

var<workgroup> partials: array<array<vec3<f32>, 9>, GATHER_WORKGROUP>;

@compute @workgroup_size(GATHER_WORKGROUP)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_id) subgroup: u32,
    @builtin(num_subgroups) subgroups: u32,
) {
    let p = workgroup_probe(wg, lid);
    if p == PROBE_NONE {
        return;
    }
    let acc = accumulate(p, lid);
    var sum: array<vec3<f32>, 9>;
    for (var k = 0u; k < 9u; k = k + 1u) {
        sum[k] = subgroupAdd(acc[k]);
    }
    if lane == 0u {
        partials[subgroup] = sum;
    }
    workgroupBarrier();
    if lid == 0u {
        var total: array<vec3<f32>, 9>;
        for (var s = 0u; s < subgroups; s = s + 1u) {
            for (var k = 0u; k < 9u; k = k + 1u) {
                total[k] = total[k] + partials[s][k];
            }
        }
        finish(p, total);
    }
}
