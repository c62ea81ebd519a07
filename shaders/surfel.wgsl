
// The asset's surfels as stored (prt_format::surfel): SURFEL_WORDS words each in `surfels`,
// the chunk's binding of the stage that includes this file (which also binds `bricks`). 20
// words: `Surfel` as it is (f32 surfels). 8 words (PackedSurfel; its `surfel` is the CPU twin):
// brick (PACKED_BACKFACE in its top bit), the position as 16-bit fractions of the brick's
// bounds and the weight as a half, the octahedral normal (`prt_decode_normal`,
// oct_normal.wgsl), gradient weights times a power of two of the brick's extent and albedo as
// halves, emission as RGB9E5.
fn surfel_at(i: u32) -> Surfel {
    let b = i * SURFEL_WORDS;
    var s: Surfel;
    if SURFEL_WORDS == 20u {
        s.position = bitcast<vec3<f32>>(vec3<u32>(surfels[b], surfels[b + 1u], surfels[b + 2u]));
        s.brick = surfels[b + 3u];
        s.normal = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 4u], surfels[b + 5u], surfels[b + 6u]));
        s.weight = bitcast<f32>(surfels[b + 7u]);
        s.albedo = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 8u], surfels[b + 9u], surfels[b + 10u]));
        s.flags = surfels[b + 11u];
        s.emission = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 12u], surfels[b + 13u], surfels[b + 14u]));
        s.gradient = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 16u], surfels[b + 17u], surfels[b + 18u]));
        return s;
    }
    let brick = surfels[b];
    s.brick = brick & ~PACKED_BACKFACE;
    s.flags = select(0u, BRICK_BACKFACE, (brick & PACKED_BACKFACE) != 0u);
    let bounds = bricks[s.brick];
    let extent = bounds.bmax - bounds.bmin;
    let xy = surfels[b + 1u];
    let z_weight = surfels[b + 2u];
    let q = vec3<f32>(vec3<u32>(xy & 0xffffu, xy >> 16u, z_weight & 0xffffu));
    s.position = min(bounds.bmin + extent * (q * PACKED_POSITION_STEP), bounds.bmax);
    s.weight = unpack2x16float(z_weight).y;
    s.normal = prt_decode_normal(surfels[b + 3u]);
    // Gradient weights were stored times 2^(E - 126), E the biased exponent of the largest
    // extent (at most 252; 0: a brick of one point): undone by the exact power 2^(126 - E).
    let largest = max(extent.x, max(extent.y, extent.z));
    let unit = select(0u, min(bitcast<u32>(largest) >> 23u, 252u), largest > 0.0);
    let g_xy = unpack2x16float(surfels[b + 4u]);
    let gz_r = unpack2x16float(surfels[b + 5u]);
    let inverse = bitcast<f32>((253u - unit) << 23u);
    s.gradient = select(vec3<f32>(0.0), vec3<f32>(g_xy, gz_r.x) * inverse, unit > 0u);
    s.albedo = vec3<f32>(gz_r.y, unpack2x16float(surfels[b + 6u]));
    let e = surfels[b + 7u];
    // 2^(exponent - 15 - 9) built from its bits (exact, where exp2 need not be).
    let step = bitcast<f32>(((e >> 27u) + RGB9E5_EXPONENT_OFFSET) << 23u);
    s.emission = vec3<f32>(vec3<u32>(e & 511u, (e >> 9u) & 511u, (e >> 18u) & 511u)) * step;
    return s;
}
