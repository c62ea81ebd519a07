//! # Merged surfels back on their surface
//!
//! A merged surfel sits at the mean of its hits ([`super::fold`]): on a curved or bevelled
//! surface that mean lies behind the surface, up to the sagitta of a surfel cell (1.5 cm for a
//! 19 cm cell across a 30 cm column). The runtime starts each surfel's shadow rays a ten
//! thousandth of a spacing off it (`prt_runtime::shadow_rays::ray_offset`), so such a surfel
//! shadows itself and its surface goes dark for every light. On Sponza's default bake (1.5 m,
//! cells of 19 cm) 25.0% of the front-face surfels facing a sun saw it, 29.3% from 9 mm further
//! out; most of those newly lit had been blocked within 1 mm or 1 cm, by their own surface. The
//! relit probes came out dark where they see such surfaces: the open points of `prt-bench
//! surface` were 12.4% too dark on average under Sponza's 31 lights (188 of 290 more than 10%
//! below the truth, 6 above), with every lookup.
//!
//! The bake therefore moves each merged surfel that lies behind its surface onto it: along its
//! normal to the first surface within [`REACH`] cells that is about parallel to it
//! ([`PARALLEL_COS`]), unless such a surface lies about as close behind it ([`BEHIND`]: then the
//! surfel already stands in front of its surface, and what is ahead is something else, a
//! shelf over a floor). A move that would take the surfel out of its brick's cell is not made
//! (a brick's key, bounds and centroid stay its own). Measured with `prt-bench surface`
//! (default spacing, half in brackets): Sponza under its 31 lights 17.1% -> 10.5% (12.0% ->
//! 7.7%); under the sun and two lights 17.9% -> 15.9% (12.2% -> 12.7%); the tuning seeds'
//! median level 6.7% -> 6.6%, worst 9.2% -> 8.6%; Cornell, fixtures/two_rooms and thick walls
//! unchanged. A shadow-ray offset of a share of the cell instead removed the bias as well
//! (0.02 cells: 11.6% and 16.2%) but moves every origin, past thin occluders too, and worsened
//! as it grew; `docs/results/surface_candidates.md` (stop 39) has both, and what is left.
//!
//! Unmerged bakes keep their hits where the rays found them (the exact bake is unchanged).

use glam::Vec3;
use prt_format::{Surfel, BRICK_BACKFACE};

use crate::accel::bvh::{SceneBvh, TriangleHit};

/// How far along its normal a surfel may move, in surfel cells: the sagitta of a cell across a
/// column a cell and a half wide. A tenth of a cell measured as well on the tuning seeds
/// (median level 6.7% against 6.6%, worst 8.6% both).
pub const REACH: f32 = 0.25;

/// A surfel does not move when a parallel surface lies behind it within this many times the
/// distance to the one ahead: it stands in front of a surface already, or between two that
/// nearly coincide (Sponza has such pairs a millimetre apart), where comparing the two
/// distances as equal would let float rounding decide, differently at another scale
/// (`shared_scenes_relight_alike_at_every_scale`).
pub const BEHIND: f32 = 2.0;

/// A surface counts as the surfel's own when its normal is within this cosine of the
/// surfel's (either side: double-sided surfaces have no winding to go by).
pub const PARALLEL_COS: f32 = 0.7;

/// What a move reads: the scene's BVH and triangles (by the BVH's index), and the cell size.
pub struct Surfaces<'a> {
    pub bvh: &'a SceneBvh,
    pub triangles: &'a [[Vec3; 3]],
    pub cell_size: f32,
}

