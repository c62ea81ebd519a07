
// The asset's surfels as stored (prt_format::surfel): SURFEL_WORDS words each in `surfels`,
// the chunk's binding of the stage that includes this file. 20 words: `Surfel` as it is (f32
// surfels). 12 words: position, brick (PACKED_BACKFACE in its top bit), gradient, octahedral
// normal (`prt_decode_normal`, oct_normal.wgsl), then albedo, weight and emission as halves
// (PackedSurfel::surfel is the CPU twin).
fn surfel_at(i: u32) -> Surfel {
    let b = i * SURFEL_WORDS;
    var s: Surfel;
    s.position = bitcast<vec3<f32>>(vec3<u32>(surfels[b], surfels[b + 1u], surfels[b + 2u]));
    if SURFEL_WORDS == 20u {
        s.brick = surfels[b + 3u];
        s.normal = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 4u], surfels[b + 5u], surfels[b + 6u]));
        s.weight = bitcast<f32>(surfels[b + 7u]);
        s.albedo = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 8u], surfels[b + 9u], surfels[b + 10u]));
        s.flags = surfels[b + 11u];
        s.emission = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 12u], surfels[b + 13u], surfels[b + 14u]));
        s.gradient = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 16u], surfels[b + 17u], surfels[b + 18u]));
        return s;
    }
    let brick = surfels[b + 3u];
    s.brick = brick & ~PACKED_BACKFACE;
    s.flags = select(0u, BRICK_BACKFACE, (brick & PACKED_BACKFACE) != 0u);
    s.gradient = bitcast<vec3<f32>>(vec3<u32>(surfels[b + 4u], surfels[b + 5u], surfels[b + 6u]));
    s.normal = prt_decode_normal(surfels[b + 7u]);
    let albedo_b_weight = unpack2x16float(surfels[b + 9u]);
    s.albedo = vec3<f32>(unpack2x16float(surfels[b + 8u]), albedo_b_weight.x);
    s.weight = albedo_b_weight.y;
    s.emission = vec3<f32>(unpack2x16float(surfels[b + 10u]), unpack2x16float(surfels[b + 11u]).x);
    return s;
}

