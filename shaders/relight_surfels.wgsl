// Stage 2, one thread per surfel of a dirty brick: direct irradiance from every light the
// brick's mask lets through, shadowed by an any-hit ray through the BVH, then the surfel's
// exitant radiance emission + albedo / pi * E (twin of CpuRelighter::direct_irradiance).
// Visibility is cached per (surfel, light) bit and re-traced only for lights that moved.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> surfels: array<Surfel>;
@group(0) @binding(3) var<storage, read> brick_light_mask: array<u32>;
@group(0) @binding(4) var<storage, read> brick_dirty: array<u32>;
@group(0) @binding(5) var<storage, read_write> surfel_visibility: array<u32>;
@group(0) @binding(6) var<storage, read_write> surfel_radiance: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> counters: Counters;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let s = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if s >= params.surfel_count {
        return;
    }
    let surfel = surfels[s];
    if brick_dirty[surfel.brick] == 0u {
        return;
    }
    let mask = brick_light_mask[surfel.brick];
    var visible = surfel_visibility[s];
    var e = vec3<f32>(0.0);
    var rays = 0u;
    for (var i = 0u; i < params.light_count; i = i + 1u) {
        let bit = 1u << i;
        if (mask & bit) == 0u {
            continue;
        }
        let ls = light_sample(lights[i], surfel.position, surfel.normal);
        if max(max(ls.irradiance.x, ls.irradiance.y), ls.irradiance.z) <= 0.0 {
            continue;
        }
        if (params.moved_lights & bit) != 0u {
            let off = ray_offset(surfel.position, params.ray_scale);
            let o = surfel.position + surfel.normal * off;
            var tmax = INFINITE_DISTANCE;
            if lights[i].kind != LIGHT_DIRECTIONAL {
                tmax = length(lights[i].position - o) - off;
            }
            rays = rays + 1u;
            if occluded(o, ls.to_light, tmax) {
                visible = visible & ~bit;
            } else {
                visible = visible | bit;
            }
        }
        if (visible & bit) != 0u {
            e = e + ls.irradiance;
        }
    }
    surfel_visibility[s] = visible;
    surfel_radiance[s] = vec4<f32>(surfel.emission + surfel.albedo * (1.0 / PI) * e, 0.0);
    atomicAdd(&counters.surfels_relit, 1u);
    if rays > 0u {
        atomicAdd(&counters.shadow_rays, rays);
    }
}
