//! Moving probes to where their rays mean something: off surfaces they lie on (a grid that
//! coincides with a wall puts probes on it, and a probe on a wall sees both of its sides), and,
//! out of geometry through the nearest back side their rays hit (virtual offset, as in Unity's
//! adaptive probe volumes).

use glam::Vec3;

use crate::trace;

/// Spacings within which a probe counts as on a surface.
pub const NEAR_SURFACE: f32 = 0.02;
/// Spacings from the surface that a probe on it moves to: near enough to see what the surface
/// sees (the probes on the bounds' faces stand in for the walls there), far enough for its rays
/// to start clear of it. On the Cornell surface reference 0.05 was as accurate as 0.03 and
/// better than 0.1.
pub const SURFACE_OFFSET: f32 = 0.05;
/// Spacings that the on-surface search starts off the grid point, towards the bounds' centre
/// ([`surface_offset`]): above float rounding near the origin (1e-3 of a spacing is about 2^-10
/// of it), well below [`NEAR_SURFACE`]. Far from the origin the search raises it to two float
/// steps of the coordinates, up to half of [`NEAR_SURFACE`] per axis; beyond about 80,000
/// spacings from the origin a float step exceeds that and the search runs below float
/// resolution (tests/tests/scale.rs).
pub const NUDGE: f32 = 1e-3;

/// Spacings past the face a probe moved out of geometry lands ([`virtual_offset`]): as far as a
/// probe on a surface moves off it ([`SURFACE_OFFSET`]). On the level family's tuning seeds
/// 0.05, 0.02 and 0.001 measured alike (median level 9.5%, 9.4%, 9.3%; worst 12.2%, 12.2%,
/// 12.1%); nearer faces left the moved probe's hits within float rounding of surfel-cell
/// boundaries 1 km from the origin, where it then relit up to 45% of SH0 (0.001) or 7% (0.02)
/// apart from the same probe at the origin (0.5% at 0.05; tests/tests/scale.rs).
pub const PAST_FACE: f32 = SURFACE_OFFSET;

/// The 26 unit directions to the neighbours of a grid cell, in a fixed order.
fn near_directions() -> impl Iterator<Item = Vec3> {
    (0..27).filter(|&i| i != 13).map(|i| {
        Vec3::new(
            (i % 3) as f32 - 1.0,
            ((i / 3) % 3) as f32 - 1.0,
            (i / 9) as f32 - 1.0,
        )
        .normalize()
    })
}

