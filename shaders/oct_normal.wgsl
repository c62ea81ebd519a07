
// prt_format::surface::decode_normal: a unit normal from two octahedral snorm16 (packed
// surfels'; the surface terms' two snorm12 go through prt_oct_unfold, from
// sample_irradiance.wgsl). Part of the engine-side snippet, and of the runtime stages that read
// packed surfels (`surfel.wgsl`).
fn prt_decode_normal(bits: u32) -> vec3<f32> {
    return prt_oct_unfold(unpack2x16snorm(bits));
}

// prt_format::surfel_terms::oct_unfold: the unit normal of an octahedral projection.
fn prt_oct_unfold(e: vec2<f32>) -> vec3<f32> {
    var v = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-v.z, 0.0);
    v.x = v.x + select(t, -t, v.x >= 0.0);
    v.y = v.y + select(t, -t, v.y >= 0.0);
    return v / sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
}
