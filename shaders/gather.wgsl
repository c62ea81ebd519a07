// Stage 8, one workgroup per probe of the update window: the probe's factors (brick radiance
// evaluated at the factor's offset, times its SH9 transfer) and its sky term, summed by a
// parallel reduction (gather_subgroup.wgsl or gather_tree.wgsl, which hold the entry point).
// Threads stride over the factor table, so a probe with more factors than threads loops and
// nothing is ever dropped. Factor tables larger than one storage binding are split into chunks of
// whole probes; the window is dispatched once per chunk, and each workgroup gathers only a probe
// of its chunk. Thread 0 then writes the probe's SH to `probe_sh` and all seven volume texels
// of the probe at once (store_probe.wgsl, which holds the volume's layout and bindings).
// Invalid probes are never gathered: their texels stay zero, validity included. Dilated probes
// (inside geometry, reading a neighbour's table: their run is the neighbour's) are gathered like
// valid ones.
// Packed (u8) tables stride over 8-byte slots (prt_format::FactorSlot): a lobe factor is one,
// decoded about the direction from the probe's ray origin to its stored point
// (prt_format::lobe); a full factor is a head and a continuation, which a thread that lands on
// it skips (its ray count is zero).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> probes: array<Probe>;
@group(0) @binding(2) var<storage, read> factors: array<u32>;
@group(0) @binding(3) var<storage, read> brick_radiance: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> sky_transfer: array<f32>;
@group(0) @binding(5) var<storage, read> sky_mask: array<u32>;
// Per lattice direction: the direction (xyz), then the sky radiance (xyz).
@group(0) @binding(6) var<storage, read> sky_directions: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> probe_dirty: array<u32>;
@group(0) @binding(8) var<storage, read_write> probe_sh: array<f32>;
@group(0) @binding(9) var<storage, read_write> counters: Counters;
@group(0) @binding(10) var<uniform> chunk: FactorChunk;
// The probes the gather visits, in grid order: the valid ones (a grid point without data, or an
// invalid probe, is never gathered, so a window of the round robin spends no work on them).
@group(0) @binding(11) var<storage, read> gather_list: array<u32>;
// Per brick, then per coarse brick: the centroid (xyz) its factors' offsets are measured from,
// and their multiplier (w, 2^level) (prt_format::Asset::factor_frame).
@group(0) @binding(12) var<storage, read> factor_frames: array<vec4<f32>>;

var<workgroup> go: u32;

// The probe this workgroup gathers, or PROBE_NONE when it has nothing to do (outside the window,
// invalid, or clean). Workgroup-uniform, so the reduction's barriers stay in uniform control.
fn workgroup_probe(wg: vec3<u32>, lid: u32) -> u32 {
    let slot = wg.x + wg.y * params.dispatch_width;
    var p = PROBE_NONE;
    if slot < params.window_count {
        p = gather_list[(params.window_start + slot) % max(params.gather_count, 1u)];
    }
    if lid == 0u {
        var flag = 0u;
        if p != PROBE_NONE && p >= chunk.probe_begin && p < chunk.probe_end {
            if (probes[p].flags & PROBE_VALID) != 0u && probe_dirty[p] == 1u {
                flag = 1u;
            }
        }
        go = flag;
    }
    if workgroupUniformLoad(&go) == 0u {
        return PROBE_NONE;
    }
    return p;
}

fn factor_radiance(brick: u32, offset: vec3<f32>) -> vec3<f32> {
    let mean = brick_radiance[4u * brick].xyz;
    let g = vec3<f32>(
        dot(brick_radiance[4u * brick + 1u].xyz, offset),
        dot(brick_radiance[4u * brick + 2u].xyz, offset),
        dot(brick_radiance[4u * brick + 3u].xyz, offset),
    );
    return max(mean + g, vec3<f32>(0.0));
}

// The signed field of `w` bits at bit `p` of a packed slot's 64 bits (lo, hi), as a float
// (prt_format::FactorSlot).
fn packed_field(lo: u32, hi: u32, p: u32, w: u32) -> f32 {
    var b: u32;
    if p >= 32u {
        b = hi >> (p - 32u);
    } else if p + w <= 32u {
        b = lo >> p;
    } else {
        b = (lo >> p) | (hi << (32u - p));
    }
    return f32(extractBits(bitcast<i32>(b), 0u, w));
}

