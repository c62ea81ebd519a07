//! Dilation of probes inside geometry: each gets the factor table, sky mask and sky transfer of
//! its nearest valid probe within [`RINGS`] grid steps, so that its SH equals that probe's at
//! runtime at no extra runtime cost (Unity's adaptive probe volumes dilate the same way, by
//! copying neighbours' data into invalid probes). A dilated probe keeps its own visibility map,
//! which sees the geometry around it at short range, so visibility-aware sampling lets it fill
//! holes (a surface whose eight probes are all inside geometry) without competing with probes
//! that see the point.

use prt_format::Grid;

/// Farthest grid step at which a source is looked for.
pub const RINGS: i64 = 2;

/// For each probe, the valid probe it copies (`None` for valid probes and for invalid ones with
/// no valid probe within reach). Nearest by grid distance, ties to the lowest index:
/// deterministic, and sources are only originally valid probes (no chains).
pub fn sources(grid: &Grid, valid: &[bool]) -> Vec<Option<usize>> {
    let n = grid.counts.map(i64::from);
    let mut out = vec![None; valid.len()];
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let p = grid.index(i as u32, j as u32, k as u32);
                if valid[p] {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_valid_neighbour_deterministically() {
        let grid = Grid::cubic([0.0; 3], 1.0, [5, 1, 1]);
        let valid = [true, false, false, false, true];
        let s = sources(&grid, &valid);
        assert_eq!(s, vec![None, Some(0), Some(0), Some(4), None]);
        let none = sources(&grid, &[false; 5]);
        assert!(none.iter().all(Option::is_none));
    }
}
