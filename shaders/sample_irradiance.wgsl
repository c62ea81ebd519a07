// Engines include this snippet in their shaders to shade with prt's indirect diffuse light.
// Bind the runtime's bindings at the group given by PRT_GROUP (PrtRuntime::wgsl_snippet injects
// it; PrtRuntime::volume_bind_group makes the group): seven volume textures, a sampler, the
// PrtVolumeInfo uniform, the probes' depth moments and positions, the surface lookup's tables
// and its near radiance (four storage buffers). sample_irradiance returns irradiance E
// (W/m^2, not divided by pi): diffuse exitance is albedo / pi * E. Twins:
// prt_runtime::surface (sample_irradiance) and prt_runtime::sample (prt_sample_sh).
//
// The textures hold SH premultiplied by each probe's validity (texture 0's alpha: 1 for a valid
// or dilated probe and a grid point filled from a coarse level, 0 for an invalid one).
//
// Both functions sample at world_pos + normal * normal_bias (metres; LookupSettings::normal_bias
// in probe spacings): probes just behind a surface see its back faces, and moving the point off
// the surface along its normal weights the probes in front more. Where the point has a surfel's
// terms, prt_sample_surface weights the probes at world_pos + normal * surface_bias instead
// (LookupSettings::surface_bias): the surfel's probe mask already says which probes count.
//
// With depth moments (PrtVolumeInfo.flags, the default) the eight probes around the point are read
// one by one and weighted, as DDGI does (Majercik et al., JCGT 2019), by
//   trilinear weight x validity x (clamp(1 + h / PRT_FACING_DEPTH, 0, 1)^2 + PRT_FACING_FLOOR)
//                    x Chebyshev term,
// where h is the probe's signed distance, in spacings, from the plane through the unmoved
// surface point (probes in front of the surface count fully, probes behind it fade out; DDGI's
// angular term instead, see prt_runtime::sample::FACING_DEPTH for why), and
// where the Chebyshev term tests the point's distance from the probe (from where its rays
// started) against the mean and
// variance of the probe's hit distances in that direction (its octahedral depth moments): a
// probe on the far side of a wall sees the wall nearer than the point and drops out. Cost: 56
// texel loads and 8 depth-moment words instead of 7 filtered fetches. Without it, one hardware
// trilinear fetch per texture weights the probes by their weight alone.

struct PrtVolumeInfo {
    origin: vec3<f32>,
    // The grid's spacing: the unit of the depth moments' distances.
    spacing: f32,
    counts: vec3<f32>,
    // Metres along the normal that prt_sample_sh moves the point before sampling.
    normal_bias: f32,
    // The lattice step along x, y, z (at most the spacing; outer probes lie on the bounds).
    step: vec3<f32>,
    // PRT_FLAG_DEPTH_MOMENTS: weight the probes by their depth moments; PRT_FLAG_SURFACE: the
    // surface lookup (prt_surface) decides where the point has a surfel.
    flags: u32,
    // The surface lookup's brick lattice (prt_format::surface): its origin and brick edge.
    surface_anchor: vec3<f32>,
    brick_size: f32,
    // Slots of the brick table minus one (a power of two minus one), its longest search, and
    // where in prt_surface the cell table, the surfel terms and the brick links start.
    slot_mask: u32,
    max_probe: u32,
    cells_at: u32,
    terms_at: u32,
    bricks_at: u32,
    // Near-field rays per surfel.
    near_rays: f32,
    // Where in prt_surface the sky terms start (two halves a word, one per surfel).
    sky_at: u32,
    // Where in prt_surface the sides start: their count, then four words each (surfel,
    // partner, the wall's octahedral snorm16 normal, its offset from the key's corner).
    sides_at: u32,
    // Pi times the sky's mean radiance: the irradiance a surfel's sky term of 1 adds.
    sky_irradiance: vec3<f32>,
    // Metres along the normal the surface lookup moves the point before weighting its probes.
    surface_bias: f32,
    // The surface lookup's floor under L2's ringing: a share of the non-linear L1 model's
    // irradiance (prt_irradiance_l1_nonlinear) times the share of near-field rays that escape.
    ringing_floor: f32,
}

// The interpolated probe SH at a point (validity-renormalised; zero where validity <= 1e-6) and
// the filtered validity itself (0 = no valid probe around the point, 1 = all eight valid).
struct PrtSample {
    sh: array<vec3<f32>, 9>,
    validity: f32,
}

