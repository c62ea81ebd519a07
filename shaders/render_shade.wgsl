// Forward+ stages 1 and 3: the depth pre-pass (vs_depth) and the shading pass (vs_main, fs_main),
// drawn with the same invariant clip positions so that the shading pass's LessEqual depth test
// shades exactly the visible surface once.
//
// fs_main shades a pixel with
//   emission + albedo / pi * (direct + indirect)
// where direct sums light_sample (the relight stages' own light model) over the directional
// lights and the pixel's tile list (or every light with culling off), each light shadowed by an
// any-hit ray through the asset's BVH, and indirect is the runtime's sample_irradiance at the
// pixel (its normal offset is in the volume uniform). The view mode picks which terms are
// written; alpha holds the number of lights evaluated at the pixel (the benchmark's figure).

// The renderer reads these declarations (render/src/bindings.rs) and binds each by its name;
// group 1 (the BVH) is declared by the runtime's shadow-ray traversal and group 2 (shaders.rs
// VOLUME_GROUP) by its sample_irradiance snippet.
@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> directional_lights: array<Light>;
@group(0) @binding(2) var<storage, read> lights: array<Light>;
@group(0) @binding(3) var<storage, read> tile_lists: array<u32>;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
@group(0) @binding(5) var<storage, read> images: array<ImageInfo>;
@group(0) @binding(6) var<storage, read> texels: array<u32>;

struct Material {
    base_color: vec3<f32>,
    flags: u32,
    emissive: vec3<f32>,
    base_image: u32,
    base_sampler: u32,
    emissive_image: u32,
    emissive_sampler: u32,
    pad: u32,
}

struct ImageInfo {
    offset: u32,
    width: u32,
    height: u32,
    pad: u32,
}

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) material: u32,
    @location(2) normal: vec3<f32>,
    @location(3) uv0: vec2<f32>,
    @location(4) uv1: vec2<f32>,
    @location(5) color: vec4<f32>,
}

struct VertexOut {
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) material: u32,
    @location(2) normal: vec3<f32>,
    @location(3) uv0: vec2<f32>,
    @location(4) uv1: vec2<f32>,
    @location(5) color: vec4<f32>,
}

struct DepthOut {
    @builtin(position) @invariant clip: vec4<f32>,
}

@vertex
fn vs_depth(v: VertexIn) -> DepthOut {
    var out: DepthOut;
    out.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    return out;
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.material = v.material;
    out.normal = v.normal;
    out.uv0 = v.uv0;
    out.uv1 = v.uv1;
    out.color = v.color;
    return out;
}