/// A probe within [`NEAR_SURFACE`] spacings of a surface (found by short rays through its
/// position along 26 directions: axes, face and corner diagonals) moves to [`SURFACE_OFFSET`]
/// spacings from it: to the front for a single-sided surface (its back is inside geometry); for a
/// double-sided one on the grid's outer layers, to the side that faces `centre` (the bounds'
/// centre: those layers lie on a building's outer walls, and outside them is open air that the
/// building's inside must not sample), else the side it is on, else the front. Repeated up to
/// three times, for corners. Deterministic: fixed directions and order.
///
/// The short rays start [`NUDGE`] spacings (or two float steps of the coordinates, if more)
/// along `inwards` (per axis +1 or -1: towards the grid's middle, by grid index so that rounding
/// cannot flip it) from the probe: a probe exactly on a surface's edge (the outer layers lie on
/// the bounds' faces, which the scene's outermost edges touch) otherwise sits on a knife-edge
/// where rounding decides whether the short rays hit, and that rounding changes with the
/// scene's scale (tests/tests/scale.rs). Which side and where the probe moves are decided from
/// the probe itself; a probe that does not move keeps its position exactly.
pub fn surface_offset(
    tracer: &trace::Tracer,
    p: Vec3,
    spacing: f32,
    inwards: Vec3,
    centre: Option<Vec3>,
) -> Vec3 {
    let eps = NEAR_SURFACE * spacing;
    // At least two float steps of the coordinates, so that far from the origin the nudge is
    // not rounded away, and at most half the on-surface distance.
    let ulp = p.abs().max_element() * f32::EPSILON;
    let nudge = inwards * (NUDGE * spacing).max(2.0 * ulp).min(0.5 * eps);
    // `at` is where the probe is; the short rays start from `at + nudge`, off any edge.
    let mut at = p;
    'moves: for _ in 0..3 {
        let search = at + nudge;
        // The rays span `search +- eps`; their triangles are gathered once (with room for
        // rounding: more candidates never change a closest hit).
        let near = tracer.bvh.near(search, 2.0 * eps);
        for d in near_directions() {
            let o = search - d * eps;
            let Some(h) = near.closest_hit(o, d, 2.0 * eps) else {
                continue;
            };
            let tri = h.triangle as usize;
            let v = tracer.scene.triangles[tri];
            let trace::TriangleShading {
                normal: n,
                material,
            } = tracer.shading[tri];
            if n == Vec3::ZERO {
                continue;
            }
            let material = &tracer.scene.materials[material as usize];
            let double_sided = material.double_sided || tracer.double_sided;
            // Signed distance of the probe from the triangle's plane (front positive).
            let side = (at - v[0]).dot(n);
            let inward = centre.map_or(0.0, |c| (c - at).dot(n));
            let towards = if !double_sided {
                n
            } else if inward.abs() > 1e-3 * eps {
                n * inward.signum()
            } else if side < -1e-3 * eps {
                -n
            } else {
                n
            };
            let target = v[0] + (at - v[0]).reject_from_normalized(n);
            at = target + towards * (SURFACE_OFFSET * spacing);
            continue 'moves;
        }
        break;
    }
    at
}

/// Virtual offset of a probe inside geometry: the nearest hit on the back side of its
/// triangle's winding is the wall it is behind (a single-sided back face, or the inside of a
/// closed, outward-wound solid whose faces are double-sided: a thick wall); the probe moves
/// just past it along that ray (at most half a spacing) and is traced again. Returns the new
/// position and rays when the probe is valid there.
///
/// On by default (`BakeSettings::virtual_offset`): a grid layer that falls just inside a thick
/// wall left the wall's face without probes, its points extrapolated from the next layer in
/// (fixtures/thick_walls.gltf at 0.298 m: 2,273 of 4,046 probes dilated, surface error 7.7%;
/// moved out, 42 dilated and 3.5%). Chosen on the level family's tuning seeds at stop 35's
/// 1,000-probe grid (`prt-bench surface`: median level 10.2% -> 9.5%, worst 17.7% -> 12.2%,
/// worst leaks 1.7% -> 0.7%).
pub fn virtual_offset(
    tracer: &trace::Tracer,
    origin: Vec3,
    rays: &trace::ProbeRays,
    spacing: f32,
    is_inside: &dyn Fn(&trace::ProbeRays) -> bool,
) -> Option<(Vec3, trace::ProbeRays)> {
    let nearest = rays.hits.iter().filter(|h| h.facing_away).min_by(|a, b| {
        (a.position - origin)
            .length_squared()
            .total_cmp(&(b.position - origin).length_squared())
            .then(a.ray.cmp(&b.ray))
    })?;
    let dir = tracer.directions[nearest.ray as usize];
    // Where four float steps of the coordinates exceed PAST_FACE spacings the coordinates
    // cannot place a probe that near a face, and it stays (tests/tests/scale.rs).
    let step = 4.0 * f32::EPSILON * nearest.position.abs().max_element();
    if step > PAST_FACE * spacing {
        return None;
    }
    let moved = nearest.position + dir * (PAST_FACE * spacing);
    if (moved - origin).length() > 0.5 * spacing {
        return None;
    }
    let again = tracer.trace_probe(moved);
    (!is_inside(&again)).then_some((moved, again))
}
