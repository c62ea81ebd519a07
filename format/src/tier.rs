//! # The coarse levels of sparse placement: open air lit from lattices 2, 4 and 8 steps apart
//!
//! Level `l` of the grid (1..=[`LEVELS`]) is its sub-lattice of every `2^l`-th index along each
//! axis plus each axis's last index ([`on_level`]); its cells ([`span`]) are `2^l` grid steps
//! wide (less at the last). A sparse bake (`prt_bake::placement`) traces the grid points
//! surfaces need, the level-`l` points of the level-`l + 1` cells a surface passes through, and
//! every point of the top level. A grid point it does not trace is
//! *filled* ([`crate::PROBE_FILLED`], with its level): after every gather the runtime sets its
//! SH to the trilinear interpolation of the level's cell around it ([`corners`]), renormalised
//! over the corners a lookup may use (valid or dilated). Its level is the lowest whose next
//! level's cell around it holds a surface, so its corners are traced and no surface lies in its
//! own cell: no wall stands between a filled point and the probes it is interpolated from. A
//! probe the bake traced and then dropped because level 1 predicts it (`prt_bake::refine`) may
//! stand beside a wall: it leaves out the corners the wall hides ([`fill_corners`]).
//!
//! Why fill grid points instead of coarser volumes and an indirection: a trilinear function on
//! a cell, restricted to one of its grid cells, is trilinear there too, so the lookup over
//! filled points returns the coarse level's interpolation exactly, and where a grid cell has
//! traced and filled corners the lookup blends them across that one cell, continuous on both of
//! its faces. There is no T-junction (every grid point exists), so no seam: the lookup keeps its
//! eight corner reads and needs no extra dependent load. What it costs is a texel and a probe
//! record per grid point, as on a uniform grid; what it saves is every factor table, sky mask
//! and visibility map of the points it does not trace.
//!
//! The twins of [`corners`]: `shaders/fill.wgsl` (stage 9 of the GPU runtime) and
//! `prt_runtime::fill`; `tests/tests/sparse.rs` checks that the lookup reproduces a coarse
//! level exactly and is continuous across a level boundary.

use crate::Grid;

/// The coarsest level: its points are `2^LEVELS` grid steps apart.
pub const LEVELS: u32 = 3;

/// Grid steps between the points of `level` along each axis.
pub fn stride(level: u32) -> u32 {
    1 << level.min(31)
}

/// Whether index `i` of an axis of `n` points is on `level`: a multiple of its stride or the
/// axis's last point (so that the level's cells cover the grid). Every index is on level 0.
pub fn on_level(n: u32, i: u32, level: u32) -> bool {
    i.is_multiple_of(stride(level)) || i + 1 == n
}

/// Whether grid point `ijk` of `grid` is on `level` along every axis.
pub fn on_level_point(grid: &Grid, ijk: [u32; 3], level: u32) -> bool {
    (0..3).all(|a| on_level(grid.counts[a], ijk[a], level))
}

/// The cell of `level` around index `i` (below `n`) along an axis of `n` points: its lower and
/// upper indices and `i`'s fraction between them, `(i - lo) / max(hi - lo, 1)` in f32 (the
/// WGSL twin's division may differ in the last bits where `hi - lo` is not a power of two; 0
/// and 1, which decide which corners count, are exact in both). An index on the level is its own cell's lower end, fraction 0, except
/// the last index, the upper end of the cell below it, fraction 1.
pub fn span(n: u32, i: u32, level: u32) -> (u32, u32, f32) {
    let s = stride(level);
    let last = n.saturating_sub(1);
    let lo = (i / s * s).min(last);
    let hi = (lo + s).min(last);
    let t = (i.saturating_sub(lo)) as f32 / (hi - lo).max(1) as f32;
    (lo, hi, t)
}

/// The eight points of `level` around grid point `ijk` (grid indices) and their trilinear
/// weights, corner `c` taking the upper end along axis `a` when bit `a` of `c` is set (the
/// order `shaders/fill.wgsl` visits them in). Weights of corners the point does not lie
/// between are zero; along an axis of one point both ends are that point.
pub fn corners(grid: &Grid, ijk: [u32; 3], level: u32) -> [(usize, f32); 8] {
    let spans: [(u32, u32, f32); 3] = std::array::from_fn(|a| span(grid.counts[a], ijk[a], level));
    std::array::from_fn(|c| {
        let mut at = [0u32; 3];
        let mut w = 1.0f32;
        for a in 0..3 {
            let (lo, hi, t) = spans[a];
            let upper = c >> a & 1 == 1;
            at[a] = if upper { hi } else { lo };
            w *= if upper { t } else { 1.0 - t };
        }
        (grid.index(at[0], at[1], at[2]), w)
    })
}

/// The [`corners`] with a positive weight: the points a filled point at `ijk` is interpolated
/// from (what the runtime's fill reads, the bake's marking and validation check).
pub fn used_corners(grid: &Grid, ijk: [u32; 3], level: u32) -> impl Iterator<Item = (usize, f32)> {
    corners(grid, ijk, level)
        .into_iter()
        .filter(|&(_, w)| w > 0.0)
}