@group(PRT_GROUP) @binding(0) var prt_volume0: texture_3d<f32>;
@group(PRT_GROUP) @binding(1) var prt_volume1: texture_3d<f32>;
@group(PRT_GROUP) @binding(2) var prt_volume2: texture_3d<f32>;
@group(PRT_GROUP) @binding(3) var prt_volume3: texture_3d<f32>;
@group(PRT_GROUP) @binding(4) var prt_volume4: texture_3d<f32>;
@group(PRT_GROUP) @binding(5) var prt_volume5: texture_3d<f32>;
@group(PRT_GROUP) @binding(6) var prt_volume6: texture_3d<f32>;
@group(PRT_GROUP) @binding(7) var prt_sampler: sampler;
@group(PRT_GROUP) @binding(8) var<uniform> prt_volume: PrtVolumeInfo;
// Per placed probe, PRT_DEPTH_WORDS words: per texel, mean and standard deviation of hit distances in
// spacings, four bits each, four texels per word (prt_format::depth).
@group(PRT_GROUP) @binding(9) var<storage, read> prt_depth_moments: array<u32>;
// Per grid point, where its probe's rays started (xyz; the grid position unless it was moved off
// a surface or out of geometry: depth-moment distances are measured from there) as the bits of
// xyz, and in w its slot (prt_format::Probe::slot): where its depth moments sit. Words, not
// floats: a slot is no float (NO_SLOT is a NaN's bits), and WGSL may flush NaNs and subnormals.
@group(PRT_GROUP) @binding(10) var<storage, read> prt_probe_positions: array<vec4<u32>>;
// The surface lookup's tables, one array of words (prt_format::surface): the brick table (four
// words a slot: key xyz, axis << 29 | brick + 1), then from the offsets in prt_volume the cells
// (16 words a brick), the surfel terms (PRT_TERMS_WORDS a surfel), per brick its first surfel,
// first near group and centre probe (PRT_BRICK_WORDS), and the sky terms (two halves a word,
// one per surfel).
@group(PRT_GROUP) @binding(11) var<storage, read> prt_surface: array<u32>;
// Per near group, the mean radiance its surfels' near-field hits bring (xyz), as the runtime
// last relit it.
@group(PRT_GROUP) @binding(12) var<storage, read> prt_near: array<vec4<f32>>;

fn prt_sh_of_texels(t: array<vec4<f32>, 7>, inv: f32) -> array<vec3<f32>, 9> {
    return array<vec3<f32>, 9>(
        t[0].xyz * inv,
        t[1].xyz * inv,
        vec3<f32>(t[1].w, t[2].xy) * inv,
        vec3<f32>(t[2].zw, t[3].x) * inv,
        t[3].yzw * inv,
        t[4].xyz * inv,
        vec3<f32>(t[4].w, t[5].xy) * inv,
        vec3<f32>(t[5].zw, t[6].x) * inv,
        t[6].yzw * inv,
    );
}

// Hardware trilinear: one filtered fetch per texture.
fn prt_sample_trilinear(p: vec3<f32>) -> PrtSample {
    let uvw = ((p - prt_volume.origin) / prt_volume.step + 0.5) / prt_volume.counts;
    var s: PrtSample;
    var t: array<vec4<f32>, 7>;
    t[0] = textureSampleLevel(prt_volume0, prt_sampler, uvw, 0.0);
    if t[0].w <= PRT_MIN_VALIDITY {
        return s;
    }
    s.validity = t[0].w;
    t[1] = textureSampleLevel(prt_volume1, prt_sampler, uvw, 0.0);
    t[2] = textureSampleLevel(prt_volume2, prt_sampler, uvw, 0.0);
    t[3] = textureSampleLevel(prt_volume3, prt_sampler, uvw, 0.0);
    t[4] = textureSampleLevel(prt_volume4, prt_sampler, uvw, 0.0);
    t[5] = textureSampleLevel(prt_volume5, prt_sampler, uvw, 0.0);
    t[6] = textureSampleLevel(prt_volume6, prt_sampler, uvw, 0.0);
    s.sh = prt_sh_of_texels(t, 1.0 / t[0].w);
    return s;
}

