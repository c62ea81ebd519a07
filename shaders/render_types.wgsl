// Types shared by the Forward+ renderer's stages (prt-render). Each has a Rust twin in
// render/src/layout.rs; a unit test checks sizes and offsets with naga.

struct Frame {
    view_proj: mat4x4<f32>,
    view: mat4x4<f32>,
    inv_proj: mat4x4<f32>,
    eye: vec3<f32>,
    mode: u32,
    width: u32,
    height: u32,
    tile: u32,
    tiles_x: u32,
    tiles_y: u32,
    max_per_tile: u32,
    other_count: u32,
    directional_count: u32,
    flags: u32,
    // The scene's length scale for shadow-ray offsets (ray_offset).
    ray_scale: f32,
    pad1: u32,
    pad2: u32,
}

struct CullStats {
    overflow_tiles: atomic<u32>,
    dropped: atomic<u32>,
    listed: atomic<u32>,
    pad: u32,
}

// Words of one tile's list: [count, index, index, ...] (twin of layout::tile_list_words).
fn tile_stride() -> u32 {
    return frame.max_per_tile + 1u;
}
