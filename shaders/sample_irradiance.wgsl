// Engines include this snippet in their shaders to shade with prt's indirect diffuse light.
// Bind the runtime's seven volume textures, its sampler and a VolumeInfo uniform at the group
// given by PRT_GROUP (PrtRuntime::wgsl_snippet injects it). sample_irradiance returns irradiance
// E (W/m^2, not divided by pi): diffuse exitance is albedo / pi * E.
//
// The textures hold SH premultiplied by validity (texture 0's alpha), so one hardware trilinear
// fetch per texture weights the eight surrounding probes by validity; dividing by the filtered
// validity renormalises. Where no valid probe surrounds the point, the result is 0.
//
// Both functions sample at world_pos + normal * normal_bias (metres; RuntimeSettings::normal_bias
// in probe spacings): probes just behind a surface see its back faces and are invalid or dark, so
// a point sampled exactly on the surface mixes them in (self-shadowing, leaking through thin
// walls); moving the point off the surface along its normal weights the probes in front more.
// prt_sample_sh exposes the interpolated SH and validity for engines with their own lobes.

struct PrtVolumeInfo {
    origin: vec3<f32>,
    spacing: f32,
    counts: vec3<f32>,
    // Metres along the normal that prt_sample_sh moves the point before sampling.
    normal_bias: f32,
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

fn prt_sample_sh(world_pos: vec3<f32>, normal: vec3<f32>) -> PrtSample {
    let p = world_pos + normal * prt_volume.normal_bias;
    let uvw = ((p - prt_volume.origin) / prt_volume.spacing + 0.5) / prt_volume.counts;
    var s: PrtSample;
    let t0 = textureSampleLevel(prt_volume0, prt_sampler, uvw, 0.0);
    s.validity = t0.w;
    if t0.w <= 1e-6 {
        return s;
    }
    let inv = 1.0 / t0.w;
    let t1 = textureSampleLevel(prt_volume1, prt_sampler, uvw, 0.0) * inv;
    let t2 = textureSampleLevel(prt_volume2, prt_sampler, uvw, 0.0) * inv;
    let t3 = textureSampleLevel(prt_volume3, prt_sampler, uvw, 0.0) * inv;
    let t4 = textureSampleLevel(prt_volume4, prt_sampler, uvw, 0.0) * inv;
    let t5 = textureSampleLevel(prt_volume5, prt_sampler, uvw, 0.0) * inv;
    let t6 = textureSampleLevel(prt_volume6, prt_sampler, uvw, 0.0) * inv;
    s.sh = array<vec3<f32>, 9>(
        t0.xyz * inv,
        t1.xyz,
        vec3<f32>(t1.w, t2.xy),
        vec3<f32>(t2.zw, t3.x),
        t3.yzw,
        t4.xyz,
        vec3<f32>(t4.w, t5.xy),
        vec3<f32>(t5.zw, t6.x),
        t6.yzw,
    );
    return s;
}

// Irradiance E at world_pos for a surface with unit normal `normal` (0 where no valid probe
// surrounds the biased point).
fn sample_irradiance(world_pos: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let c = prt_sample_sh(world_pos, normal).sh;
    let n = normal;
    // Clamped-cosine factors A_l (pi, 2pi/3, pi/4) times the basis of conventions.md section 2.
    let e = PRT_A0 * PRT_SH_Y00 * c[0]
        + PRT_A1 * PRT_SH_Y1 * (n.y * c[1] + n.z * c[2] + n.x * c[3])
        + PRT_A2 * PRT_SH_Y2_OFF * (n.x * n.y * c[4] + n.y * n.z * c[5] + n.x * n.z * c[7])
        + PRT_A2 * PRT_SH_Y20 * (3.0 * n.z * n.z - 1.0) * c[6]
        + PRT_A2 * PRT_SH_Y22 * (n.x * n.x - n.y * n.y) * c[8];
    return max(e, vec3<f32>(0.0));
}