fn prt_sign_not_zero(v: vec2<f32>) -> vec2<f32> {
    return select(vec2<f32>(-1.0), vec2<f32>(1.0), v >= vec2<f32>(0.0));
}

// Texel of a probe's octahedral depth moments holding unit direction d (prt_format::depth).
fn prt_depth_texel(d: vec3<f32>) -> u32 {
    var e = vec2<f32>(d.x, d.z) / (abs(d.x) + abs(d.y) + abs(d.z));
    if d.y < 0.0 {
        e = (1.0 - abs(e.yx)) * prt_sign_not_zero(e);
    }
    let side = f32(PRT_DEPTH_SIDE);
    let t = vec2<u32>(clamp(floor((e * 0.5 + 0.5) * side), vec2<f32>(0.0), vec2<f32>(side - 1.0)));
    return t.y * PRT_DEPTH_SIDE + t.x;
}

// Facing and Chebyshev weight of the probe at `probe` whose depth moments sit at `slot` for the
// surface point `surface` (facing) moved along its normal n to x (Chebyshev test against them).
fn prt_depth_weight(slot: u32, probe: vec3<f32>, surface: vec3<f32>, x: vec3<f32>, n: vec3<f32>) -> f32 {
    let v = x - probe;
    let len = length(v);
    let dist = len / prt_volume.spacing;
    if dist <= PRT_MIN_DISTANCE {
        return 1.0;
    }
    let dir = v / len;
    let behind = clamp(dot(probe - surface, n) / prt_volume.spacing / PRT_FACING_DEPTH + 1.0, 0.0, 1.0);
    var w = behind * behind + PRT_FACING_FLOOR;
    // A grid point filled from a coarse level has no depth moments: its facing term alone.
    if slot == PRT_NO_SLOT {
        return w;
    }
    let texel = prt_depth_texel(dir);
    // Four texels a word, a byte each: mean in the low four bits, deviation in the high four,
    // each q^2 times its step (prt_format::depth::moments).
    let word = prt_depth_moments[slot * PRT_DEPTH_WORDS + texel / 4u];
    let byte = (word >> (8u * (texel & 3u))) & 0xffu;
    let q = vec2<u32>(byte & 15u, byte >> 4u);
    let mean = f32(q.x * q.x) * PRT_DEPTH_MEAN_STEP;
    let deviation = f32(q.y * q.y) * PRT_DEPTH_DEVIATION_STEP;
    // A saturated mean (the top value: sky, or hits farther than about 3.7 spacings) bounds
    // nothing.
    if dist > mean && q.x < PRT_DEPTH_TOP {
        let variance = max(deviation * deviation, PRT_MIN_VARIANCE);
        let d = dist - mean;
        let chebyshev = variance / (variance + d * d);
        var v = chebyshev * chebyshev * chebyshev;
        if v < PRT_CRUSH_THRESHOLD {
            v = v * v * v / (PRT_CRUSH_THRESHOLD * PRT_CRUSH_THRESHOLD);
        }
        w = w * max(v, PRT_MIN_CHEBYSHEV);
    }
    return w;
}

