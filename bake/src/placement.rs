//! Sparse placement: probes only at the grid points that surfaces need.
//!
//! A renderer samples the volume at surfaces. `sample_irradiance` moves the point along its
//! normal by the normal bias (0.2 spacings by default) and reads the eight probes of the grid
//! cell around it; the surface terms' lookup weights the same eight. A probe none of whose
//! eight cells holds such a point is never read at a surface, yet on a uniform grid it costs as
//! much as any other: in the air of an open level most probes are such probes (issue 32: a
//! 200 x 200 x 40 m street at 1 m is 1.66 M probes, about 116 k of them beside surfaces).
//!
//! [`surface_probes`] keeps a grid point when some triangle comes within one lattice step plus
//! [`REACH`] spacings of it along every axis (the box its cells cover, widened by at least the
//! normal bias), by a conservative test: the triangle's bounding box overlaps that box and its
//! plane passes through it (Akenine-Moller's triangle-box test without the nine edge axes, so a
//! box beside a triangle's corner may be kept; none a surface needs is dropped). The bake traces
//! those probes (the fine tier) and the coarse tier's ([`prt_format::tier`]: every fourth grid
//! point along each axis), [`sparse_probes`]. The others keep a record with no data
//! ([`prt_format::NO_SLOT`]); [`mark_filled`] flags those the runtime fills from the coarse
//! tier after every gather, so that a point in open air far from every surface gets the coarse
//! tier's light, interpolated without a seam where it meets the fine tier.
//!
//! The outer layers also stand for everything beyond the bounds (lookups clamp to the grid),
//! so a triangle outside the bounds keeps the outer grid points it faces.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;
use prt_format::{tier, Grid, Probe, PROBE_FILLED};
use rayon::prelude::*;

/// Spacings beyond a grid point's cells within which a surface keeps it: covers the lookup's
/// default normal bias (0.2 spacings, `prt_runtime::LookupSettings::normal_bias`) with room to
/// spare. A surface point sampled with a larger bias can land in a cell whose far corners were
/// not placed; those weigh 0 and the lookup renormalises over the rest.
pub const REACH: f32 = 0.25;

/// Which probes of `grid` surfaces need: per grid point in grid order, whether some triangle
/// of `triangles` lies within its cells widened by [`REACH`] (module docs).
pub fn surface_probes(grid: &Grid, triangles: &[[Vec3; 3]]) -> Vec<bool> {
    near(grid, triangles, Boxes::Points)
}

/// What a sparse bake traces: per grid point, whether surfaces need it ([`surface_probes`]) or
/// it is on the coarse tier ([`tier::is_coarse_point`]); and how many the surfaces need.
pub fn sparse_probes(grid: &Grid, triangles: &[[Vec3; 3]]) -> (Vec<bool>, usize) {
    let mut placed = surface_probes(grid, triangles);
    let near = placed.iter().filter(|&&p| p).count();
    let n = grid.counts;
    placed.par_iter_mut().enumerate().for_each(|(index, p)| {
        let i = index as u32;
        *p |= tier::is_coarse_point(grid, [i % n[0], i / n[0] % n[1], i / (n[0] * n[1])]);
    });
    (placed, near)
}

/// Flags [`PROBE_FILLED`] on every grid point of `grid` the placement left out (`placed`
/// false) that has a valid coarse point with a positive weight ([`tier::corners`]), and
/// returns how many. The coarse points are all placed, so none of a filled point's corners is
/// filled itself (as validation requires). A point whose coarse points are all inside
/// geometry stays without light, as a point inside geometry should.
pub fn mark_filled(grid: &Grid, probes: &mut [Probe], placed: &[bool]) -> usize {
    let n = grid.counts;
    let fill: Vec<bool> = (0..probes.len())
        .into_par_iter()
        .map(|index| {
            let i = index as u32;
            let ijk = [i % n[0], i / n[0] % n[1], i / (n[0] * n[1])];
            !placed[index]
                && tier::corners(grid, ijk)
                    .iter()
                    .any(|&(c, w)| w > 0.0 && probes[c].is_valid())
        })
        .collect();
    for (p, _) in probes.iter_mut().zip(&fill).filter(|(_, &f)| f) {
        p.flags |= PROBE_FILLED;
    }
    fill.iter().filter(|&&f| f).count()
}

/// Which cells of `grid` surfaces pass through: per cell, indexed by its lowest corner's grid
/// index, whether some triangle of `triangles` lies within the cell widened by [`REACH`]
/// spacings (the last index along an axis names no cell and is never marked).
/// Sparse bakes dilate only into cells a surface needs (`crate::dilate`).
pub fn surface_cells(grid: &Grid, triangles: &[[Vec3; 3]]) -> Vec<bool> {
    near(grid, triangles, Boxes::Cells)
}

/// What a grid index stands for in [`near`]: its point's cells, or the cell it is the lowest
/// corner of.
#[derive(Clone, Copy, PartialEq)]
enum Boxes {
    Points,
    Cells,
}

