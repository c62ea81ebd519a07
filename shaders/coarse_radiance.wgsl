// Stage 5, one thread per coarse brick (prt_format::coarse): when one of its bricks was relit
// this update, its linear radiance model from theirs (twin of prt_runtime::relight::
// coarse_radiance), the fit over all their surfels without reading one:
//   mean = sum_c W_c m_c / W,  gradient = 2^level M^-1 sum_c (M_c G_c + W_c (mu_c - mu) m_c)
// written after the bricks' in brick_radiance, and its dirty flag after theirs in brick_dirty
// (what stage 7 marks probes by). Bricks are never written here, so the order of the threads
// does not matter.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> bricks: array<Brick>;
@group(0) @binding(2) var<storage, read> coarse_bricks: array<CoarseBrick>;
@group(0) @binding(3) var<storage, read> coarse_children: array<u32>;
@group(0) @binding(4) var<storage, read> brick_moments: array<BrickMoments>;
@group(0) @binding(5) var<storage, read_write> brick_dirty: array<u32>;
@group(0) @binding(6) var<storage, read_write> brick_radiance: array<vec4<f32>>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if c >= params.coarse_count {
        return;
    }
    let coarse = coarse_bricks[c];
    let end = coarse.first_child + coarse.child_count;
    var dirty = params.all_radiance_dirty != 0u;
    for (var i = coarse.first_child; i < end && !dirty; i = i + 1u) {
        dirty = brick_dirty[coarse_children[i]] != 0u;
    }
    let at = params.brick_count + c;
    brick_dirty[at] = select(0u, 1u, dirty);
    if !dirty {
        return;
    }
    var mean = vec3<f32>(0.0);
    var br = vec3<f32>(0.0);
    var bg = vec3<f32>(0.0);
    var bb = vec3<f32>(0.0);
    for (var i = coarse.first_child; i < end; i = i + 1u) {
        let b = coarse_children[i];
        let m = brick_moments[b];
        let d = bricks[b].centroid - coarse.centroid;
        let l = brick_radiance[4u * b].xyz;
        mean = mean + m.weight * l;
        br = br + symmetric_times(m.moment, brick_radiance[4u * b + 1u].xyz) + m.weight * l.x * d;
        bg = bg + symmetric_times(m.moment, brick_radiance[4u * b + 2u].xyz) + m.weight * l.y * d;
        bb = bb + symmetric_times(m.moment, brick_radiance[4u * b + 3u].xyz) + m.weight * l.z * d;
    }
    brick_radiance[4u * at] = vec4<f32>(mean / coarse.weight, 0.0);
    brick_radiance[4u * at + 1u] = vec4<f32>(symmetric_times(coarse.inverse, br), 0.0);
    brick_radiance[4u * at + 2u] = vec4<f32>(symmetric_times(coarse.inverse, bg), 0.0);
    brick_radiance[4u * at + 3u] = vec4<f32>(symmetric_times(coarse.inverse, bb), 0.0);
}
