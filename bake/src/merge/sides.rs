//! Which side of a wall in its surfel cell a ray hit lies on.
//!
//! A surfel is the mean of the hits of one cell whose normals agree ([`crate::merge::fold`]).
//! Where a zero-thickness wall crosses the cell (a partition meeting a ceiling, a floor or
//! another wall), the hits of both rooms made one surfel whose mean lies on the side with more
//! hits, and a point on the other side read that surfel's probes: on stop 66's blind
//! interior_156 a dark-room ceiling point 7.5 mm from a partition read the lit room's probes,
//! 12.7x its truth (docs/results/surface_stop67_sides.md). Splitting bricks at walls
//! ([`crate::merge::split`]) parts surfels, not the hits of one cell.
//!
//! So each hit is tested against its cell's centre (a little off it, [`REFERENCE_SHIFT`], and
//! moved onto the hit's plane), both lifted off the surface as the split's links are
//! ([`LIFT_CELLS`] cells, so that the relief of a detailed surface does not split it), and
//! where nothing stands in the way there, a tenth of a cell off it ([`LOW_LIFT_CELLS`]), where
//! only a wall that leans over the surface counts: a hit a wall parts from the centre is
//! `across`, and the fold merges it only with hits across too. One or two rays per hit, traced
//! with the probe that made it, in parallel. The surface lookup then tells
//! a point which of the cell's two surfels lies on its side ([`sides_of`],
//! `prt_format::surface::SurfaceSide`).

use glam::Vec3;
use prt_format::surface::{encode_normal, SurfaceSide, SurfaceTerms, CELL_WORDS, NO_SURFEL};
use prt_format::{Brick, Surfel};

use crate::accel::bvh::SceneBvh;
use crate::merge::key::cell_centre;
use crate::merge::split::LIFT_CELLS;
use crate::trace::Hit;

/// Where in its cell the point a hit is tested against lies, from the cell's centre, in cells:
/// a few hundredths off it, since the bake puts walls at round coordinates in the middle of
/// cells (`crate::merge::fold::BrickFolder::new`), where a segment to the centre would end on
/// the wall and rounding would decide.
const REFERENCE_SHIFT: [f32; 3] = [0.0123, 0.0234, 0.0345];

/// Cells off the surface a second segment runs where the first ([`LIFT_CELLS`]) hits nothing:
/// a wall that leans over the surface (an awning sloping down from a facade) lies lower than a
/// cell a little way out, so the segment lifted a cell passes over it and the hits beneath it
/// merged with those above. On stop 68's street_198 (a blind level) a facade point 9 cm under
/// the line where an awning meets it read the sunlit surfel above, 11.5x its truth. What the low segment
/// meets parts hits only where it reaches a cell or more off the surface ([`stands_off`]): a
/// wall leaning over it, not relief on it (without that test Sponza's sides went from 5,043 to
/// 11,771 at 1.5 m; docs/results/surface_stop68.md). Only a tenth was measured.
pub const LOW_LIFT_CELLS: f32 = 0.1;

/// Marks the hits of `hits` that a wall in their surfel cell (cells of `cell_size` from
/// `anchor`) parts from the cell's centre. Back faces (bricks of their own) and hits at the
/// centre are left unmarked; nothing is marked when merging is off (`cell_size` 0).
pub fn mark_across(
    hits: &mut [Hit],
    scene: (&SceneBvh, &[[Vec3; 3]]),
    anchor: Vec3,
    cell_size: f32,
) {
    if cell_size <= 0.0 {
        return;
    }
    let (bvh, triangles) = scene;
    let (lift, low) = (LIFT_CELLS * cell_size, LOW_LIFT_CELLS * cell_size);
    // Segments shorter than a thousandth of a cell cross no wall worth a surfel.
    let shortest = (1e-3 * cell_size).powi(2);
    let shift = Vec3::from(REFERENCE_SHIFT) * cell_size;
    for h in hits.iter_mut().filter(|h| !h.backface) {
        let reference = cell_centre(h.position, anchor, cell_size) + shift;
        let to = (reference - h.position).reject_from_normalized(h.normal);
        if to.length_squared() > shortest {
            let (p, n) = (h.position, h.normal);
            h.across = bvh.occluded(p + lift * n, &[to], 1.0) & 1 != 0
                || bvh
                    .closest_hit(p + low * n, to, 1.0)
                    .is_some_and(|hit| stands_off(&triangles[hit.triangle as usize], p, n, lift));
        }
    }
}

