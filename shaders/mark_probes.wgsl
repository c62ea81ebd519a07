// Stage 7, one thread per probe: a valid probe must be re-gathered when one of its factors'
// bricks was relit, or when every probe is dirty (sky change, first update, a bounce, a fixed
// bounce count restarting). The flag persists
// until the probe's turn in the amortised round robin comes (stage 8 clears it). Dispatched once
// per factor chunk; each dispatch handles the chunk's probes.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> probes: array<Probe>;
@group(0) @binding(2) var<storage, read> factors: array<u32>;
@group(0) @binding(3) var<storage, read> brick_dirty: array<u32>;
@group(0) @binding(4) var<storage, read_write> probe_dirty: array<u32>;
@group(0) @binding(5) var<uniform> chunk: FactorChunk;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if p >= params.probe_count || p < chunk.probe_begin || p >= chunk.probe_end {
        return;
    }
    let probe = probes[p];
    if (probe.flags & PROBE_VALID) == 0u {
        return;
    }
    var dirty = params.all_probes_dirty != 0u;
    for (var f = probe.first_factor; f < probe.first_factor + probe.factor_count && !dirty; f = f + 1u) {
        let word = factors[(f - chunk.first_factor) * FACTOR_WORDS];
        // A packed table's continuation slot (no rays) names no brick (prt_format::FactorSlot).
        if FACTOR_FORMAT == FACTOR_U8 && (word & 0xffu) == 0u {
            continue;
        }
        dirty = brick_dirty[select(word, word >> 8u, FACTOR_FORMAT == FACTOR_U8)] != 0u;
    }
    if dirty {
        probe_dirty[p] = 1u;
    }
}
