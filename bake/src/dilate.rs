//! Dilation of probes inside geometry: each reads the factor table (format 12: its run is the
//! source's, no copy) and gets copies of the sky mask and sky transfer of its nearest valid
//! probe within [`RINGS`] grid steps, so that its SH equals that probe's at runtime (Unity's
//! adaptive probe volumes dilate the same way, by copying neighbours' data into invalid
//! probes). A dilated probe keeps its own visibility map, which sees the geometry around it at
//! short range, so visibility-aware sampling lets it fill holes (a surface whose
//! eight probes are all inside geometry) without competing with probes that see the point.
//!
//! Only a probe that fills a hole is dilated: one corner of a cell none of whose eight
//! corners is valid. Elsewhere the lookup already has a valid probe in the cell, and the copy
//! cost a full factor table for nothing: on the bundled scenes and the level family's tuning
//! seeds (`prt-bench surface --case bundled,tuning --lookup default`, both spacings, uniform
//! and sparse, stop 40) dilating only these measured the same surface error, to the last digit
//! reported, as dilating every invalid probe (and, sparse, as dilating none), with up to 16%
//! fewer probes with data (atrium_1 at 0.85 m: 4,652 against 5,544).

use prt_format::Grid;

/// Farthest grid step at which a source is looked for.
pub const RINGS: i64 = 2;

/// For each probe, the valid probe whose data it reads (`None` for valid probes, for invalid
/// ones that fill no hole, and for those with no valid probe within reach). With `cells` (per
/// cell, indexed by its lowest corner: whether a surface needs it,
/// `crate::placement::surface_cells`) only holes in those cells count: a sparse bake fills no
/// hole inside a solid block. Nearest by grid distance, ties to the lowest index:
/// deterministic, and sources are only originally valid probes (no chains).
pub fn sources(grid: &Grid, valid: &[bool], cells: Option<&[bool]>) -> Vec<Option<usize>> {
    let n = grid.counts.map(i64::from);
    let mut out = vec![None; valid.len()];
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let p = grid.index(i as u32, j as u32, k as u32);
                if valid[p] || !fills_a_hole(grid, (valid, cells), [i, j, k]) {
                    continue;
                }
                let mut best: Option<(i64, usize)> = None;
                for dk in -RINGS..=RINGS {
                    for dj in -RINGS..=RINGS {
                        for di in -RINGS..=RINGS {
                            let (x, y, z) = (i + di, j + dj, k + dk);
                            if x < 0 || y < 0 || z < 0 || x >= n[0] || y >= n[1] || z >= n[2] {
                                continue;
                            }
                            let q = grid.index(x as u32, y as u32, z as u32);
                            let d = di * di + dj * dj + dk * dk;
                            if valid[q] && best.is_none_or(|(bd, bq)| (d, q) < (bd, bq)) {
                                best = Some((d, q));
                            }
                        }
                    }
                }
                out[p] = best.map(|(_, q)| q);
            }
        }
    }
    out
}

/// Whether the probe at `ijk` is a corner of a cell none of whose corners is valid (along an
/// axis of one probe, the cell is that layer) and, with `cells`, that a surface needs.
fn fills_a_hole(grid: &Grid, (valid, cells): (&[bool], Option<&[bool]>), ijk: [i64; 3]) -> bool {
    let n = grid.counts.map(i64::from);
    // The cells' lowest corners along each axis: the probe's own and the one below.
    let lows = |a: usize| (ijk[a] - 1).max(0)..=ijk[a].min((n[a] - 2).max(0));
    for ck in lows(2) {
        for cj in lows(1) {
            for ci in lows(0) {
                let cell = grid.index(ci as u32, cj as u32, ck as u32);
                if cells.is_some_and(|cells| !cells[cell]) {
                    continue;
                }
                let corner = |o: usize, c: i64, a: usize| (c + ((o >> a) & 1) as i64).min(n[a] - 1);
                let any_valid = (0..8).any(|o| {
                    let (x, y, z) = (corner(o, ci, 0), corner(o, cj, 1), corner(o, ck, 2));
                    valid[grid.index(x as u32, y as u32, z as u32)]
                });
                if !any_valid {
                    return true;
                }
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_valid_neighbour_deterministically() {
        let grid = Grid::cubic([0.0; 3], 1.0, [5, 1, 1]);
        let valid = [true, false, false, false, true];
        let s = sources(&grid, &valid, None);
        // Cells 1-2 and 2-3 have no valid corner: probes 1, 2 and 3 fill holes.
        assert_eq!(s, vec![None, Some(0), Some(0), Some(4), None]);
        let six = Grid::cubic([0.0; 3], 1.0, [6, 1, 1]);
        // Cells 0-1 and 1-2 have a valid corner: probe 1 fills no hole.
        assert_eq!(
            sources(&six, &[true, false, true, false, false, true], None),
            vec![None, None, None, Some(2), Some(5), None]
        );
        let none = sources(&grid, &[false; 5], None);
        assert!(none.iter().all(Option::is_none));
    }
}