fn wrap(i: i32, n: i32, mode: u32) -> i32 {
    if mode == WRAP_CLAMP {
        return clamp(i, 0, n - 1);
    }
    if mode == WRAP_MIRROR {
        let m = ((i % (2 * n)) + 2 * n) % (2 * n);
        return select(m, 2 * n - 1 - m, m >= n);
    }
    return ((i % n) + n) % n;
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

fn fetch(info: ImageInfo, x: i32, y: i32, sampler_bits: u32) -> vec3<f32> {
    let w = i32(info.width);
    let h = i32(info.height);
    let tx = wrap(x, w, sampler_bits & 3u);
    let ty = wrap(y, h, (sampler_bits >> 2u) & 3u);
    let t = unpack4x8unorm(texels[info.offset + u32(ty * w + tx)]);
    return vec3<f32>(srgb_to_linear(t.x), srgb_to_linear(t.y), srgb_to_linear(t.z));
}

// Twin of prt_scene::texture::sample: the glTF sampler's wrap modes, nearest or bilinear.
fn sample_image(image: u32, sampler_bits: u32, uv: vec2<f32>) -> vec3<f32> {
    let info = images[image];
    // Empty images and non-finite coordinates sample white, as on the CPU.
    let finite = uv.x == uv.x && uv.y == uv.y && abs(uv.x) < 3.0e38 && abs(uv.y) < 3.0e38;
    if info.width == 0u || info.height == 0u || !finite {
        return vec3<f32>(1.0);
    }
    let x = clamp(uv.x * f32(info.width), -1.0e6, 1.0e6);
    let y = clamp(uv.y * f32(info.height), -1.0e6, 1.0e6);
    if (sampler_bits & SAMPLER_NEAREST) != 0u {
        return fetch(info, i32(floor(x)), i32(floor(y)), sampler_bits);
    }
    let fx0 = floor(x - 0.5);
    let fy0 = floor(y - 0.5);
    let fx = x - 0.5 - fx0;
    let fy = y - 0.5 - fy0;
    let x0 = i32(fx0);
    let y0 = i32(fy0);
    let top = mix(fetch(info, x0, y0, sampler_bits), fetch(info, x0 + 1, y0, sampler_bits), fx);
    let bottom = mix(fetch(info, x0, y0 + 1, sampler_bits), fetch(info, x0 + 1, y0 + 1, sampler_bits), fx);
    return mix(top, bottom, fy);
}

fn uv_of(in: VertexOut, sampler_bits: u32) -> vec2<f32> {
    return select(in.uv0, in.uv1, (sampler_bits & SAMPLER_UV1) != 0u);
}

// One light at a surface point, shadowed by an any-hit ray through the BVH.
fn direct_light(light: Light, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let ls = light_sample(light, p, n, 0.0);
    if max(max(ls.irradiance.x, ls.irradiance.y), ls.irradiance.z) <= 0.0 {
        return vec3<f32>(0.0);
    }
    if (frame.flags & FLAG_SHADOWS) != 0u {
        let off = ray_offset(p, frame.ray_scale);
        let o = p + n * off;
        var tmax = INFINITE_DISTANCE;
        if light.kind != LIGHT_DIRECTIONAL {
            tmax = length(light.position - o) - off;
        }
        if occluded(o, ls.to_light, tmax) {
            return vec3<f32>(0.0);
        }
    }
    return ls.irradiance;
}

struct ShadeOut {
    @location(0) color: vec4<f32>,
    @location(1) position: vec4<f32>,
    @location(2) normal: vec4<f32>,
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> ShadeOut {
    let m = materials[in.material];
    // Only double-sided materials are drawn without back-face culling: their back faces are lit
    // with the normal turned towards the viewer (docs/conventions.md section 4).
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    var albedo = m.base_color * in.color.xyz;
    if m.base_image != NO_IMAGE {
        albedo = albedo * sample_image(m.base_image, m.base_sampler, uv_of(in, m.base_sampler));
    }
    albedo = clamp(albedo, vec3<f32>(0.0), vec3<f32>(1.0));
    var emission = m.emissive;
    if m.emissive_image != NO_IMAGE && max(max(emission.x, emission.y), emission.z) > 0.0 {
        emission = emission * sample_image(m.emissive_image, m.emissive_sampler, uv_of(in, m.emissive_sampler));
    }
    let p = in.world;

    var out: ShadeOut;
    out.position = vec4<f32>(p, 1.0);
    out.normal = vec4<f32>(n, 0.0);
    if frame.mode == MODE_ALBEDO {
        out.color = vec4<f32>(albedo, 0.0);
        return out;
    }
    var direct = vec3<f32>(0.0);
    var evaluated = 0u;
    if frame.mode != MODE_INDIRECT {
        for (var i = 0u; i < frame.directional_count; i = i + 1u) {
            direct = direct + direct_light(directional_lights[i], p, n);
        }
        evaluated = frame.directional_count;
        if (frame.flags & FLAG_TILED) != 0u {
            let tile = vec2<u32>(in.clip.xy) / frame.tile;
            let base = (tile.y * frame.tiles_x + tile.x) * tile_stride();
            let count = tile_lists[base] & ~TILE_OVERFLOW;
            for (var k = 0u; k < count; k = k + 1u) {
                direct = direct + direct_light(lights[tile_lists[base + 1u + k]], p, n);
            }
            evaluated = evaluated + count;
        } else {
            for (var i = 0u; i < frame.other_count; i = i + 1u) {
                direct = direct + direct_light(lights[i], p, n);
            }
            evaluated = evaluated + frame.other_count;
        }
    }
    var indirect = vec3<f32>(0.0);
    if frame.mode != MODE_DIRECT {
        indirect = sample_irradiance(p, n);
    }
    var radiance = albedo * (1.0 / PI) * (direct + indirect);
    if frame.mode != MODE_INDIRECT {
        radiance = radiance + emission;
    }
    out.color = vec4<f32>(radiance, f32(evaluated));
    return out;
}
