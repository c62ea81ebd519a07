// Stage 4, one thread per dirty brick: the brick's linear radiance model from its surfels, the
// weighted mean and the gradient sum_s g_s L_s (twin of CpuRelighter::brick_radiance). Four
// vec4 per brick: mean, then the gradient of red, green and blue. A surfel's radiance is its
// direct radiance (stage 2) plus, with bounces (BOUNCES), its bounce radiance (stage 3). Then
// the weighted mean radiance of each of the brick's near groups (the surface lookup's, twin of
// prt_runtime::surface::group_radiance), for stage 6's near fields.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> bricks: array<Brick>;
@group(0) @binding(2) var<storage, read> surfels: array<u32>;
@group(0) @binding(3) var<storage, read> brick_dirty: array<u32>;
@group(0) @binding(4) var<storage, read> surfel_radiance: array<u32>;
@group(0) @binding(5) var<storage, read_write> brick_radiance: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> surfel_bounce: array<u32>;
// The per-surfel arrays hold this chunk's surfels only (dispatched once per chunk).
@group(0) @binding(7) var<uniform> chunk: SurfelChunk;
// Brick count, per brick its first near group and group count, per group its first surfel and
// surfel count (a brick count of 0: the asset has no surface terms).
@group(0) @binding(8) var<storage, read> surface_groups: array<u32>;
@group(0) @binding(9) var<storage, read_write> group_radiance: array<vec4<f32>>;

fn surfel_radiance_at(s: u32) -> vec3<f32> {
    // RADIANCE_WORDS a surfel (relight_surfels.wgsl, bounce_surfels.wgsl).
    var direct = vec3<u32>(0u);
    var bounce = vec3<u32>(0u);
    for (var i = 0u; i < RADIANCE_WORDS; i = i + 1u) {
        direct[i] = surfel_radiance[RADIANCE_WORDS * s + i];
        if BOUNCES {
            bounce[i] = surfel_bounce[RADIANCE_WORDS * s + i];
        }
    }
    var l = decode_radiance(direct);
    if BOUNCES {
        l = l + decode_radiance(bounce);
    }
    return l;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let b = chunk.brick_begin + linear_index(wg, lid, WORKGROUP, params.dispatch_width);
    if b >= chunk.brick_end {
        return;
    }
    let brick = bricks[b];
    let all = params.all_radiance_dirty != 0u && (brick.flags & BRICK_BACKFACE) == 0u;
    if brick_dirty[b] == 0u && !all {
        return;
    }
    var mean = vec3<f32>(0.0);
    var gr = vec3<f32>(0.0);
    var gg = vec3<f32>(0.0);
    var gb = vec3<f32>(0.0);
    var weight = 0.0;
    let first = brick.first_surfel - chunk.surfel_begin;
    for (var s = first; s < first + brick.surfel_count; s = s + 1u) {
        let l = surfel_radiance_at(s);
        let surfel = surfel_at(s);
        mean = mean + surfel.weight * l;
        gr = gr + surfel.gradient * l.x;
        gg = gg + surfel.gradient * l.y;
        gb = gb + surfel.gradient * l.z;
        weight = weight + surfel.weight;
    }
    brick_radiance[4u * b] = vec4<f32>(mean / weight, 0.0);
    brick_radiance[4u * b + 1u] = vec4<f32>(gr, 0.0);
    brick_radiance[4u * b + 2u] = vec4<f32>(gg, 0.0);
    brick_radiance[4u * b + 3u] = vec4<f32>(gb, 0.0);
    let bricks_with_groups = surface_groups[0];
    if b >= bricks_with_groups {
        return;
    }
    let first_group = surface_groups[1u + 2u * b];
    for (var g = first_group; g < first_group + surface_groups[2u + 2u * b]; g = g + 1u) {
        let at = 1u + 2u * bricks_with_groups + 2u * g;
        let begin = surface_groups[at] - chunk.surfel_begin;
        var sum = vec3<f32>(0.0);
        var w = 0.0;
        for (var s = begin; s < begin + surface_groups[at + 1u]; s = s + 1u) {
            let weight = surfel_at(s).weight;
            sum = sum + weight * surfel_radiance_at(s);
            w = w + weight;
        }
        group_radiance[g] = vec4<f32>(sum / w, 0.0);
    }
}