// The eight probes around p (the surface point `surface` moved along its normal n) read one by
// one (twin: VolumeSampler::sample_weighted), each weighted by its trilinear weight and
// validity times, with `masked`, whether the point's surfel sees it (its terms' `mask` around the
// probe at grid position `centre`; PRT_BLOCKED_WEIGHT when not), else its depth moments.
// validity < 0: masked, and the surfel sees none of them.
fn prt_sample_probes(surface: vec3<f32>, p: vec3<f32>, n: vec3<f32>, masked: bool, mask: u32, centre: vec3<i32>) -> PrtSample {
    var s: PrtSample;
    let last = prt_volume.counts - 1.0;
    let g = clamp((p - prt_volume.origin) / prt_volume.step, vec3<f32>(0.0), last);
    let base = floor(g);
    let f = g - base;
    let counts = vec3<u32>(prt_volume.counts);
    var acc: array<vec4<f32>, 7>;
    var total = 0.0;
    var seen = false;
    for (var c = 0u; c < 8u; c = c + 1u) {
        let o = vec3<f32>(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u));
        let tri = mix(1.0 - f, f, o);
        let w_tri = tri.x * tri.y * tri.z;
        let ijk = vec3<u32>(min(base + o, last));
        let at = vec3<i32>(ijk);
        let t0 = textureLoad(prt_volume0, at, 0);
        if w_tri <= 0.0 || t0.w <= 0.0 {
            continue;
        }
        s.validity = s.validity + w_tri * t0.w;
        var w = w_tri;
        if masked {
            let d = at - centre;
            var visible = true;
            if all(abs(d) <= vec3<i32>(1)) {
                let bit = u32((d.x + 1) + 3 * (d.y + 1) + 9 * (d.z + 1));
                visible = ((mask >> bit) & 1u) != 0u;
            }
            seen = seen || visible;
            w = w * select(PRT_BLOCKED_WEIGHT, 1.0, visible);
        } else {
            let index = ijk.x + counts.x * (ijk.y + counts.y * ijk.z);
            let probe = prt_probe_positions[index];
            w = w * prt_depth_weight(probe.w, bitcast<vec3<f32>>(probe.xyz), surface, p, n);
        }
        total = total + w * t0.w;
        acc[0] = acc[0] + w * t0;
        acc[1] = acc[1] + w * textureLoad(prt_volume1, at, 0);
        acc[2] = acc[2] + w * textureLoad(prt_volume2, at, 0);
        acc[3] = acc[3] + w * textureLoad(prt_volume3, at, 0);
        acc[4] = acc[4] + w * textureLoad(prt_volume4, at, 0);
        acc[5] = acc[5] + w * textureLoad(prt_volume5, at, 0);
        acc[6] = acc[6] + w * textureLoad(prt_volume6, at, 0);
    }
    if masked && !seen {
        s.validity = -1.0;
        return s;
    }
    if s.validity <= PRT_MIN_VALIDITY || total <= 0.0 {
        s.validity = 0.0;
        return s;
    }
    s.sh = prt_sh_of_texels(acc, 1.0 / total);
    return s;
}

fn prt_sample_sh(world_pos: vec3<f32>, normal: vec3<f32>) -> PrtSample {
    let p = world_pos + normal * prt_volume.normal_bias;
    if (prt_volume.flags & PRT_FLAG_DEPTH_MOMENTS) != 0u {
        return prt_sample_probes(world_pos, p, normal, false, 0u, vec3<i32>(0));
    }
    return prt_sample_trilinear(p);
}

// Irradiance E of interpolated SH c on a surface with unit normal n (clamped at 0).
fn prt_irradiance(c: array<vec3<f32>, 9>, n: vec3<f32>) -> vec3<f32> {
    // Clamped-cosine factors A_l (pi, 2pi/3, pi/4) times the basis of docs/conventions.md section 2.
    let e = PRT_A0 * PRT_SH_Y00 * c[0]
        + PRT_A1 * PRT_SH_Y1 * (n.y * c[1] + n.z * c[2] + n.x * c[3])
        + PRT_A2 * PRT_SH_Y2_OFF * (n.x * n.y * c[4] + n.y * n.z * c[5] + n.x * n.z * c[7])
        + PRT_A2 * PRT_SH_Y20 * (3.0 * n.z * n.z - 1.0) * c[6]
        + PRT_A2 * PRT_SH_Y22 * (n.x * n.x - n.y * n.y) * c[8];
    return max(e, vec3<f32>(0.0));
}

// Irradiance on unit normal n from the L0 and L1 of c alone by Enlighten's non-linear model
// (twin: prt_format::sh::irradiance_l1_nonlinear): E0 (a + (1 - a) (p + 1) q^p), E0 the mean
// irradiance, r = |c1| / (sqrt(3) c0), q = (1 + cos) / 2 on the angle to c1, p = 1 + 2r,
// a = (1 - r) / (1 + r). Never negative; 0 where c0 <= 0.
fn prt_irradiance_l1_nonlinear(c: array<vec3<f32>, 9>, n: vec3<f32>) -> vec3<f32> {
    // Per colour channel: L1 along x, y, z is c[3], c[1], c[2].
    let c0 = c[0];
    let len = sqrt(c[3] * c[3] + c[1] * c[1] + c[2] * c[2]);
    let along = c[3] * n.x + c[1] * n.y + c[2] * n.z;
    let positive = c0 > vec3<f32>(0.0);
    let r = min(len / (sqrt(3.0) * select(vec3<f32>(1.0), c0, positive)), vec3<f32>(1.0));
    let directed = len > vec3<f32>(0.0);
    let cos_n = select(vec3<f32>(0.0), along / select(vec3<f32>(1.0), len, directed), directed);
    // Not 0: pow(0, p) is exp2(p log2 0), which WGSL leaves undefined.
    let q = clamp(0.5 * (1.0 + cos_n), vec3<f32>(1e-20), vec3<f32>(1.0));
    let p = 1.0 + 2.0 * r;
    let a = (1.0 - r) / (1.0 + r);
    let e = PRT_A0 * PRT_SH_Y00 * c0 * (a + (1.0 - a) * (p + 1.0) * pow(q, p));
    return select(vec3<f32>(0.0), e, positive);
}


