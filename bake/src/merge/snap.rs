//! # Merged surfels back on their surface
//!
//! A merged surfel sits at the mean of its hits ([`super::fold`]): on a curved or bevelled surface
//! that mean lies behind the surface, up to the sagitta of a surfel cell (1.5 cm for a 19 cm cell
//! across a column of 30 cm radius). The runtime starts each surfel's shadow rays a ten thousandth
//! of a spacing off it (`prt_runtime::shadow_rays::ray_offset`), so such a surfel shadows itself
//! and its surface goes dark for every light. On Sponza's default bake (1.5 m, cells of 19 cm)
//! 25.0% of the front-face surfels facing a sun saw it, 29.3% from 9 mm further out; most of those
//! newly lit had been blocked within 1 mm or 1 cm, by their own surface. The relit probes came out
//! dark where they see such surfaces: the open points of `prt-bench surface` were 12.4% too dark on
//! average under Sponza's 31 lights (188 of 290 more than 10% below the truth, 6 above), with every
//! lookup.
//!
//! The bake therefore moves each merged surfel that lies behind its surface onto it: along its
//! normal to the first surface within [`REACH`] cells that is about parallel to it
//! ([`PARALLEL_COS`]; facing the same way, where the scene is single-sided), unless such a surface
//! lies about as close behind it ([`BEHIND`]: then the surfel already stands in front of its
//! surface, and what is ahead is something else, a shelf over a floor). A move that would take the
//! surfel out of its brick's cell is not made (a brick's key, bounds and centroid stay its own).
//! Measured with `prt-bench surface` (default spacing, half in brackets): Sponza under its 31
//! lights 17.1% -> 10.45% (12.0% -> 7.6%); under the sun and two lights 17.9% -> 15.8% (12.2% ->
//! 12.7%); the tuning seeds' median level 6.7% -> 6.6%, worst 9.2% -> 8.6% (5.6% -> 5.5%); Cornell,
//! fixtures/two_rooms and thick walls unchanged. A shadow-ray offset of a share of the cell instead
//! removed the bias as well (0.02 cells: 11.6% and 16.2%) but moves every origin, past thin
//! occluders too, and worsened as it grew; `docs/results/surface_candidates.md` (stop 39) has both,
//! and what is left.
//!
//! Unmerged bakes keep their hits where the rays found them (the exact bake is unchanged).

use glam::Vec3;
use prt_format::{Surfel, BRICK_BACKFACE};

use crate::accel::bvh::{SceneBvh, TriangleHit};

/// How far along its normal a surfel may move, in surfel cells: the sagitta of a cell's chord
/// across a column 1.25 cells wide.
pub const REACH: f32 = 0.25;

/// A surfel does not move when a parallel surface lies behind it within this many times the
/// distance to the one ahead: it stands in front of a surface already, or between two that
/// nearly coincide (Sponza has such pairs a millimetre apart), where comparing the two
/// distances as equal would let float rounding decide, differently at another scale
/// (`shared_scenes_relight_alike_at_every_scale`).
pub const BEHIND: f32 = 2.0;

/// A surface counts as the surfel's own when its normal is within this cosine of the
/// surfel's (about 45 degrees; either side in a double-sided scene).
pub const PARALLEL_COS: f32 = 0.7;

