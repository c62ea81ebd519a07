// Engines include this snippet in their shaders to shade with prt's indirect diffuse light.
// Bind the runtime's bindings at the group given by PRT_GROUP (PrtRuntime::wgsl_snippet injects
// it; PrtRuntime::volume_bind_group makes the group): seven volume textures, a sampler, the
// PrtVolumeInfo uniform and the probes' depth moments. sample_irradiance returns irradiance E
// (W/m^2, not divided by pi): diffuse exitance is albedo / pi * E. Twin: prt_runtime::sample.
//
// The textures hold SH premultiplied by each probe's validity (texture 0's alpha: 1 for a valid
// or dilated probe, 0 for an invalid one).
//
// Both functions sample at world_pos + normal * normal_bias (metres; RuntimeSettings::normal_bias
// in probe spacings): probes just behind a surface see its back faces, and moving the point off
// the surface along its normal weights the probes in front more.
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
    // PRT_FLAG_DEPTH_MOMENTS: weight the probes by their depth moments.
    flags: u32,
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
// Per probe, PRT_DEPTH_WORDS words: per texel, mean and standard deviation of hit distances in
// spacings, one byte each, two texels per word (prt_format::depth).
@group(PRT_GROUP) @binding(9) var<storage, read> prt_depth_moments: array<u32>;
// Per probe, where its rays started (xyz; the grid position unless it was moved off a surface or
// out of geometry): depth-moment distances are measured from there.
@group(PRT_GROUP) @binding(10) var<storage, read> prt_probe_positions: array<vec4<f32>>;

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

// Facing and Chebyshev weight of probe `index` at `probe` for the surface point `surface`
// (facing) moved along its normal n to x (Chebyshev test against its depth moments).
fn prt_depth_weight(index: u32, probe: vec3<f32>, surface: vec3<f32>, x: vec3<f32>, n: vec3<f32>) -> f32 {
    let v = x - probe;
    let len = length(v);
    let dist = len / prt_volume.spacing;
    if dist <= PRT_MIN_DISTANCE {
        return 1.0;
    }
    let dir = v / len;
    let behind = clamp(dot(probe - surface, n) / prt_volume.spacing / PRT_FACING_DEPTH + 1.0, 0.0, 1.0);
    var w = behind * behind + PRT_FACING_FLOOR;
    let texel = prt_depth_texel(dir);
    let bytes = unpack4x8unorm(prt_depth_moments[index * PRT_DEPTH_WORDS + texel / 2u]);
    let pair = select(bytes.xy, bytes.zw, (texel & 1u) == 1u);
    let mean = pair.x * PRT_MAX_DEPTH;
    let deviation = pair.y * PRT_MAX_DEVIATION;
    // A saturated mean (sky, or hits beyond PRT_MAX_DEPTH) bounds nothing.
    if dist > mean && pair.x < 1.0 {
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
// one, weighted by their depth moments.
fn prt_sample_depth_weighted(surface: vec3<f32>, p: vec3<f32>, n: vec3<f32>) -> PrtSample {
    var s: PrtSample;
    let last = prt_volume.counts - 1.0;
    let g = clamp((p - prt_volume.origin) / prt_volume.step, vec3<f32>(0.0), last);
    let base = floor(g);
    let f = g - base;
    let counts = vec3<u32>(prt_volume.counts);
    var acc: array<vec4<f32>, 7>;
    var total = 0.0;
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
        let index = ijk.x + counts.x * (ijk.y + counts.y * ijk.z);
        let w = w_tri * prt_depth_weight(index, prt_probe_positions[index].xyz, surface, p, n);
        total = total + w * t0.w;
        acc[0] = acc[0] + w * t0;
        acc[1] = acc[1] + w * textureLoad(prt_volume1, at, 0);
        acc[2] = acc[2] + w * textureLoad(prt_volume2, at, 0);
        acc[3] = acc[3] + w * textureLoad(prt_volume3, at, 0);
        acc[4] = acc[4] + w * textureLoad(prt_volume4, at, 0);
        acc[5] = acc[5] + w * textureLoad(prt_volume5, at, 0);
        acc[6] = acc[6] + w * textureLoad(prt_volume6, at, 0);
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
        return prt_sample_depth_weighted(world_pos, p, normal);
    }
    return prt_sample_trilinear(p);
}

// Irradiance E at world_pos for a surface with unit normal `normal` (0 where no valid probe
// surrounds the biased point).
fn sample_irradiance(world_pos: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let c = prt_sample_sh(world_pos, normal).sh;
    let n = normal;
    // Clamped-cosine factors A_l (pi, 2pi/3, pi/4) times the basis of docs/conventions.md section 2.
    let e = PRT_A0 * PRT_SH_Y00 * c[0]
        + PRT_A1 * PRT_SH_Y1 * (n.y * c[1] + n.z * c[2] + n.x * c[3])
        + PRT_A2 * PRT_SH_Y2_OFF * (n.x * n.y * c[4] + n.y * n.z * c[5] + n.x * n.z * c[7])
        + PRT_A2 * PRT_SH_Y20 * (3.0 * n.z * n.z - 1.0) * c[6]
        + PRT_A2 * PRT_SH_Y22 * (n.x * n.x - n.y * n.y) * c[8];
    return max(e, vec3<f32>(0.0));
}