// Steps on each side of zero of a signed field of `w` bits (prt_format::levels).
fn field_levels(w: u32) -> f32 {
    return f32((1u << (w - 1u)) - 1u);
}

// Terms 1..8 of the lobe of length `r` and band-2 scale `a2` about `toward` times the DC
// term `t0`, and `t0` (prt_format::lobe::lobe_terms): band 1 `R Y_1(d) / Y_00`, band 2
// `A_2 Y_2(d) / Y_00`.
fn lobe_transfer(t0: f32, r: f32, a2: f32, toward: vec3<f32>) -> array<f32, 9> {
    var t: array<f32, 9>;
    t[0] = t0;
    let len_sq = dot(toward, toward);
    // Zero or past the f32 range: no direction (prt_format::lobe::lobe_terms).
    if len_sq > 0.0 && len_sq <= 3.4e38 {
        let y = sh_basis(toward * (1.0 / sqrt(len_sq)));
        for (var k = 1u; k < 9u; k = k + 1u) {
            t[k] = y[k] / SH_Y00 * select(a2, r, k < 4u) * t0;
        }
    }
    return t;
}

// An f16 or f32 factor's transfer and offset (its brick is its first word).
struct FloatFactor {
    t: array<f32, 9>,
    offset: vec3<f32>,
}

// The f16 or f32 factor at word `base` (prt_format::FactorF16, FactorF32).
fn float_factor(base: u32) -> FloatFactor {
    var g: FloatFactor;
    g.t[0] = f32(factors[base + 1u]) * params.ray_weight * SH_Y00;
    if FACTOR_FORMAT == FACTOR_F16 {
        for (var w = 0u; w < 4u; w = w + 1u) {
            let h = unpack2x16float(factors[base + 2u + w]);
            g.t[1u + 2u * w] = h.x;
            g.t[2u + 2u * w] = h.y;
        }
        g.offset = vec3<f32>(unpack2x16float(factors[base + 6u]), unpack2x16float(factors[base + 7u]).x);
    } else {
        for (var k = 1u; k < 9u; k = k + 1u) {
            g.t[k] = bitcast<f32>(factors[base + 1u + k]);
        }
        g.offset = vec3<f32>(
            bitcast<f32>(factors[base + 10u]),
            bitcast<f32>(factors[base + 11u]),
            bitcast<f32>(factors[base + 12u]),
        );
    }
    return g;
}

