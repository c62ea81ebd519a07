// Writing one grid point's SH, shared by the stages that produce it: a gathered probe's nine
// coefficients to `probe_sh` (which the stage declares; PROBE_SH_FLOATS an entry at the
// probe's slot, rgb by coefficient, the layout `PrtRuntime::read_probe_sh` reads,
// prt_runtime::contract::probe_sh_entry) and, for it and a filled point (fill.wgsl), all seven
// volume texels at once, so a texel never holds half of an update.
//
// Volume layout (premultiplied by validity, so hardware trilinear filtering weights valid
// probes only): texture 0 = (c0.rgb, validity); textures 1..6 = the 24 values c1.r, c1.g, c1.b,
// c2.r, ... c8.b in order, four per texel. A written probe has validity 1; a probe never written
// keeps zero texels, validity included.

@group(1) @binding(0) var volume0: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(1) var volume1: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(2) var volume2: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(3) var volume3: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(4) var volume4: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(5) var volume5: texture_storage_3d<VOLUME_FORMAT, write>;
@group(1) @binding(6) var volume6: texture_storage_3d<VOLUME_FORMAT, write>;

fn texel(v: vec4<f32>) -> vec4<f32> {
    return clamp(v, vec4<f32>(-params.texel_limit), vec4<f32>(params.texel_limit));
}

// Grid point p's SH c, to its seven texels.
fn store_texels(p: u32, c: array<vec3<f32>, 9>) {
    let n = params.grid_counts;
    let at = vec3<i32>(vec3<u32>(p % n.x, (p / n.x) % n.y, p / (n.x * n.y)));
    textureStore(volume0, at, texel(vec4<f32>(c[0], 1.0)));
    textureStore(volume1, at, texel(vec4<f32>(c[1], c[2].x)));
    textureStore(volume2, at, texel(vec4<f32>(c[2].yz, c[3].xy)));
    textureStore(volume3, at, texel(vec4<f32>(c[3].z, c[4])));
    textureStore(volume4, at, texel(vec4<f32>(c[5], c[6].x)));
    textureStore(volume5, at, texel(vec4<f32>(c[6].yz, c[7].xy)));
    textureStore(volume6, at, texel(vec4<f32>(c[7].z, c[8])));
}

// Probe p's SH c, to its probe_sh entry and its seven texels.
fn store_probe(p: u32, entry: u32, c: array<vec3<f32>, 9>) {
    for (var k = 0u; k < 9u; k = k + 1u) {
        let at = PROBE_SH_FLOATS * entry + 3u * k;
        probe_sh[at] = c[k].x;
        probe_sh[at + 1u] = c[k].y;
        probe_sh[at + 2u] = c[k].z;
    }
    store_texels(p, c);
}