impl Surfaces<'_> {
    /// Moves the merged surfel `s` of the brick whose cell is `cell` (min, max) onto its
    /// surface when it lies behind it (module docs); back-face surfels stay (they are black).
    pub fn place(&self, s: &mut Surfel, cell: [Vec3; 2]) {
        if s.flags & BRICK_BACKFACE != 0 {
            return;
        }
        let (c, n) = (Vec3::from(s.position), Vec3::from(s.normal));
        let reach = REACH * self.cell_size;
        let Some(ahead) = self.parallel(self.bvh.closest_hit(c, n, reach), n) else {
            return;
        };
        if self
            .parallel(self.bvh.closest_hit(c, -n, ahead), n)
            .is_some()
        {
            return;
        }
        let p = c + n * ahead;
        if p.cmpge(cell[0]).all() && p.cmple(cell[1]).all() {
            s.position = p.to_array();
        }
    }

    /// The distance of `hit` when its triangle is about parallel to `n`.
    fn parallel(&self, hit: Option<TriangleHit>, n: Vec3) -> Option<f32> {
        let hit = hit?;
        let [v0, v1, v2] = self.triangles[hit.triangle as usize];
        let g = (v1 - v0).cross(v2 - v0);
        (g.dot(n).abs() >= PARALLEL_COS * g.length()).then_some(hit.t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of half-size `r` at height `z`, facing +z.
    fn square(z: f32, r: f32) -> [[Vec3; 3]; 2] {
        let v = |x: f32, y: f32| Vec3::new(x, y, z);
        [
            [v(-r, -r), v(r, -r), v(r, r)],
            [v(-r, -r), v(r, r), v(-r, r)],
        ]
    }

    fn surfel(p: Vec3, n: Vec3) -> Surfel {
        Surfel {
            position: p.to_array(),
            normal: n.to_array(),
            weight: 1.0,
            ..Surfel::default()
        }
    }

    /// The cell `[-1, 1]^3` and a surfel cell of 0.4 (reach 0.1).
    fn place(triangles: &[[Vec3; 3]], s: &mut Surfel) {
        let surfaces = Surfaces {
            bvh: &SceneBvh::build(triangles, 1.0),
            triangles,
            cell_size: 0.4,
        };
        surfaces.place(s, [Vec3::splat(-1.0), Vec3::splat(1.0)]);
    }

    #[test]
    fn a_surfel_behind_its_surface_moves_onto_it() {
        // The mean of hits on a bent surface: 5 cm behind it, within the reach of 10 cm.
        let tris = square(0.0, 1.0);
        let mut s = surfel(Vec3::new(0.1, 0.2, -0.05), Vec3::Z);
        place(&tris, &mut s);
        assert!((Vec3::from(s.position) - Vec3::new(0.1, 0.2, 0.0)).length() < 1e-6);
    }

    #[test]
    fn a_surfel_in_front_of_its_surface_stays_under_a_shelf() {
        // A floor surfel 1 mm above the floor, a shelf 5 cm above it: the shelf is not its
        // surface.
        let mut tris = square(0.0, 1.0).to_vec();
        tris.extend(square(0.051, 0.5));
        let p = Vec3::new(0.1, 0.2, 0.001);
        let mut s = surfel(p, Vec3::Z);
        place(&tris, &mut s);
        assert_eq!(Vec3::from(s.position), p);
    }

    #[test]
    fn what_is_beyond_reach_across_or_outside_the_cell_stays() {
        let tris = square(0.0, 1.0);
        // 20 cm behind: out of reach.
        let far = Vec3::new(0.0, 0.0, -0.2);
        let mut s = surfel(far, Vec3::Z);
        place(&tris, &mut s);
        assert_eq!(Vec3::from(s.position), far);
        // A wall across the normal is not the surfel's surface.
        let mut s = surfel(Vec3::new(0.0, 0.0, -0.05), Vec3::X);
        let wall: Vec<[Vec3; 3]> = square(0.0, 1.0)
            .iter()
            .map(|t| t.map(|v| Vec3::new(v.z + 0.03, v.x, v.y)))
            .chain(square(0.0, 1.0))
            .collect();
        let before = s.position;
        place(&wall, &mut s);
        assert!((Vec3::from(s.position) - Vec3::new(0.03, 0.0, -0.05)).length() < 1e-6);
        s.position = before;
        s.normal = Vec3::Y.to_array();
        place(&tris, &mut s);
        assert_eq!(s.position, before);
        // The surface above the cell's top.
        let mut s = surfel(Vec3::new(0.0, 0.0, 0.95), Vec3::Z);
        place(&square(1.02, 1.0), &mut s);
        assert_eq!(Vec3::from(s.position), Vec3::new(0.0, 0.0, 0.95));
        // Back faces stay.
        let mut s = Surfel {
            flags: BRICK_BACKFACE,
            ..surfel(Vec3::new(0.0, 0.0, -0.05), Vec3::Z)
        };
        place(&tris, &mut s);
        assert_eq!(Vec3::from(s.position), Vec3::new(0.0, 0.0, -0.05));
    }
}
