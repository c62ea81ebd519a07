//! Sparse placement: probes where surfaces need them, coarse levels in the open.
//!
//! A renderer samples the volume at surfaces. `sample_irradiance` moves the point along its
//! normal by the normal bias (0.2 spacings by default; the surface terms' lookup by its surface
//! bias, 0.1) and reads the eight probes of the grid cell around it. A probe none of whose
//! eight cells holds such a point is never read at a surface, yet on a uniform grid it costs as
//! much as any other: in the air of an open level most probes are such probes (issue 32: a
//! 200 x 200 x 40 m street at 1 m is 1.66 M probes, about 116 k of them beside surfaces).
//!
//! [`surface_probes`] keeps a grid point when some triangle comes within one lattice step plus
//! [`REACH`] spacings of it along every axis (the box its cells cover, widened by at least the
//! normal bias), by a conservative test: the triangle's bounding box overlaps that box and its
//! plane passes through it (Akenine-Moller's triangle-box test without the nine edge axes, so a
//! box beside a triangle's corner may be kept; none a surface needs is dropped); its twin
//! [`surface_cells`] marks the grid cells a surface passes through. [`plan`] builds the coarse
//! levels of `prt_format::tier` over those cells, as Unity's adaptive probe volumes refine bricks
//! only where geometry is: it traces the points surfaces need, the points 2 steps apart in
//! the 4-step cells surfaces pass through, 4 apart in the 8-step ones, and 8 apart everywhere. The others keep a record with no data ([`prt_format::NO_SLOT`]); [`mark_filled`]
//! flags those the runtime fills from their level after every gather, so that a point in open
//! air gets the light of the probes around it, interpolated without a seam where the levels
//! meet.
//!
//! The outer layers also stand for everything beyond the bounds (lookups clamp to the grid),
//! so a triangle outside the bounds keeps the outer grid points it faces.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;
use prt_format::{tier, Grid, Probe, FILL_LEVEL_SHIFT, PROBE_FILLED};
use rayon::prelude::*;

/// Spacings beyond a grid point's cells within which a surface keeps it: covers the lookups'
/// default biases (0.2 spacings, `prt_runtime::LookupSettings::normal_bias`, and
/// `prt_format::surface::SURFACE_BIAS`, the surface lookup's) with room to spare. A surface
/// point sampled with a larger bias can land in a cell whose far corners were not traced: they
/// are filled from a coarse level (or, inside geometry, weigh 0).
pub const REACH: f32 = 0.25;
const _: () = assert!(REACH > prt_format::surface::SURFACE_BIAS);

/// Spacings added to every box of the placement's tests, so that a triangle exactly on a box's
/// face (walls at round coordinates and grids of round spacings put many there) is kept at
/// every scale: without it, rounding flipped such decisions between a 2 m Cornell room and its
/// copy scaled by 0.001 (11% of a probe's SH0 apart, `tests/tests/scale.rs`). Relative to the
/// spacing, as rounding is relative to the coordinates.
pub const TOLERANCE: f32 = 1e-3;

/// Which probes of `grid` surfaces need: per grid point in grid order, whether some triangle
/// of `triangles` lies within its cells widened by [`REACH`] (module docs).
pub fn surface_probes(grid: &Grid, triangles: &[[Vec3; 3]]) -> Vec<bool> {
    near(grid, triangles, Boxes::Points)
}

/// What a sparse bake does with each grid point: trace it, or leave it to be filled from a
/// coarse level ([`prt_format::tier`]).
#[derive(Clone, Debug)]
pub struct Plan {
    /// Per grid point: 0 to trace it, else the level it is filled from.
    level: Vec<u8>,
    /// Per level 1..=[`tier::LEVELS`]: how many of its cells a surface passes through.
    busy_cells: [usize; tier::LEVELS as usize],
    /// The grid cells surfaces pass through ([`surface_cells`]), which sparse bakes also
    /// dilate into.
    cells: Vec<bool>,
}

impl Plan {
    /// Per grid point, whether the bake traces it.
    pub fn traced(&self) -> Vec<bool> {
        self.level.iter().map(|&l| l == 0).collect()
    }

    /// Per grid cell (indexed by its lowest corner), whether a surface passes through it.
    pub fn surface_cells(&self) -> &[bool] {
        &self.cells
    }
}