/// Whether `triangle`, met by the low segment, reaches `lift` or more off the plane through
/// `p` with normal `n`: a wall that leans over the surface, not relief on it. This depends on
/// how the mesh is cut as well as on its shape: a shallow ramp or bevel of large triangles
/// reaches a cell off the plane too, and parts the hits at its foot (docs/limits.md).
fn stands_off(triangle: &[Vec3; 3], p: Vec3, n: Vec3, lift: f32) -> bool {
    triangle.iter().any(|&v| n.dot(v - p) >= lift)
}

/// What [`sides_of`] pairs surfels with: the scene, the surfels (asset indices, up to the end
/// of the brick's key run), which of them a side may name, and the fold's normal agreement.
pub struct Pairing<'a> {
    pub bvh: &'a SceneBvh,
    /// The scene's triangles, by the BVH's triangle index.
    pub triangles: &'a [[Vec3; 3]],
    pub surfels: &'a [Surfel],
    /// Per surfel, whether a side may name it: traced, and of a near group its key's first
    /// brick can count to.
    pub eligible: &'a [bool],
    /// The fold merges hits whose normals agree to this cosine: two surfels of one cell that
    /// agree as well were parted by a wall ([`mark_across`]), not by their normals.
    pub merge_normal_cos: f32,
}

/// The sides of brick `b`'s cells (`table`, the cell table of `crate::surface_terms`): for
/// each cell whose named surfel lies in it, the other surfel of the cell nearest its centre
/// that faces the same way (within the fold's normal agreement) and that a wall parts from
/// it: the segment between the two, each lifted [`LIFT_CELLS`] along its normal as the bake's
/// splits test ([`crate::merge::split`]), hits a triangle, or where it does not, the segment
/// lifted [`LOW_LIFT_CELLS`] hits a wall that leans over the surface ([`stands_off`], as
/// [`mark_across`] tests). The side's plane is that triangle's line in the named surfel's
/// plane (the segment's direction where the wall lies within about 6 degrees of that plane),
/// kept only where it parts the two surfels by more than [`SEPARATION`] cells; a point beyond
/// it reads the other surfel ([`SurfaceTerms::side_of`]).
pub fn sides_of(
    terms: &SurfaceTerms,
    pairing: &Pairing,
    b: &Brick,
    table: &[u32; CELL_WORDS],
) -> Vec<SurfaceSide> {
    let surfels = pairing.surfels;
    let key = terms.key_of(b.centroid);
    let corner = Vec3::from(terms.key_corner(key));
    let cell = terms.header.brick_size / 4.0;
    let first = b.first_surfel as usize;
    // The lookup's cell of each surfel of the run, once: every surfel in exactly one, so one
    // side at most.
    let cell_of: Vec<usize> = (surfels[first..].iter())
        .map(|s| terms.cell_of(key, s.position))
        .collect();
    let in_cell = |c: usize, i: usize| cell_of[i - first] == c;
    let mut sides = Vec::new();
    for c in 0..64 {
        let named = (table[c / 4] >> (8 * (c % 4))) as u8;
        if named == NO_SURFEL || !in_cell(c, first + usize::from(named)) {
            continue;
        }
        let s0 = first + usize::from(named);
        let centre = Vec3::from(terms.cell_centre(key, c));
        let n0 = Vec3::from(surfels[s0].normal);
        let mut others: Vec<usize> = (first..surfels.len())
            .filter(|&i| i != s0 && pairing.eligible[i] && in_cell(c, i))
            .filter(|&i| Vec3::from(surfels[i].normal).dot(n0) >= pairing.merge_normal_cos)
            .collect();
        let d = |i: &usize| Vec3::from(surfels[*i].position).distance_squared(centre);
        others.sort_by(|a, b| d(a).total_cmp(&d(b)).then(a.cmp(b)));
        let side = others
            .into_iter()
            .find_map(|s1| side_between(pairing, (s0, s1), corner, cell));
        sides.extend(side);
    }
    sides
}

