// Benchmark baseline for stage 6 (not used by the runtime): the prior art's integer atomic
// accumulation (CasualPRT). Each thread converts its share of the probe's SH to 16.16 fixed
// point and adds it to global accumulators with atomicAdd; after a storage barrier thread 0
// reads them back (resetting them for the next update) and stores the probe as the real gather
// does. Same accumulate() as the real gather, so only the reduction differs.

@group(2) @binding(0) var<storage, read_write> fixed_accum: array<atomic<i32>>;

const FIXED_ONE: f32 = 65536.0;

@compute @workgroup_size(GATHER_WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = workgroup_probe(wg, lid);
    if p == PROBE_NONE {
        return;
    }
    let acc = accumulate(p, lid);
    for (var k = 0u; k < 9u; k = k + 1u) {
        for (var c = 0u; c < 3u; c = c + 1u) {
            atomicAdd(&fixed_accum[27u * p + 3u * k + c], i32(round(acc[k][c] * FIXED_ONE)));
        }
    }
    storageBarrier();
    if lid == 0u {
        var total: array<vec3<f32>, 9>;
        for (var k = 0u; k < 9u; k = k + 1u) {
            for (var c = 0u; c < 3u; c = c + 1u) {
                total[k][c] = f32(atomicExchange(&fixed_accum[27u * p + 3u * k + c], 0)) / FIXED_ONE;
            }
        }
        finish(p, total);
    }
}
