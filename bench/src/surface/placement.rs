//! How many probes the surfaces use: the corners of every grid cell that holds a surfel. The
//! lookup at a surface point reads only the eight corners of its cell (or of a cell beside it,
//! after the normal bias), so a sparse placement (issue 32, item 2) that keeps these probes
//! and drops the rest (empty air, solid interiors) loses nothing at surfaces: the column is what
//! a uniform grid of the same spacing would keep.

use glam::{UVec3, Vec3};
use prt_format::{Asset, BRICK_BACKFACE};

/// Probes that are a corner of a grid cell holding a front-face surfel.
pub fn surface_probes(asset: &Asset) -> usize {
    let g = &asset.header.grid;
    let counts = UVec3::from(g.counts);
    if counts.min_element() == 0 {
        return 0;
    }
    let last_cell = counts.saturating_sub(UVec3::ONE).max(UVec3::ONE) - UVec3::ONE;
    let mut used = vec![false; g.probe_count() as usize];
    let (origin, step) = (Vec3::from(g.origin), Vec3::from(g.step));
    for s in asset
        .surfels
        .iter()
        .filter(|s| s.flags & BRICK_BACKFACE == 0)
    {
        let t = ((Vec3::from(s.position) - origin) / step).max(Vec3::ZERO);
        let cell = t.as_uvec3().min(last_cell);
        for corner in 0..8u32 {
            let o = UVec3::new(corner & 1, corner >> 1 & 1, corner >> 2 & 1);
            let p = (cell + o).min(counts - UVec3::ONE);
            used[g.index(p.x, p.y, p.z)] = true;
        }
    }
    used.iter().filter(|&&u| u).count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use prt_bake::{BakeSettings, NoProgress};

    fn bake(name: &str) -> Asset {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fixtures")
            .join(name);
        prt_bake::bake(&path, &BakeSettings::default(), &NoProgress)
            .unwrap()
            .0
    }

    /// A plane on a one-layer grid uses every probe; a closed box on the grid's outer faces
    /// uses its two outer layers (11^3 - 7^3), not the 7^3 probes deep inside it.
    #[test]
    fn probes_at_surfaces() {
        let quad = bake("textured_quad.gltf");
        assert_eq!(surface_probes(&quad), quad.probes.len());
        let cube = bake("closed_box_outward.gltf");
        assert_eq!(cube.header.grid.counts, [11, 11, 11]);
        assert_eq!(surface_probes(&cube), 11 * 11 * 11 - 7 * 7 * 7);
    }
}
