//! How many probes the surfaces use: the eight probes the lookup reads at each surfel, with and
//! without the runtime's normal bias (`LookupSettings::normal_bias`: the point is moved along
//! its normal before the trilinear weights, so a surfel near a cell's face also reads the next
//! cell). A sparse placement (issue 32, item 2) that keeps these probes and drops the rest
//! (empty air, solid interiors) keeps what the lookup reads at the surfaces the probes' rays
//! found: the column is what it would keep of a uniform grid of the same spacing.

use glam::Vec3;
use prt_format::{Asset, Grid, BRICK_BACKFACE};
use prt_runtime::sample::corners;
use prt_runtime::LookupSettings;

/// Probes the lookup reads at a front-face surfel, at the surfel and moved by the default
/// normal bias.
pub fn surface_probes(asset: &Asset) -> usize {
    let g = &asset.header.grid;
    if g.counts.contains(&0) {
        return 0;
    }
    let bias = LookupSettings::default().normal_bias * g.spacing;
    let mut used = vec![false; g.probe_count() as usize];
    for s in asset
        .surfels
        .iter()
        .filter(|s| s.flags & BRICK_BACKFACE == 0)
    {
        let p = Vec3::from(s.position);
        mark_corners(g, p, &mut used);
        mark_corners(g, p + Vec3::from(s.normal) * bias, &mut used);
    }
    used.iter().filter(|&&u| u).count()
}

/// Marks the probes the lookup weights at `p`: those of the eight around it with a positive
/// trilinear weight (`prt_runtime::sample::corners`, the CPU twin's own corner walk).
fn mark_corners(g: &Grid, p: Vec3, used: &mut [bool]) {
    for (i, w) in corners(g, p) {
        if w > 0.0 {
            used[i] = true;
        }
    }
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
    /// uses the probes on its faces (17^3 - 15^3): its surfels lie on those layers, where the
    /// next layer in has no trilinear weight, and the bias moves them outwards.
    #[test]
    fn probes_at_surfaces() {
        let quad = bake("textured_quad.gltf");
        assert_eq!(surface_probes(&quad), quad.probes.len());
        let cube = bake("closed_box_outward.gltf");
        assert_eq!(cube.header.grid.counts, [17, 17, 17]);
        assert_eq!(surface_probes(&cube), 17 * 17 * 17 - 15 * 15 * 15);
    }
}