/// Least distance, in cells, between a side's plane and each of its two surfels: a plane
/// closer to either would decide its own surfel's points by rounding.
pub const SEPARATION: f32 = 0.01;

/// The side of surfel `s0` towards `s1` (docs of [`sides_of`]), or `None` when nothing
/// stands between them or the wall's line does not part them.
fn side_between(
    pairing: &Pairing,
    (s0, s1): (usize, usize),
    corner: Vec3,
    cell: f32,
) -> Option<SurfaceSide> {
    let at = |s: usize| {
        let s = &pairing.surfels[s];
        (Vec3::from(s.position), Vec3::from(s.normal))
    };
    let ((p0, n0), (p1, n1)) = (at(s0), at(s1));
    let segment = |lift: f32| {
        let from = p0 + lift * n0;
        (from, p1 + lift * n1 - from)
    };
    let lift = LIFT_CELLS * cell;
    let (from, to) = segment(lift);
    let (from, to, hit) = match pairing.bvh.closest_hit(from, to, 1.0) {
        Some(hit) => (from, to, hit),
        None => {
            let (from, to) = segment(LOW_LIFT_CELLS * cell);
            let hit = pairing.bvh.closest_hit(from, to, 1.0)?;
            let triangle = &pairing.triangles[hit.triangle as usize];
            stands_off(triangle, p0, n0, lift).then_some((from, to, hit))?
        }
    };
    let x = from + hit.t * to;
    let [a, b, c] = pairing.triangles[hit.triangle as usize];
    let wall = (b - a).cross(c - a).normalize_or_zero();
    let across = wall.reject_from_normalized(n0);
    // The wall's line in the surfel's plane: the points y of that plane with
    // wall . (y - x) = 0, that is n . (y - p0) = wall . (x - p0) / k (taken from p0, not the
    // origin, for the precision far from it). Where the wall lies within 6 degrees of the
    // plane (its normal's part across it, k, under 0.1) that line is ill-conditioned: the
    // segment's direction, through the hit.
    let (n, through) = if across.length() > 0.1 {
        let k = across.length();
        let n = across / k;
        let y = x - n0 * n0.dot(x - p0);
        (n, y + n * (wall.dot(x - p0) / k - n.dot(y - p0)))
    } else {
        (to.reject_from_normalized(n0).normalize_or_zero(), x)
    };
    if !n.is_finite() || n == Vec3::ZERO {
        return None;
    }
    // Towards s1, and as the lookup decodes it.
    let n = if n.dot(p1 - p0) < 0.0 { -n } else { n };
    let normal = encode_normal(n.to_array());
    let n = Vec3::from(prt_format::surface::decode_normal(normal));
    let offset = n.dot(through - corner);
    let margin = SEPARATION * cell;
    let parts = n.dot(p0 - corner) < offset - margin && n.dot(p1 - corner) > offset + margin;
    parts.then_some(SurfaceSide {
        surfel: s0 as u32,
        partner: s1 as u32,
        normal,
        offset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two triangles of the square `at([-1, 1]^2)`.
    fn square(at: impl Fn(f32, f32) -> Vec3) -> [[Vec3; 3]; 2] {
        let (a, b, c, d) = (at(-1.0, -1.0), at(1.0, -1.0), at(1.0, 1.0), at(-1.0, 1.0));
        [[a, b, c], [a, c, d]]
    }

    /// A ceiling at y = 1 with a partition at x = 0.03 in the cell [0, 0.1]: hits on the far
    /// side of the partition from the cell's centre (0.05) are across, those on its side are
    /// not, and without the partition none is; a partition through the centre (x = 0.05)
    /// parts the hits too.
    #[test]
    fn a_partition_in_the_cell_parts_its_hits() {
        let down = Vec3::NEG_Y;
        let ceiling = square(|u, v| Vec3::new(u, 1.0, v));
        let partition = square(|u, v| Vec3::new(0.03, u, v));
        let hits = || [0.01, 0.02, 0.04, 0.09].map(|x| Hit::grey(0, Vec3::new(x, 1.0, 0.05), down));
        let across = |triangles: &[[Vec3; 3]]| {
            let mut h = hits();
            let bvh = SceneBvh::build(triangles, 1.0);
            mark_across(&mut h, (&bvh, triangles), Vec3::ZERO, 0.1);
            h.map(|h| h.across)
        };
        let walled = [ceiling, partition].concat();
        assert_eq!(across(&walled), [true, true, false, false]);
        let through = partition.map(|t| t.map(|v| v + Vec3::X * 0.02));
        assert_eq!(
            across(&[ceiling, through].concat()),
            [true, true, true, false]
        );
        assert_eq!(across(&ceiling), [false; 4]);
    }

    /// A facade at z = 0 with an awning that leaves it at y = 0.03 and slopes down outwards
    /// (0.45 down per unit out), in the cell [0, 0.1]: a cell out, the awning is below every
    /// hit, so only the low segment ([`LOW_LIFT_CELLS`]) parts the hits beneath it from the
    /// cell's centre, and the two surfels get a side along the awning's line; relief shorter
    /// than a cell parts nothing ([`stands_off`]).
    #[test]
    fn an_awning_over_the_cell_parts_the_hits_beneath_it() {
        let out = Vec3::Z;
        let facade = square(|u, v| Vec3::new(u, v, 0.0));
        let awning = square(|u, v| {
            let z = (v + 1.0) / 2.0;
            Vec3::new(u, 0.03 - 0.45 * z, z)
        });
        let across = |triangles: &[[Vec3; 3]]| {
            let mut h =
                [0.01, 0.02, 0.04, 0.09].map(|y| Hit::grey(0, Vec3::new(0.05, y, 0.0), out));
            let bvh = SceneBvh::build(triangles, 1.0);
            mark_across(&mut h, (&bvh, triangles), Vec3::ZERO, 0.1);
            h.map(|h| h.across)
        };
        assert_eq!(
            across(&[facade, awning].concat()),
            [true, true, false, false]
        );
        // Relief: a ridge lower than the low segment, and one above it but short of a cell.
        for height in [0.005, 0.05] {
            let ridge = square(|u, v| Vec3::new(u, 0.03, (v + 1.0) * height / 2.0));
            assert_eq!(across(&[facade, ridge].concat()), [false; 4], "{height}");
        }
        // The surfels beneath and above the awning get a side along its line, y = 0.03.
        let triangles = [facade, awning].concat();
        let bvh = SceneBvh::build(&triangles, 1.0);
        let surfel = |y: f32| Surfel {
            position: [0.05, y, 0.0],
            normal: out.to_array(),
            ..Surfel::default()
        };
        let surfels = [surfel(0.06), surfel(0.015)];
        let pairing = Pairing {
            bvh: &bvh,
            triangles: &triangles,
            surfels: &surfels,
            eligible: &[true, true],
            merge_normal_cos: 0.9,
        };
        let side = side_between(&pairing, (0, 1), Vec3::ZERO, 0.1).expect("a side");
        let n = Vec3::from(prt_format::surface::decode_normal(side.normal));
        assert!(n.dot(Vec3::NEG_Y) > 0.999, "{n}");
        assert!((side.offset + 0.03).abs() < 1e-3, "{}", side.offset);
    }
}