// This thread's share of the probe's SH: factors lid, lid + WORKGROUP, ... and sky rays likewise.
fn accumulate(p: u32, lid: u32) -> array<vec3<f32>, 9> {
    var acc: array<vec3<f32>, 9>;
    // The packed factors' fields (indexed at run time, so copied out of the constants once).
    var range = SH_RANGE;
    var bits = SH_BITS;
    var at = TERMS_AT;
    let probe = probes[p];
    for (var f = probe.first_factor + lid; f < probe.first_factor + probe.factor_count; f = f + GATHER_WORKGROUP) {
        let base = (f - chunk.first_factor) * FACTOR_WORDS;
        var t: array<f32, 9>;
        var brick = factors[base];
        var offset: vec3<f32>;
        if FACTOR_FORMAT == FACTOR_U8 {
            // prt_format::FactorSlot: a head (offsets, R, SLOT_FULL, A_2) or a continuation.
            let rays = brick & 0xffu;
            if rays == 0u {
                continue;
            }
            brick = brick >> 8u;
            let t0 = f32(rays) * params.ray_weight * SH_Y00;
            let head = factors[base + 1u];
            let ol = params.offset_scale / field_levels(OFFSET_BITS);
            offset = vec3<f32>(
                packed_field(head, 0u, 0u, OFFSET_BITS),
                packed_field(head, 0u, OFFSET_BITS, OFFSET_BITS),
                packed_field(head, 0u, 2u * OFFSET_BITS, OFFSET_BITS),
            ) * ol;
            if (head & SLOT_FULL) != 0u {
                // The eight terms, in the continuation slot that follows.
                let lo = factors[base + FACTOR_WORDS];
                let hi = factors[base + FACTOR_WORDS + 1u];
                t[0] = t0;
                for (var k = 1u; k < 9u; k = k + 1u) {
                    let w = bits[k - 1u];
                    t[k] = packed_field(lo, hi, at[k - 1u], w) / field_levels(w) * range[k - 1u] * t0;
                }
            } else {
                let frame = factor_frames[brick];
                let toward = frame.xyz + offset * frame.w - probe.position;
                let r = f32((head >> R_AT) & R_TOP) / f32(R_TOP);
                let a2 = f32((head >> A2_AT) & A2_TOP) / f32(A2_TOP);
                t = lobe_transfer(t0, r, a2, toward);
            }
        } else {
            let g = float_factor(base);
            t = g.t;
            offset = g.offset;
        }
        let l = factor_radiance(brick, offset);
        for (var k = 0u; k < 9u; k = k + 1u) {
            acc[k] = acc[k] + t[k] * l;
        }
    }
    if params.sky_mode == SKY_CONSTANT && lid == 0u {
        for (var k = 0u; k < 9u; k = k + 1u) {
            acc[k] = acc[k] + sky_transfer[9u * probe.slot + k] * params.sky_color;
        }
    }
    if params.sky_mode == SKY_DIRECTIONS {
        // A word of 32 rays per thread, its set bits one by one: a word no ray of which
        // escaped costs its two loads. sky_directions are in sky order, as the masks' bits.
        // (Every thread the same word and a bit each measured slower on lavapipe than the
        // mask word per ray this replaced: docs/results/packing.md, format 17.)
        let base = sky_mask[probe.slot];
        let words = (params.ray_count + 31u) / 32u;
        for (var w = lid; w < words; w = w + GATHER_WORKGROUP) {
            var m = sky_word(base, w);
            while m != 0u {
                let i = 32u * w + countTrailingZeros(m);
                m = m & (m - 1u);
                let y = sh_basis(sky_directions[2u * i].xyz);
                let l = sky_directions[2u * i + 1u].xyz;
                for (var k = 0u; k < 9u; k = k + 1u) {
                    acc[k] = acc[k] + params.ray_weight * y[k] * l;
                }
            }
        }
    }
    return acc;
}

// Word w of the sky mask of the probe whose record starts at `base` (bit j: the ray at
// sky-order position 32 w + j escaped). The record is a bitmap of mixed words, one of full
// words, then the mixed words: two loads for a full word, two for an empty one, three and a
// popcount (and one more load per 32 words before it) for a mixed one (twin:
// prt_format::sky_mask::word).
fn sky_word(base: u32, w: u32) -> u32 {
    let h = ((params.ray_count + 31u) / 32u + 31u) / 32u;
    let bit = 1u << (w % 32u);
    if (sky_mask[base + h + w / 32u] & bit) != 0u {
        // Full: every ray of the word; the last word holds ray_count - 32 w of them (1..=32).
        return 0xffffffffu >> (32u - min(params.ray_count - 32u * w, 32u));
    }
    let mixed = sky_mask[base + w / 32u];
    if (mixed & bit) == 0u {
        return 0u;
    }
    var before = countOneBits(mixed & (bit - 1u));
    for (var k = 0u; k < w / 32u; k = k + 1u) {
        before = before + countOneBits(sky_mask[base + k]);
    }
    return sky_mask[base + 2u * h + before];
}

// Thread 0: store the finished probe.
fn finish(p: u32, c: array<vec3<f32>, 9>) {
    store_probe(p, probes[p].slot, c);
    // Clean, and gathered by this update (the fill redoes the points beside it).
    probe_dirty[p] = params.update_serial;
    atomicAdd(&counters.probes_gathered, 1u);
    var peak = 0.0;
    for (var k = 0u; k < 9u; k = k + 1u) {
        peak = max(peak, max(max(abs(c[k].x), abs(c[k].y)), abs(c[k].z)));
    }
    if peak > params.texel_limit {
        atomicAdd(&counters.probes_clamped, 1u);
    }
}