/// Sparse placement over `grid` for `triangles` ([`Plan`]). Per level `l`, a cell is *busy*
/// when a surface passes through it (one of its grid cells is in [`surface_cells`], which
/// covers every point [`surface_probes`] keeps). A point is traced when surfaces need it
/// ([`surface_probes`]), or it is on level `l` and lies in a busy level-`l + 1` cell, or it
/// is on the top level. Any other point is filled from the lowest level `l` whose
/// level-`l + 1` cell around it is busy (the top level where none is), whose corners are
/// therefore traced. No wall stands between a filled point and the probes it is interpolated
/// from: where its level-`l` cell is not busy, the segments stay in a cell no surface passes
/// through; where it is (level 1), the corners are at most one step from the point along each
/// axis, inside the box that [`surface_probes`] found no triangle in. One level of cells 4
/// steps wide, filled over whole cells whether a surface passed through them or not, leaked
/// light through walls into rooms (`prt-bench open-air`: 57% and 78% mean error at the filled
/// points of the two-room fixture and interior_4); docs/results/sparse.md has the variants.
pub fn plan(grid: &Grid, triangles: &[[Vec3; 3]]) -> Plan {
    let near = surface_probes(grid, triangles);
    let cells = surface_cells(grid, triangles);
    let levels = tier::LEVELS as usize;
    // Per level, per cell by its lowest corner's grid index: whether a surface passes through.
    let mut busy = vec![vec![false; cells.len()]; levels];
    for (index, _) in cells.iter().enumerate().filter(|(_, &c)| c) {
        let c = grid.ijk(index);
        for (l, busy) in busy.iter_mut().enumerate() {
            let lo: [u32; 3] =
                std::array::from_fn(|a| tier::span(grid.counts[a], c[a], l as u32 + 1).0);
            busy[grid.index(lo[0], lo[1], lo[2])] = true;
        }
    }
    let level = (0..cells.len())
        .into_par_iter()
        .map(|index| {
            let ijk = grid.ijk(index);
            // Whether a busy cell of level `l` (1..=LEVELS) holds the point.
            let in_busy = |l: u32| in_busy_cell(grid, ijk, l, &busy[l as usize - 1]);
            let traced = near[index]
                || (1..tier::LEVELS).any(|l| tier::on_level_point(grid, ijk, l) && in_busy(l + 1))
                || tier::on_level_point(grid, ijk, tier::LEVELS);
            match traced {
                true => 0,
                false => (1..tier::LEVELS)
                    .find(|&l| in_busy(l + 1))
                    .unwrap_or(tier::LEVELS) as u8,
            }
        })
        .collect();
    let busy_cells = std::array::from_fn(|l| busy[l].iter().filter(|&&b| b).count());
    Plan {
        level,
        busy_cells,
        cells,
    }
}

/// Whether a cell of `level` holding grid point `ijk` (on its boundary too) is in `busy`
/// (indexed by the cell's lowest corner).
fn in_busy_cell(grid: &Grid, ijk: [u32; 3], level: u32, busy: &[bool]) -> bool {
    let n = grid.counts;
    // The lowest corners of the cells holding the point along one axis: its own, and the one
    // below where the point is on the level (the last point of an axis starts no cell).
    let lows = |a: usize| {
        let (lo, hi, _) = tier::span(n[a], ijk[a], level);
        let own = (lo < hi || n[a] == 1).then_some(lo);
        let below = (ijk[a] == lo && lo > 0).then(|| tier::span(n[a], lo - 1, level).0);
        [own, below]
    };
    let (x, y, z) = (lows(0), lows(1), lows(2));
    x.iter().flatten().any(|&i| {
        y.iter()
            .flatten()
            .any(|&j| z.iter().flatten().any(|&k| busy[grid.index(i, j, k)]))
    })
}

/// What `plan` places ([`crate::Placed`], before [`mark_filled`] counts the filled points), and
/// the warning for a plan with no surface in the bounds.
pub fn summary(plan: &Plan) -> (crate::Placed, Option<String>) {
    let traced = plan.level.iter().filter(|&&l| l == 0).count();
    let placed = crate::Placed {
        grid: plan.level.len(),
        traced,
        busy_cells: plan.busy_cells,
        filled: [0; tier::LEVELS as usize],
    };
    let warning = (plan.busy_cells[0] == 0).then(|| {
        format!(
            "sparse placement found no surface: no triangle lies within a quarter spacing \
             of any cell of the {} grid points (check the bounds); only the {traced} probes \
             of the coarsest level light the volume",
            plan.level.len()
        )
    });
    (placed, warning)
}

