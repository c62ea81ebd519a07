//! # The coarse tier of sparse placement: open air lit from a lattice four grid steps apart
//!
//! A sparse bake (`prt_bake::placement`) traces the grid points that surfaces need (the fine
//! tier) and, everywhere else, only the points of a coarse sub-lattice: every
//! [`COARSE_STRIDE`]-th index along each axis, plus each axis's last index. A grid point
//! between them that the bake did not trace is *filled* ([`crate::PROBE_FILLED`]): after
//! every gather the runtime sets its SH to the trilinear interpolation of the coarse cell
//! around it ([`corners`]), renormalised over the corners a lookup may use (valid or dilated).
//!
//! Why fill grid points instead of a second volume and an indirection: a trilinear function on
//! a coarse cell, restricted to one of its fine cells, is trilinear there too, so the fine
//! lookup over filled points returns the coarse tier's interpolation exactly, and where a fine
//! cell has traced and filled corners the lookup blends them across that one cell, continuous
//! on both of its faces. There is no T-junction (every grid point exists), so no seam: the
//! lookup keeps its eight corner reads and no extra dependent load. What it costs is a texel
//! and a probe record per grid point, as on a uniform grid; what it saves is every factor
//! table, sky mask and visibility map of the points it does not trace (most of an open
//! level's volume).
//!
//! The twins of [`corners`]: `shaders/fill.wgsl` (stage 9 of the GPU runtime) and
//! `prt_runtime::fill`; `tests/tests/sparse.rs` checks that the lookup is continuous across a
//! tier boundary.

use crate::Grid;

/// Grid steps between the coarse tier's points along each axis.
pub const COARSE_STRIDE: u32 = 4;

/// Whether index `i` of an axis of `n` points is on the coarse tier: a multiple of
/// [`COARSE_STRIDE`] or the axis's last point (so that the coarse cells cover the grid).
pub fn is_coarse(n: u32, i: u32) -> bool {
    i.is_multiple_of(COARSE_STRIDE) || i + 1 == n
}

/// The coarse interval of index `i` (below `n`) along an axis of `n` points: its lower and
/// upper coarse indices and `i`'s fraction between them, `(i - lo) / max(hi - lo, 1)` in f32
/// (as the WGSL twin divides). A coarse index is its own interval's lower end, fraction 0,
/// except the last index, which is the upper end of the interval below it, fraction 1.
pub fn span(n: u32, i: u32) -> (u32, u32, f32) {
    let last = n.saturating_sub(1);
    let lo = (i / COARSE_STRIDE * COARSE_STRIDE).min(last);
    let hi = (lo + COARSE_STRIDE).min(last);
    let t = (i.saturating_sub(lo)) as f32 / (hi - lo).max(1) as f32;
    (lo, hi, t)
}

/// Whether grid point `(i, j, k)` of `grid` is on the coarse tier along every axis.
pub fn is_coarse_point(grid: &Grid, ijk: [u32; 3]) -> bool {
    (0..3).all(|a| is_coarse(grid.counts[a], ijk[a]))
}

/// The eight coarse points around grid point `(i, j, k)` (grid indices) and their trilinear
/// weights, corner `c` taking the upper end along axis `a` when bit `a` of `c` is set (the
/// order `shaders/fill.wgsl` visits them in). Weights of corners the point does not lie
/// between are zero; along an axis of one point both ends are that point.
pub fn corners(grid: &Grid, ijk: [u32; 3]) -> [(usize, f32); 8] {
    let spans: [(u32, u32, f32); 3] = std::array::from_fn(|a| span(grid.counts[a], ijk[a]));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_cover_every_index() {
        for n in 1..14u32 {
            for i in 0..n {
                let (lo, hi, t) = span(n, i);
                assert!(is_coarse(n, lo) && is_coarse(n, hi), "n {n} i {i}");
                assert!(
                    lo <= i && i <= hi && hi - lo <= COARSE_STRIDE,
                    "n {n} i {i}"
                );
                let back = lo as f32 + t * (hi - lo) as f32;
                assert_eq!(back, i as f32, "n {n} i {i}");
                if is_coarse(n, i) {
                    // A coarse point is its own interpolation.
                    assert!(i == lo && t == 0.0 || i == hi && t == 1.0, "n {n} i {i}");
                }
            }
        }
    }

    /// Filling from the coarse tier reproduces any trilinear function exactly, and so does
    /// the fine lookup between filled points (the module's argument for no seams).
    #[test]
    fn a_trilinear_function_is_reproduced() {
        let grid = Grid::cubic([0.0; 3], 0.5, [11, 6, 9]);
        let f = |p: [f32; 3]| {
            let (x, y, z) = (p[0], p[1], p[2]);
            1.0 + 0.5 * x - 0.25 * y + 2.0 * z + 0.125 * x * y - 0.75 * y * z + 0.0625 * x * y * z
        };
        let value: Vec<f32> = (0..grid.probe_count() as u32)
            .map(|index| {
                let n = grid.counts;
                let ijk = [index % n[0], index / n[0] % n[1], index / (n[0] * n[1])];
                f(grid.position(ijk[0], ijk[1], ijk[2]))
            })
            .collect();
        for k in 0..9 {
            for j in 0..6 {
                for i in 0..11 {
                    let filled: f32 = corners(&grid, [i, j, k])
                        .iter()
                        .map(|&(c, w)| w * value[c])
                        .sum();
                    let truth = value[grid.index(i, j, k)];
                    assert!((filled - truth).abs() < 1e-5, "({i}, {j}, {k})");
                }
            }
        }
    }

    #[test]
    fn weights_sum_to_one_and_the_last_layer_is_coarse() {
        let grid = Grid::cubic([0.0; 3], 1.0, [6, 1, 5]);
        for (i, j, k) in [(0, 0, 0), (1, 0, 3), (5, 0, 4), (4, 0, 2)] {
            let sum: f32 = corners(&grid, [i, j, k]).iter().map(|c| c.1).sum();
            assert!((sum - 1.0).abs() < 1e-6);
        }
        assert!(is_coarse_point(&grid, [5, 0, 4]));
        assert!(is_coarse_point(&grid, [4, 0, 0]));
        assert!(!is_coarse_point(&grid, [2, 0, 0]));
    }
}
