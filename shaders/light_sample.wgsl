// The light model shared by the relight stages and the reference renderer: KHR_lights_punctual
// irradiance (docs/conventions.md section 3), twin of prt_runtime::lights::PreparedLight. Needs
// the Light struct of types.wgsl.

// Unshadowed irradiance of a light at p with normal n, the unit direction towards the light and
// its distance (INFINITE_DISTANCE for directional lights), the inverse square softened to
// 1 / (d^2 + spread_sq) (0 for a point; a surfel's cell for surfels). Twin of
// PreparedLight::irradiance_over.
struct LightSample {
    irradiance: vec3<f32>,
    to_light: vec3<f32>,
    distance: f32,
}

fn light_sample(light: Light, p: vec3<f32>, n: vec3<f32>, spread_sq: f32) -> LightSample {
    var s: LightSample;
    if light.kind == LIGHT_DIRECTIONAL {
        let l = -light.direction;
        s.irradiance = light.radiant * max(dot(n, l), 0.0);
        s.to_light = l;
        s.distance = INFINITE_DISTANCE;
        return s;
    }
    let to_light = light.position - p;
    let d2 = dot(to_light, to_light);
    let d = sqrt(d2);
    var l = vec3<f32>(0.0, 1.0, 0.0);
    if d > 0.0 {
        l = to_light / d;
    }
    let cosine = max(dot(n, l), 0.0);
    let x = d2 * light.inv_range_sq;
    let window = clamp(1.0 - x * x, 0.0, 1.0);
    var e = cosine * window * window / max(d2 + spread_sq, MIN_DISTANCE_SQ);
    if light.kind == LIGHT_SPOT {
        let c = clamp((dot(light.direction, -l) - light.cos_outer) * light.cone_scale, 0.0, 1.0);
        e = e * c * c;
    }
    s.irradiance = light.radiant * e;
    s.to_light = l;
    s.distance = d;
    return s;
}