/// Flags [`PROBE_FILLED`] and its level ([`prt_format::FILL_LEVEL_SHIFT`]) on every grid point of
/// `grid` the plan leaves out that has a valid point of its level with a positive weight
/// ([`tier::used_corners`]), and returns how many per level (1..=[`tier::LEVELS`]). Those points
/// are all traced, so none is filled itself (as validation requires). A point whose level's points
/// are all inside geometry stays without light, as a point inside geometry should.
pub fn mark_filled(
    grid: &Grid,
    probes: &mut [Probe],
    plan: &Plan,
) -> [usize; tier::LEVELS as usize] {
    let fill: Vec<u8> = (0..probes.len())
        .into_par_iter()
        .map(|index| {
            let level = plan.level.get(index).copied().unwrap_or(0);
            let lit = level > 0
                && tier::used_corners(grid, grid.ijk(index), u32::from(level))
                    .any(|(c, _)| probes[c].is_valid());
            if lit {
                level
            } else {
                0
            }
        })
        .collect();
    let mut counts = [0; tier::LEVELS as usize];
    for (p, &level) in probes.iter_mut().zip(&fill).filter(|(_, &l)| l > 0) {
        p.flags |= PROBE_FILLED | u32::from(level) << FILL_LEVEL_SHIFT;
        counts[level as usize - 1] += 1;
    }
    counts
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
    let tolerance = TOLERANCE * grid.spacing;
    let reach = Vec3::splat(REACH * grid.spacing + tolerance);
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
                // The point's box; an outer layer's reaches out to the triangle beyond it (and
                // the tolerance past it: the triangle is then on no face of the box), and a
                // flat axis's (one layer) covers the triangle's whole extent along it.
                let (mut lo, mut hi) = (p - below, p + above);
                for a in 0..3 {
                    if ijk[a] == 0 {
                        lo[a] = lo[a].min(tmin[a] - tolerance);
                    }
                    if ijk[a] >= outer(counts[a]) {
                        hi[a] = hi[a].max(tmax[a] + tolerance);
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

    /// Without surfaces only the top level is traced and everything else is filled from it;
    /// left-out points next to a valid point of their level are filled, those whose level's
    /// points are all invalid are not.
    #[test]
    fn without_surfaces_the_top_level_fills_the_rest() {
        let grid = Grid::cubic([0.0; 3], 1.0, [17, 9, 6]);
        let plan = plan(&grid, &[]);
        assert_eq!(plan.busy_cells, [0; tier::LEVELS as usize]);
        for k in 0..6 {
            for j in 0..9 {
                for i in 0..17 {
                    let top = i % 8 == 0 && j % 8 == 0 && (k == 0 || k == 5);
                    let level = plan.level[grid.index(i, j, k)];
                    assert_eq!(level, if top { 0 } else { 3 }, "({i}, {j}, {k})");
                }
            }
        }
        let mut probes: Vec<Probe> = plan
            .traced()
            .iter()
            .map(|&p| Probe {
                flags: if p { prt_format::PROBE_VALID } else { 0 },
                ..Probe::default()
            })
            .collect();
        // The cell x in 8..16 loses its valid corners: points inside it, and on its face x = 8
        // whose only corners are there, stay dark; points of the cell x in 0..8 are filled.
        for (i, j, k) in [(8, 0, 0), (16, 0, 0), (8, 8, 0), (16, 8, 0)] {
            for k in [k, 5] {
                probes[grid.index(i, j, k)].flags = 0;
            }
        }
        let filled = mark_filled(&grid, &mut probes, &plan);
        assert!(!probes[grid.index(9, 6, 1)].is_filled());
        assert!(probes[grid.index(2, 6, 1)].is_filled());
        assert_eq!(probes[grid.index(2, 6, 1)].fill_level(), 3);
        assert!(
            !probes[grid.index(8, 0, 0)].is_filled(),
            "traced points are never filled"
        );
        let count = probes.iter().filter(|p| p.is_filled()).count();
        assert_eq!(filled, [0, 0, count]);
    }

    /// A floor through a 17 x 17 x 17 grid at y = 0.1: the levels refine towards it. The
    /// layers y = 0 and 1 that the lookup reads at the floor are traced; going up, level-1
    /// points are traced in the level-2 cells holding the floor, level-2 points in the
    /// level-3 cells, and the points in between are filled from the lowest level whose next
    /// level's cell holds the floor.
    #[test]
    fn the_levels_refine_towards_a_surface() {
        let grid = Grid::cubic([0.0; 3], 1.0, [17, 17, 17]);
        let floor = [[
            Vec3::new(-1.0, 0.1, -1.0),
            Vec3::new(40.0, 0.1, -1.0),
            Vec3::new(-1.0, 0.1, 40.0),
        ]];
        let plan = plan(&grid, &floor);
        let at = |i, j, k| plan.level[grid.index(i, j, k)];
        for j in 0..=1 {
            assert_eq!((at(1, j, 3), at(5, j, 7)), (0, 0), "y {j}");
        }
        // y in 2..=4 (the level-2 cells holding the floor): level-1 points traced, the others
        // filled from level 1.
        assert_eq!(
            (at(2, 4, 2), at(2, 2, 6), at(1, 3, 2), at(3, 2, 5)),
            (0, 0, 1, 1)
        );
        // y in 4..=8 (the level-3 cell): level-2 points traced, others filled from level 2.
        assert_eq!((at(4, 8, 4), at(2, 6, 2), at(5, 6, 1)), (0, 2, 2));
        // Above: only level-3 points traced, the rest filled from level 3.
        assert_eq!((at(8, 16, 8), at(4, 12, 4), at(1, 9, 1)), (0, 3, 3));
        assert_eq!(plan.busy_cells, [64, 16, 4]);
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