// ---- The surface lookup (twin: prt_runtime::surface::SurfaceSampler) ----
//
// Where the asset carries surface terms (PRT_FLAG_SURFACE), the point's surfel is found by
// brick key (brick lattice cell, the normal's dominant axis) in the hash table, then by the
// point's cell of that brick. Its terms say which of the 27 probes around it the surfel sees
// (a probe it cannot see keeps PRT_BLOCKED_WEIGHT of its trilinear weight) and scale the
// irradiance by (clamp(open . L, 0, A(n_s) . L) + hits / rays * near) / (A(n_s) . L) per
// channel: open the mean SH basis of its near-field rays that escape (held to what the whole
// hemisphere brings: L2 ringing can exceed it), near its near group's relit radiance per hit, A
// the clamped-cosine transfer of the surfel's normal; raise it, E, to F - E where that is
// more, F being ringing_floor times the escaping share of the non-linear L1 irradiance (L2
// rings below 0 behind a bright lobe, a dark room's probes looking through its door); then add
// the surfel's sky term (the sky it sees less the sky its probes bring it) times pi times the
// sky's mean radiance, clamped at 0.
// A point without one gets prt_sample_sh.

// What sample_irradiance computed: the SH it interpolated, its validity and the irradiance.
struct PrtSurfaceSample {
    sh: array<vec3<f32>, 9>,
    validity: f32,
    irradiance: vec3<f32>,
}

fn prt_dominant_axis(n: vec3<f32>) -> u32 {
    let a = abs(n);
    if a.x >= a.y && a.x >= a.z {
        return select(0u, 1u, n.x < 0.0);
    }
    if a.y >= a.z {
        return select(2u, 3u, n.y < 0.0);
    }
    return select(4u, 5u, n.z < 0.0);
}

// prt_format::surface::slot_hash.
fn prt_slot_hash(key: vec3<i32>, axis: u32) -> u32 {
    var h = bitcast<u32>(key.x) * 0x8da6b343u;
    h = h ^ (bitcast<u32>(key.y) * 0xd8163841u);
    h = h ^ (bitcast<u32>(key.z) * 0xcb1ab31fu);
    h = h ^ (axis * 0x9e3779b9u);
    h = h ^ (h >> 16u);
    h = h * 0x7feb352du;
    return h ^ (h >> 15u);
}