/// Per grid index, whether a triangle overlaps its box ([`Boxes`]).
fn near(grid: &Grid, triangles: &[[Vec3; 3]], boxes: Boxes) -> Vec<bool> {
    let count = grid.probe_count() as usize;
    let keep: Vec<AtomicBool> = (0..count).map(|_| AtomicBool::new(false)).collect();
    triangles.par_iter().for_each(|t| {
        for_boxes_near(grid, t, boxes, |index| {
            keep[index].store(true, Ordering::Relaxed)
        });
    });
    keep.into_iter().map(AtomicBool::into_inner).collect()
}

/// Calls `f` with every grid index whose widened box ([`Boxes`]) triangle `t` overlaps.
fn for_boxes_near(grid: &Grid, t: &[Vec3; 3], boxes: Boxes, mut f: impl FnMut(usize)) {
    let (tmin, tmax) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    let origin = Vec3::from(grid.origin);
    let step = Vec3::from(grid.step);
    let reach = Vec3::splat(REACH * grid.spacing);
    // The box of index p is [p - below, p + above].
    let (below, above) = match boxes {
        Boxes::Points => (step + reach, step + reach),
        Boxes::Cells => (reach, step + reach),
    };
    // The last index along an axis: the outer layer, or the last cell.
    let outer = |n: u32| match boxes {
        Boxes::Points => n.saturating_sub(1),
        Boxes::Cells => n.saturating_sub(2),
    };
    let counts = grid.counts;
    // The indices whose boxes the triangle's bounding box overlaps, clamped to the grid (the
    // outer layers and cells stand for what lies beyond it).
    let range = |a: usize| -> Option<(u32, u32)> {
        let n = counts[a];
        if n <= 1 {
            return Some((0, 0));
        }
        let lo = ((tmin[a] - above[a] - origin[a]) / step[a]).ceil();
        let hi = ((tmax[a] + below[a] - origin[a]) / step[a]).floor();
        let last = outer(n) as f32;
        // Infinite bounds (a triangle that overflows f32) clamp to the grid's ends.
        if lo.is_nan() || hi.is_nan() {
            return None;
        }
        let (lo, hi) = (lo.clamp(0.0, last), hi.clamp(0.0, last));
        (lo <= hi).then_some((lo as u32, hi as u32))
    };
    let (Some(rx), Some(ry), Some(rz)) = (range(0), range(1), range(2)) else {
        return;
    };
    let normal = (t[1] - t[0]).cross(t[2] - t[0]);
    let plane = normal.dot(t[0]);
    for k in rz.0..=rz.1 {
        for j in ry.0..=ry.1 {
            for i in rx.0..=rx.1 {
                let ijk = [i, j, k];
                let p = Vec3::from(grid.position(i, j, k));
                // The point's box; an outer layer's reaches out to the triangle beyond it, and
                // a flat axis's (one layer) covers the triangle's whole extent along it.
                let (mut lo, mut hi) = (p - below, p + above);
                for a in 0..3 {
                    if ijk[a] == 0 {
                        lo[a] = lo[a].min(tmin[a]);
                    }
                    if ijk[a] >= outer(counts[a]) {
                        hi[a] = hi[a].max(tmax[a]);
                    }
                }
                if overlaps(normal, plane, (tmin, tmax), (lo, hi)) {
                    f(grid.index(i, j, k));
                }
            }
        }
    }
}