/// What a move reads: the scene's BVH and triangles (by the BVH's index), the cell size, and
/// whether every surface is double-sided (then a triangle's winding says nothing).
pub struct Surfaces<'a> {
    pub bvh: &'a SceneBvh,
    pub triangles: &'a [[Vec3; 3]],
    pub cell_size: f32,
    pub double_sided: bool,
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
        let behind = self.bvh.closest_hit(c, -n, BEHIND * ahead);
        if self.parallel(behind, n).is_some() {
            return;
        }
        // Half-open, as brick keys are (`floor`): a surfel on the cell's upper face would
        // belong to the next brick.
        let p = c + n * ahead;
        if p.cmpge(cell[0]).all() && p.cmplt(cell[1]).all() {
            s.position = p.to_array();
        }
    }

    /// The distance of `hit` when its triangle is about parallel to `n`: facing the same way
    /// in a single-sided scene (the surfel's own surface, met from behind ahead of it or from
    /// the front behind it; a face turned towards the surfel is something else), either way
    /// when double-sided. A triangle whose cross product underflows to zero has no plane.
    fn parallel(&self, hit: Option<TriangleHit>, n: Vec3) -> Option<f32> {
        let hit = hit?;
        let [v0, v1, v2] = self.triangles[hit.triangle as usize];
        let g = (v1 - v0).cross(v2 - v0);
        let (area, along) = (g.length(), g.dot(n));
        let along = if self.double_sided {
            along.abs()
        } else {
            along
        };
        (area > 0.0 && along >= PARALLEL_COS * area).then_some(hit.t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of half-size `r` at height `z`, facing +z (-z with `down`).
    fn square(z: f32, r: f32, down: bool) -> [[Vec3; 3]; 2] {
        let v = |x: f32, y: f32| Vec3::new(x, y, z);
        let (a, b, c, d) = (v(-r, -r), v(r, -r), v(r, r), v(-r, r));
        match down {
            false => [[a, b, c], [a, c, d]],
            true => [[a, c, b], [a, d, c]],
        }
    }

    fn surfel(p: Vec3, n: Vec3) -> Surfel {
        Surfel {
            position: p.to_array(),
            normal: n.to_array(),
            weight: 1.0,
            ..Surfel::default()
        }
    }

    /// Where `s` goes in the cell `[-1, 1)^3` with surfel cells of 0.4 (reach 0.1).
    fn placed(triangles: &[[Vec3; 3]], double_sided: bool, s: Surfel) -> Vec3 {
        let surfaces = Surfaces {
            bvh: &SceneBvh::build(triangles, 1.0),
            triangles,
            cell_size: 0.4,
            double_sided,
        };
        let mut s = s;
        surfaces.place(&mut s, [Vec3::splat(-1.0), Vec3::splat(1.0)]);
        Vec3::from(s.position)
    }

    #[test]
    fn a_surfel_behind_its_surface_moves_onto_it() {
        // The mean of hits on a bent surface: 5 cm behind it, within the reach of 10 cm; a
        // double-sided scene's surface wound either way.
        let behind = surfel(Vec3::new(0.1, 0.2, -0.05), Vec3::Z);
        for (down, double_sided) in [(false, false), (false, true), (true, true)] {
            let p = placed(&square(0.0, 1.0, down), double_sided, behind);
            assert!((p - Vec3::new(0.1, 0.2, 0.0)).length() < 1e-6, "{p}");
        }
    }

    #[test]
    fn a_surfel_in_front_of_its_surface_stays_under_a_shelf() {
        // A floor surfel 1 mm above the floor, a shelf 5 cm above it (its underside facing the
        // floor, or double-sided): the shelf is not its surface.
        let p = Vec3::new(0.1, 0.2, 0.001);
        for (down, double_sided) in [(true, false), (false, true)] {
            let mut tris = square(0.0, 1.0, false).to_vec();
            tris.extend(square(0.051, 0.5, down));
            assert_eq!(placed(&tris, double_sided, surfel(p, Vec3::Z)), p);
        }
    }

    #[test]
    fn a_face_turned_towards_the_surfel_is_not_its_surface_when_single_sided() {
        let p = Vec3::new(0.0, 0.0, -0.05);
        let facing = square(0.0, 1.0, true);
        assert_eq!(placed(&facing, false, surfel(p, Vec3::Z)), p);
    }

    #[test]
    fn what_is_beyond_reach_tilted_or_outside_the_cell_stays() {
        let floor = square(0.0, 1.0, false);
        // 20 cm behind: out of reach.
        let far = Vec3::new(0.0, 0.0, -0.2);
        assert_eq!(placed(&floor, false, surfel(far, Vec3::Z)), far);
        // A surface 50 degrees off the surfel's plane is not its own.
        let p = Vec3::new(0.0, 0.0, -0.05);
        let tilt = glam::Quat::from_rotation_x(50f32.to_radians());
        let tilted: Vec<[Vec3; 3]> = floor.iter().map(|t| t.map(|v| tilt * v)).collect();
        assert_eq!(placed(&tilted, true, surfel(p, Vec3::Z)), p);
        // 40 degrees off still is.
        let tilt = glam::Quat::from_rotation_x(40f32.to_radians());
        let tilted: Vec<[Vec3; 3]> = floor.iter().map(|t| t.map(|v| tilt * v)).collect();
        assert_ne!(placed(&tilted, true, surfel(p, Vec3::Z)), p);
        // The surface on the cell's upper face belongs to the next brick.
        let top = Vec3::new(0.0, 0.0, 0.95);
        assert_eq!(
            placed(&square(1.0, 1.0, false), false, surfel(top, Vec3::Z)),
            top
        );
        // Back faces stay.
        let back = Surfel {
            flags: BRICK_BACKFACE,
            ..surfel(p, Vec3::Z)
        };
        assert_eq!(placed(&floor, false, back), p);
    }
}