// The surfel whose terms stand for a point `from_corner` past its brick key's corner where the
// cell table named `named`: its partner when a wall crosses its cell and the point lies beyond
// it (prt_format::surface::SurfaceTerms::side_of; the sides sorted by surfel, searched by
// halves).
fn prt_side_of(named: u32, from_corner: vec3<f32>) -> u32 {
    if (prt_surface[prt_volume.terms_at + PRT_TERMS_WORDS * named + 3u] & PRT_SIDE_BIT) == 0u {
        return named;
    }
    var lo = 0u;
    var hi = prt_surface[prt_volume.sides_at];
    while lo < hi {
        let mid = (lo + hi) / 2u;
        let at = prt_volume.sides_at + 1u + 4u * mid;
        let s = prt_surface[at];
        if s == named {
            let n = prt_decode_normal(prt_surface[at + 2u]);
            if dot(n, from_corner) > bitcast<f32>(prt_surface[at + 3u]) {
                return prt_surface[at + 1u];
            }
            return named;
        }
        if s < named {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return named;
}

// The point's surfel (x) and its brick (y), or PRT_NONE in x.
fn prt_find_surfel(p: vec3<f32>, n: vec3<f32>) -> vec2<u32> {
    let key = vec3<i32>(floor((p - prt_volume.surface_anchor) / prt_volume.brick_size));
    let axis = prt_dominant_axis(n);
    let start = prt_slot_hash(key, axis);
    var brick = PRT_NONE;
    for (var i = 0u; i <= prt_volume.max_probe; i++) {
        let at = ((start + i) & prt_volume.slot_mask) * 4u;
        let value = prt_surface[at + 3u];
        if value == 0u {
            break;
        }
        let k = vec3<i32>(bitcast<i32>(prt_surface[at]), bitcast<i32>(prt_surface[at + 1u]), bitcast<i32>(prt_surface[at + 2u]));
        if all(k == key) && (value >> PRT_SLOT_AXIS_SHIFT) == axis {
            brick = (value & ((1u << PRT_SLOT_AXIS_SHIFT) - 1u)) - 1u;
            break;
        }
    }
    if brick == PRT_NONE {
        return vec2<u32>(PRT_NONE, 0u);
    }
    let origin = prt_volume.surface_anchor + vec3<f32>(key) * prt_volume.brick_size;
    let c = vec3<u32>(clamp(floor((p - origin) / (prt_volume.brick_size / 4.0)), vec3<f32>(0.0), vec3<f32>(3.0)));
    let byte = c.x + 4u * (c.y + 4u * c.z);
    let within = (prt_surface[prt_volume.cells_at + 16u * brick + byte / 4u] >> (8u * (byte % 4u))) & 0xffu;
    if within == PRT_NO_SURFEL {
        return vec2<u32>(PRT_NONE, 0u);
    }
    let named = prt_surface[prt_volume.bricks_at + PRT_BRICK_WORDS * brick] + within;
    let surfel = prt_side_of(named, p - origin);
    if (prt_surface[prt_volume.terms_at + PRT_TERMS_WORDS * surfel] >> PRT_TERMS_CENTRE_SHIFT) == 0u {
        return vec2<u32>(PRT_NONE, 0u);
    }
    return vec2<u32>(surfel, brick);
}

// Grid position of probe `index`.
fn prt_probe_ijk(index: u32) -> vec3<i32> {
    let c = vec3<u32>(prt_volume.counts);
    return vec3<i32>(vec3<u32>(index % c.x, (index / c.x) % c.y, index / (c.x * c.y)));
}

// prt_oct_unfold (prt_format::surfel_terms::oct_unfold) and prt_decode_normal (the sides' wall
// normals, prt_format::surface::decode_normal) follow the snippet, from oct_normal.wgsl, which
// the runtime's surfel stages share.

// The signed field of `bits` bits at `at` of `word` in units of its levels
// (prt_format::surfel_terms::unit_field).
fn prt_unit_field(word: u32, at: u32, bits: u32) -> f32 {
    return f32(bitcast<i32>(word << (32u - at - bits)) >> (32u - bits)) / f32((1u << (bits - 1u)) - 1u);
}

// The unit normal of a surfel's terms: two octahedral snorm12
// (prt_format::surfel_terms::SurfelTerms::normal).
fn prt_terms_normal(word: u32) -> vec3<f32> {
    let n = PRT_TERMS_NORMAL_BITS;
    let e = vec2<f32>(prt_unit_field(word, 0u, n), prt_unit_field(word, n, n));
    return prt_oct_unfold(max(e, vec2<f32>(-1.0)));
}

// The SH9 basis of docs/conventions.md section 2 at unit n.
fn prt_basis(n: vec3<f32>) -> array<f32, 9> {
    return array<f32, 9>(
        PRT_SH_Y00,
        PRT_SH_Y1 * n.y,
        PRT_SH_Y1 * n.z,
        PRT_SH_Y1 * n.x,
        PRT_SH_Y2_OFF * n.x * n.y,
        PRT_SH_Y2_OFF * n.y * n.z,
        PRT_SH_Y20 * (3.0 * n.z * n.z - 1.0),
        PRT_SH_Y2_OFF * n.x * n.z,
        PRT_SH_Y22 * (n.x * n.x - n.y * n.y),
    );
}

// The full lookup at world_pos for a surface with unit normal `normal`.
fn prt_sample_surface(world_pos: vec3<f32>, normal: vec3<f32>) -> PrtSurfaceSample {
    var out: PrtSurfaceSample;
    var found = vec2<u32>(PRT_NONE, 0u);
    if (prt_volume.flags & PRT_FLAG_SURFACE) != 0u {
        found = prt_find_surfel(world_pos, normal);
    }
    if found.x == PRT_NONE {
        let s = prt_sample_sh(world_pos, normal);
        out.sh = s.sh;
        out.validity = s.validity;
        out.irradiance = prt_irradiance(s.sh, normal);
        return out;
    }
    let t = prt_volume.terms_at + PRT_TERMS_WORDS * found.x;
    let b = prt_volume.bricks_at + PRT_BRICK_WORDS * found.y;
    let p = world_pos + normal * prt_volume.surface_bias;
    // The surfel's centre probe: its code's offset from its brick key's (prt_format::surfel_terms).
    let mask = prt_surface[t];
    let centre_code = max(mask >> PRT_TERMS_CENTRE_SHIFT, 1u) - 1u;
    let offset = vec3<i32>(vec3<u32>(centre_code % 3u, (centre_code / 3u) % 3u, centre_code / 9u)) - vec3<i32>(1);
    let centre = prt_probe_ijk(prt_surface[b + 2u]) + offset;
    var s = prt_sample_probes(world_pos, p, normal, true, mask, centre);
    if s.validity < 0.0 {
        s = prt_sample_sh(world_pos, normal);
    }
    out.sh = s.sh;
    out.validity = s.validity;
    out.irradiance = prt_irradiance(s.sh, normal);
    // The terms' words (prt_format::surfel_terms): normal and hits, group and open k = 1..3,
    // open k = 4..8; open as codes from what a uniformly blocked hemisphere would see.
    let normal_hits = prt_surface[t + 1u];
    let group_open = prt_surface[t + 2u];
    let open_l2 = prt_surface[t + 3u];
    let hits = f32(normal_hits >> PRT_TERMS_HITS_AT);
    let rays = prt_volume.near_rays;
    let escape_share = (rays - hits) / rays;
    let bound = min(escape_share, 1.0 - escape_share) + 1.0 / rays;
    let share = hits / rays;
    let group = prt_surface[b + 1u] + (group_open & 0xffu);
    let near = prt_near[group].xyz;
    let y = prt_basis(prt_terms_normal(normal_hits));
    var bits = PRT_OPEN_BITS;
    var at = PRT_OPEN_AT;
    var range = PRT_OPEN_RANGE;
    var lo = vec3<f32>(0.0);
    var all_l = vec3<f32>(0.0);
    for (var k = 0u; k < 9u; k++) {
        let a = select(select(0.25, 2.0 / 3.0, k < 4u), 1.0, k == 0u);
        let transfer = a * y[k];
        var open = escape_share * transfer;
        if k > 0u {
            let word = select(open_l2, group_open, k < 4u);
            open = open + prt_unit_field(word, at[k - 1u], bits[k - 1u]) * (bound * range[k]);
        }
        lo = lo + s.sh[k] * open;
        all_l = all_l + s.sh[k] * transfer;
    }
    let escaping = min(max(lo, vec3<f32>(0.0)), max(all_l, vec3<f32>(0.0)));
    let ratio = max((escaping + share * near) / all_l, vec3<f32>(0.0));
    out.irradiance = select(out.irradiance, out.irradiance * ratio, all_l > vec3<f32>(0.0));
    // The floor under L2's ringing, fading as L2 rises: max(E, F - E), F the floor (twin:
    // prt_runtime::surface::floor_ringing).
    let ringing = prt_volume.ringing_floor * escape_share;
    if ringing > 0.0 {
        let lifted = ringing * prt_irradiance_l1_nonlinear(s.sh, normal) - out.irradiance;
        out.irradiance = max(out.irradiance, lifted);
    }
    if any(prt_volume.sky_irradiance != vec3<f32>(0.0)) {
        let sky = unpack2x16float(prt_surface[prt_volume.sky_at + found.x / 2u])[found.x % 2u];
        out.irradiance = max(out.irradiance + sky * prt_volume.sky_irradiance, vec3<f32>(0.0));
    }
    return out;
}

// Irradiance E at world_pos for a surface with unit normal `normal` (0 where no valid probe
// surrounds the biased point): the surface lookup where the asset has terms for the point,
// the probe volume alone elsewhere.
fn sample_irradiance(world_pos: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    return prt_sample_surface(world_pos, normal).irradiance;
}