/// The [`used_corners`] a filled point reads: those not in its `hidden` bits
/// ([`crate::Probe::fill_hidden`], bit `c` for corner `c`).
pub fn fill_corners(
    grid: &Grid,
    ijk: [u32; 3],
    level: u32,
    hidden: u32,
) -> impl Iterator<Item = (usize, f32)> {
    corners(grid, ijk, level)
        .into_iter()
        .enumerate()
        .filter(move |&(c, (_, w))| w > 0.0 && hidden >> c & 1 == 0)
        .map(|(_, corner)| corner)
}

/// The points filled grid point `index` of `probes` is interpolated from, with their weights
/// (not normalised): its [`fill_corners`] that are valid. What the runtime's fill averages
/// (`prt_runtime::fill`) and the bake's sky terms interpolate the probes' sky transfer over.
pub fn filled_from<'a>(
    grid: &Grid,
    probes: &'a [crate::Probe],
    index: usize,
) -> impl Iterator<Item = (usize, f32)> + 'a {
    let probe = probes[index];
    fill_corners(
        grid,
        grid.ijk(index),
        probe.fill_level(),
        probe.fill_hidden(),
    )
    .filter(|&(c, _)| probes.get(c).is_some_and(|p| p.is_valid()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_cover_every_index() {
        for level in 0..=LEVELS {
            for n in 1..20u32 {
                for i in 0..n {
                    let (lo, hi, t) = span(n, i, level);
                    let at = format!("n {n} i {i} level {level}");
                    assert!(on_level(n, lo, level) && on_level(n, hi, level), "{at}");
                    assert!(lo <= i && i <= hi && hi - lo <= stride(level), "{at}");
                    assert_eq!(lo as f32 + t * (hi - lo) as f32, i as f32, "{at}");
                    if on_level(n, i, level) {
                        // A point of the level is its own interpolation.
                        assert!(i == lo && t == 0.0 || i == hi && t == 1.0, "{at}");
                    }
                }
            }
        }
    }

    /// Filling from a level reproduces any trilinear function exactly, and so does the fine
    /// lookup between filled points (the module's argument for no seams).
    #[test]
    fn a_trilinear_function_is_reproduced() {
        let grid = Grid::cubic([0.0; 3], 0.5, [11, 6, 19]);
        let f = |p: [f32; 3]| {
            let (x, y, z) = (p[0], p[1], p[2]);
            1.0 + 0.5 * x - 0.25 * y + 2.0 * z + 0.125 * x * y - 0.75 * y * z + 0.0625 * x * y * z
        };
        let value: Vec<f32> = (0..grid.probe_count() as usize)
            .map(|index| {
                let [i, j, k] = grid.ijk(index);
                f(grid.position(i, j, k))
            })
            .collect();
        for level in 1..=LEVELS {
            for (index, &truth) in value.iter().enumerate() {
                let filled: f32 = corners(&grid, grid.ijk(index), level)
                    .iter()
                    .map(|&(c, w)| w * value[c])
                    .sum();
                assert!((filled - truth).abs() < 1e-4, "{index} level {level}");
            }
        }
    }

    /// A filled point's hidden corners drop out of what it reads, and no other.
    #[test]
    fn hidden_corners_are_left_out() {
        let grid = Grid::cubic([0.0; 3], 1.0, [5, 5, 5]);
        let ijk = [1, 1, 1];
        let all: Vec<(usize, f32)> = used_corners(&grid, ijk, 1).collect();
        assert_eq!(all.len(), 8);
        assert_eq!(fill_corners(&grid, ijk, 1, 0).collect::<Vec<_>>(), all);
        let corner_5 = grid.index(2, 0, 2);
        let seen: Vec<usize> = fill_corners(&grid, ijk, 1, 1 << 5).map(|c| c.0).collect();
        assert_eq!(seen.len(), 7);
        assert!(!seen.contains(&corner_5));
        assert_eq!(fill_corners(&grid, ijk, 1, 0xff).count(), 0);
    }

    #[test]
    fn weights_sum_to_one_and_the_last_layer_is_on_every_level() {
        let grid = Grid::cubic([0.0; 3], 1.0, [6, 1, 5]);
        for (i, j, k) in [(0, 0, 0), (1, 0, 3), (5, 0, 4), (4, 0, 2)] {
            for level in 1..=LEVELS {
                let sum: f32 = corners(&grid, [i, j, k], level).iter().map(|c| c.1).sum();
                assert!((sum - 1.0).abs() < 1e-6);
            }
        }
        assert!(on_level_point(&grid, [5, 0, 4], LEVELS));
        assert!(on_level_point(&grid, [4, 0, 0], 2));
        assert!(!on_level_point(&grid, [4, 0, 0], 3));
        assert!(!on_level_point(&grid, [2, 0, 0], 2));
        assert!(on_level_point(&grid, [2, 0, 0], 1));
    }
}
