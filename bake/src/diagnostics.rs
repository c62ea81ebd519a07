//! What is wrong with a scene, told before the user wonders why the light is wrong: inconsistent
//! triangle winding (the usual reason a scene bakes with most probes invalid) and grids whose
//! probes are mostly inside geometry.

use glam::Vec3;
use rayon::prelude::*;

/// Shared edges of a mesh, and how many of them both of their triangles walk the same way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Winding {
    /// Edges used by exactly two triangles.
    pub shared_edges: u64,
    /// Of those, edges both triangles walk in the same direction: one of the two triangles faces
    /// the other way round (glTF 2.0 spec 3.7.2.1: front faces are counter-clockwise).
    pub inconsistent_edges: u64,
}

impl Winding {
    /// Fraction of shared edges with inconsistent winding.
    pub fn inconsistent_fraction(&self) -> f64 {
        if self.shared_edges == 0 {
            0.0
        } else {
            self.inconsistent_edges as f64 / self.shared_edges as f64
        }
    }
}

/// The warning for inconsistent winding, with the share of edges affected and the way out.
pub fn winding_warning(w: &Winding) -> String {
    format!(
        "{} of {} shared edges ({:.1}%) are walked the same way by both of their triangles: \
         the scene's winding is inconsistent, so single-sided back faces will make probes \
         invalid; bake with --double-sided",
        w.inconsistent_edges,
        w.shared_edges,
        100.0 * w.inconsistent_fraction()
    )
}

/// The warning for a grid whose probes are mostly inside geometry (`valid`: per probe), with the
/// likely reason; `None` when at least half are valid.
pub fn inside_warning(
    valid: &[bool],
    settings: &crate::BakeSettings,
    winding: &Winding,
    winding_hint: bool,
) -> Option<String> {
    let inside = valid.iter().filter(|v| !**v).count();
    if 2 * inside <= valid.len() {
        return None;
    }
    let reason = if winding_hint {
        "the winding is inconsistent (warned above): bake with --double-sided".to_string()
    } else {
        format!(
            "the winding is consistent ({} of {} shared edges inconsistent), so the back faces \
             are the model's own: check the bounds, and bake with --double-sided if its surfaces \
             are meant to be seen from both sides",
            winding.inconsistent_edges, winding.shared_edges
        )
    };
    Some(format!(
        "{inside} of {} probes are inside geometry (more than {:.0}% of their rays hit back faces \
         of single-sided surfaces{}); {reason}",
        valid.len(),
        100.0 * settings.invalid_backface_fraction,
        if settings.double_sided {
            ""
        } else {
            ", or they see no sky and face away from every hit"
        },
    ))
}

/// Counts shared and inconsistently wound edges; vertices are the same when their world
/// positions are bit-identical (as when triangles share an index). An edge from a vertex to
/// itself (a triangle with two equal corners, which the loader skips as zero-area) joins no two
/// triangles and is not counted.
///
/// By sorting, in parallel: corners by position bits (numbering the distinct vertices), then
/// edges by their two vertex numbers, so that an edge's uses lie side by side. Counting
/// directed edges in one hash map (foldhash) took 0.16-0.21 s for Sponza's 187k triangles, on
/// one thread beside the BVH build, which then waited for it: the BVH stage took 0.20-0.21 s,
/// 0.13-0.15 s now (`prt bake --spacing 1.9`, 2 threads). Only counts are read, so no order of
/// equal items changes the result.
pub fn winding(triangles: &[[Vec3; 3]]) -> Winding {
    let vertex = vertex_numbers(triangles);
    // Per directed edge (a, b): its undirected key (smaller number first) and whether it is
    // walked from the larger number to the smaller.
    let mut edges: Vec<(u64, bool)> = vertex
        .par_chunks_exact(3)
        .flat_map_iter(|t| {
            [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
                .into_iter()
                .filter(|(a, b)| a != b)
                .map(|(a, b)| (u64::from(a.min(b)) << 32 | u64::from(a.max(b)), a > b))
        })
        .collect();
    edges.par_sort_unstable();
    let mut w = Winding::default();
    for uses in edges.chunk_by(|x, y| x.0 == y.0) {
        if let [(_, first), (_, second)] = uses {
            w.shared_edges += 1;
            // Sorted, so a pair walked both ways is (false, true).
            w.inconsistent_edges += u64::from(first == second);
        }
    }
    w
}

/// Per triangle corner, the number of its vertex: equal for bit-identical positions. Corners
/// are numbered in u32: 2^32 corners would take 51 GB of triangles before this runs.
fn vertex_numbers(triangles: &[[Vec3; 3]]) -> Vec<u32> {
    let mut corners: Vec<([u32; 3], u32)> = triangles
        .iter()
        .flatten()
        .map(|v| v.to_array().map(f32::to_bits))
        .zip(0u32..)
        .collect();
    corners.par_sort_unstable();
    let mut number = vec![0u32; corners.len()];
    let mut next = 0u32;
    for (i, &(position, corner)) in corners.iter().enumerate() {
        if i > 0 && corners[i - 1].0 != position {
            next += 1;
        }
        number[corner as usize] = next;
    }
    number
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flipped_triangle_is_found() {
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0));
        let good = winding(&[[a, b, c], [b, d, c]]);
        assert_eq!(
            good,
            Winding {
                shared_edges: 1,
                inconsistent_edges: 0
            }
        );
        let bad = winding(&[[a, b, c], [b, c, d]]);
        assert_eq!(
            bad,
            Winding {
                shared_edges: 1,
                inconsistent_edges: 1
            }
        );
    }

    /// The sorted count equals counting directed edges in a hash map (the check it replaced,
    /// self-edges left out) on grids of quads with random flips, duplicated triangles (edges
    /// used up to four times) and triangles with repeated corners, whose corners are shared by
    /// equal positions only.
    #[test]
    fn sorting_counts_as_a_map_of_directed_edges_does() {
        fn by_map(triangles: &[[Vec3; 3]]) -> Winding {
            let key = |v: Vec3| v.to_array().map(f32::to_bits);
            let mut directed = std::collections::HashMap::new();
            for t in triangles {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    if key(a) != key(b) {
                        *directed.entry((key(a), key(b))).or_insert(0u32) += 1;
                    }
                }
            }
            let mut w = Winding::default();
            for (&(a, b), &forward) in &directed {
                if a > b && directed.contains_key(&(b, a)) {
                    continue;
                }
                let backward = directed.get(&(b, a)).copied().unwrap_or(0);
                if forward + backward == 2 {
                    w.shared_edges += 1;
                    w.inconsistent_edges += u64::from(forward == 2 || backward == 2);
                }
            }
            w
        }
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for n in [1usize, 2, 5, 12] {
            let v = |i: usize, j: usize| Vec3::new(i as f32, j as f32, ((i * j) % 3) as f32);
            let mut triangles = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
                    for mut t in [[a, b, c], [a, c, d]] {
                        match next() % 10 {
                            0 => t.swap(1, 2),
                            1 => triangles.push(t),
                            2 => t[1] = t[0],
                            3 => t = [a; 3],
                            _ => {}
                        }
                        triangles.push(t);
                    }
                }
            }
            let w = winding(&triangles);
            assert_eq!(w, by_map(&triangles), "{n}x{n} quads");
            if n >= 5 {
                assert!(w.inconsistent_edges > 0 && w.shared_edges > w.inconsistent_edges);
            }
        }
    }
}