/// Whether a triangle (plane `normal . x = plane`, bounding box `tri`) may overlap the box:
/// their bounding boxes overlap and the plane passes within the box, or the plane test
/// overflows (conservative: a triangle of huge coordinates keeps the points it may touch).
fn overlaps(normal: Vec3, plane: f32, tri: (Vec3, Vec3), (lo, hi): (Vec3, Vec3)) -> bool {
    if tri.0.cmpgt(hi).any() || tri.1.cmplt(lo).any() {
        return false;
    }
    let (centre, extent) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let distance = normal.dot(centre) - plane;
    let radius = extent.dot(normal.abs());
    // NaN (an overflowed plane test) counts as a hit.
    distance.abs() <= radius || distance.is_nan() || radius.is_nan()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A floor at y = 0.1 over a 5 x 5 x 5 grid of step 1 keeps the layers y = 0 and y = 1,
    /// whose cells hold it; y = 2 is 1.9 away, beyond a step and REACH.
    #[test]
    fn a_floor_keeps_the_two_layers_around_it() {
        let grid = Grid::cubic([0.0; 3], 1.0, [5, 5, 5]);
        let floor = [
            [
                Vec3::new(-1.0, 0.1, -1.0),
                Vec3::new(9.0, 0.1, -1.0),
                Vec3::new(-1.0, 0.1, 9.0),
            ],
            [
                Vec3::new(9.0, 0.1, -1.0),
                Vec3::new(9.0, 0.1, 9.0),
                Vec3::new(-1.0, 0.1, 9.0),
            ],
        ];
        let keep = surface_probes(&grid, &floor);
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..5 {
                    assert_eq!(keep[grid.index(i, j, k)], j <= 1, "({i}, {j}, {k})");
                }
            }
        }
    }

    /// A slanted triangle keeps the points whose boxes its plane crosses, not its whole
    /// bounding box; one outside the bounds keeps the outer layer it faces.
    #[test]
    fn slanted_and_outside_triangles() {
        let grid = Grid::cubic([0.0; 3], 1.0, [9, 9, 9]);
        let slant = [[
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(8.0, 8.0, 0.0),
            Vec3::new(0.0, 0.0, 8.0),
        ]];
        let keep = surface_probes(&grid, &slant);
        // The plane x = y: a point is within 1.25 of it along both axes' boxes when
        // |x - y| <= 2.5.
        for j in 0..9 {
            for i in 0..9 {
                let near = (i as i32 - j as i32).abs() <= 2;
                assert_eq!(keep[grid.index(i, j, 4)], near, "({i}, {j})");
            }
        }
        assert!(keep.iter().filter(|&&k| k).count() < keep.len() / 2);
        let beyond = [[
            Vec3::new(20.0, 1.0, 1.0),
            Vec3::new(20.0, 2.0, 1.0),
            Vec3::new(20.0, 1.0, 2.0),
        ]];
        let keep = surface_probes(&grid, &beyond);
        assert!(keep[grid.index(8, 1, 1)] && keep[grid.index(8, 2, 2)]);
        assert!(!keep[grid.index(7, 1, 1)]);
    }

    /// A floor at y = 0.1 passes through the cells of the layer y = 0 (0 to 1) and, within
    /// REACH, of none other; the last index along an axis names no cell.
    #[test]
    fn a_floor_passes_through_one_layer_of_cells() {
        let grid = Grid::cubic([0.0; 3], 1.0, [4, 4, 4]);
        let floor = [[
            Vec3::new(-1.0, 0.1, -1.0),
            Vec3::new(9.0, 0.1, -1.0),
            Vec3::new(-1.0, 0.1, 9.0),
        ]];
        let cells = surface_cells(&grid, &floor);
        for k in 0..4 {
            for j in 0..4 {
                for i in 0..4 {
                    let expected = j == 0 && i < 3 && k < 3;
                    assert_eq!(cells[grid.index(i, j, k)], expected, "({i}, {j}, {k})");
                }
            }
        }
    }

    /// The coarse tier is placed wherever surfaces are not; left-out points next to a valid
    /// coarse point are filled, those whose coarse points are all invalid are not.
    #[test]
    fn the_coarse_tier_is_placed_and_fills_the_rest() {
        let grid = Grid::cubic([0.0; 3], 1.0, [9, 9, 6]);
        let (placed, near) = sparse_probes(&grid, &[]);
        assert_eq!(near, 0);
        for k in 0..6 {
            for j in 0..9 {
                for i in 0..9 {
                    let coarse = i % 4 == 0 && j % 4 == 0 && (k % 4 == 0 || k == 5);
                    assert_eq!(placed[grid.index(i, j, k)], coarse, "({i}, {j}, {k})");
                }
            }
        }
        let mut probes: Vec<Probe> = placed
            .iter()
            .map(|&p| Probe {
                flags: if p { prt_format::PROBE_VALID } else { 0 },
                ..Probe::default()
            })
            .collect();
        // The coarse cell x, y in 4..8 loses its valid corners: points strictly inside it stay
        // dark, points on its faces shared with valid cells are filled.
        for k in [0, 4, 5] {
            for (i, j) in [(4, 4), (8, 4), (4, 8), (8, 8)] {
                probes[grid.index(i, j, k)].flags = 0;
            }
        }
        let filled = mark_filled(&grid, &mut probes, &placed);
        assert!(!probes[grid.index(5, 6, 1)].is_filled());
        assert!(probes[grid.index(2, 6, 1)].is_filled());
        assert!(
            !probes[grid.index(4, 4, 0)].is_filled(),
            "placed points are never filled"
        );
        assert_eq!(filled, probes.iter().filter(|p| p.is_filled()).count());
    }

    /// A triangle whose plane test overflows f32 keeps the points it may touch (a huge quad
    /// over the whole grid keeps all of them); one of all-NaN corners keeps none. No panic.
    #[test]
    fn huge_and_nan_triangles() {
        let grid = Grid::cubic([0.0; 3], 1.0, [3, 3, 3]);
        let huge = [[
            Vec3::new(-3e38, 1.0, -3e38),
            Vec3::new(3e38, 1.0, -3e38),
            Vec3::new(-3e38, 1.0, 3e38),
        ]];
        assert!(surface_probes(&grid, &huge).iter().all(|&k| k));
        let nan = [[Vec3::NAN; 3]];
        assert!(surface_probes(&grid, &nan).iter().all(|&k| !k));
    }
}
