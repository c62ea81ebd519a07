//! What is wrong with a scene, told before the user wonders why the light is wrong: inconsistent
//! triangle winding (the usual reason a scene bakes with most probes invalid), grids whose
//! probes are mostly inside geometry, and what the bake could not classify (probes in gaps far
//! narrower than the spacing, surfels that see none of their probes).

use glam::Vec3;
use rayon::prelude::*;

/// Fraction of shared edges with inconsistent winding above which the bake warns.
pub(crate) const WINDING_WARNING: f64 = 0.01;

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
/// likely reason; `None` when at least half are valid. The scene's winding is asked of
/// `winding` only for the warning's text.
pub fn inside_warning(
    valid: &[bool],
    settings: &crate::BakeSettings,
    winding: impl FnOnce() -> Winding,
    winding_hint: bool,
) -> Option<String> {
    let inside = valid.iter().filter(|v| !**v).count();
    if 2 * inside <= valid.len() {
        return None;
    }
    let reason = if winding_hint {
        "the winding is inconsistent (warned above): bake with --double-sided".to_string()
    } else {
        let winding = winding();
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
/// Each directed edge becomes one `u64`: a 63-bit hash of its two vertices' position bits
/// (smaller vertex hash first, so both directions agree) above one bit for the direction.
/// Grouping equal integers (`group_equal`) puts an edge's uses side by side, several times
/// faster than a hash map of directed edges or numbering vertices by sorting corners. Two
/// distinct vertices or edges share a hash with probability about n^2 / 2^64 (2e-8 for
/// Sponza's 562k edges), which at worst miscounts an edge of a diagnostic percentage; the
/// hashes are seeded with a constant, so the count is the same on every run.
pub fn winding(triangles: &[[Vec3; 3]]) -> Winding {
    let edges: Vec<[u64; 3]> = triangles
        .par_iter()
        .map(|t| {
            let bits = t.map(|v| v.to_array().map(f32::to_bits));
            let vertex = bits.map(vertex_hash);
            [(0, 1), (1, 2), (2, 0)].map(|(i, j)| match bits[i] == bits[j] {
                true => SELF_EDGE,
                false => edge_key(vertex[i], vertex[j]),
            })
        })
        .collect();
    let edges = group_equal(edges.as_flattened());
    let mut w = Winding::default();
    for uses in edges.chunk_by(|x, y| x >> 1 == y >> 1) {
        if let [first, second] = uses {
            if *first >> 1 != SELF_EDGE >> 1 {
                w.shared_edges += 1;
                w.inconsistent_edges += u64::from(first == second);
            }
        }
    }
    w
}

/// A vertex's 64-bit hash from its position bits.
fn vertex_hash([x, y, z]: [u32; 3]) -> u64 {
    mix((u64::from(x) | u64::from(y) << 32) ^ mix(u64::from(z) ^ WINDING_SEED))
}

/// The directed edge from the vertex hashed `a` to the one hashed `b`: the undirected edge's
/// 63-bit hash, then whether it runs from the larger vertex hash to the smaller.
fn edge_key(a: u64, b: u64) -> u64 {
    mix(a.min(b) ^ mix(a.max(b) ^ WINDING_SEED)) << 1 | u64::from(a > b)
}

/// A bijective 64-bit mixer (the finaliser of MurmurHash3, Appleby 2008): every input bit
/// flips each output bit with probability about one half.
fn mix(mut h: u64) -> u64 {
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^ h >> 33
}

/// [`winding`]'s stand-in for an edge from a vertex to itself, left out of the count (an edge
/// whose hash is this, one in 2^63, is left out with them).
const SELF_EDGE: u64 = u64::MAX;

/// `keys` (uniform hashes) sorted: one pass to count buckets of their top bits (four to eight
/// keys a bucket), one to scatter them, then a sort of each small bucket, which stays in cache
/// where one sort of every key does not.
fn group_equal(keys: &[u64]) -> Vec<u64> {
    let bits = (keys.len() / 4).max(2).ilog2().min(24);
    let bucket = |k: u64| (k >> (64 - bits)) as usize;
    let mut start = vec![0u32; (1 << bits) + 1];
    for &k in keys {
        start[bucket(k) + 1] += 1;
    }
    for b in 1..start.len() {
        start[b] += start[b - 1];
    }
    let mut next = start.clone();
    let mut out = vec![0u64; keys.len()];
    for &k in keys {
        let b = bucket(k);
        out[next[b] as usize] = k;
        next[b] += 1;
    }
    for b in start.windows(2) {
        out[b[0] as usize..b[1] as usize].sort_unstable();
    }
    out
}

/// The seed of [`winding`]'s hashes: any constant, so that counts repeat from run to run.
const WINDING_SEED: u64 = 0x243f_6a88_85a3_08d3;

/// Share of the surfels with terms that may see none of their probes, or of the valid probes
/// that may sit in gaps, before the bake warns.
const WARNING_FRACTION: f64 = 0.1;

/// The warning for a grid whose probes mostly sit in gaps far narrower than the spacing
/// (`prt_format::summary::probe_in_gap`): they see the gap's two sides and little else, so the
/// bake cannot tell what lights the surfaces beyond them.
pub(crate) fn gap_warning(asset: &prt_format::Asset) -> Option<String> {
    let valid = asset.probes.iter().filter(|p| p.is_valid()).count();
    let in_gaps = (0..asset.probes.len())
        .filter(|&p| asset.probes[p].is_valid() && prt_format::summary::probe_in_gap(asset, p))
        .count();
    (in_gaps as f64 > WARNING_FRACTION * valid as f64).then(|| {
        format!(
            "{in_gaps} of {valid} probes ({:.0}%) sit in gaps narrower than a tenth of the \
             spacing ({} m): they see little beyond the gap's two sides, and surfaces no probe \
             sees are sampled from probes that cannot see them; a finer --spacing, or bounds \
             that leave such gaps out, resolves them",
            100.0 * in_gaps as f64 / valid.max(1) as f64,
            asset.header.grid.spacing
        )
    })
}

/// The warning for a bake whose surfels mostly cannot tell which probes light them (gaps or
/// pockets narrower than the spacing, surfaces outside the grid), with the way out.
pub(crate) fn blind_warning(terms: &prt_format::surface::SurfaceTerms) -> Option<String> {
    let (traced, blind) = terms.traced_and_blind();
    (blind as f64 > WARNING_FRACTION * traced as f64).then(|| {
        format!(
            "{blind} of {traced} surfels ({:.0}%) see none of the probes around them (gaps or \
             pockets narrower than the probe spacing, or surfaces outside the grid): their \
             points are sampled with the probe volume's weights; a finer --spacing resolves more \
             of them",
            100.0 * blind as f64 / traced.max(1) as f64
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blind-surfel warning: silent at a tenth of the traced surfels, said (with the count
    /// and the way out) above it; untraced surfels (back faces) do not count.
    #[test]
    fn surfels_that_see_no_probe_are_warned_about_past_a_tenth() {
        use prt_format::surface::{SurfaceTerms, SurfelTerms};
        use prt_format::surfel_terms::centre_code;
        let surfel = |mask: u32| SurfelTerms {
            mask,
            ..SurfelTerms::default()
        };
        let terms = |blind: usize| SurfaceTerms {
            surfels: (0..20)
                .map(|i| match i {
                    _ if i < blind => surfel(centre_code([0; 3])),
                    _ if i < 18 => surfel(centre_code([0; 3]) | 1),
                    _ => surfel(0),
                })
                .collect(),
            ..SurfaceTerms::default()
        };
        assert_eq!(terms(1).traced_and_blind(), (18, 1));
        assert!(blind_warning(&terms(1)).is_none());
        let w = blind_warning(&terms(4)).expect("4 of 18 warn");
        assert!(
            w.starts_with("4 of 18 surfels") && w.contains("--spacing"),
            "{w}"
        );
    }

    /// The winding is counted for the warning only when it is given: never when most probes
    /// are valid.
    #[test]
    fn the_inside_warning_counts_the_winding_only_when_it_warns() {
        let settings = crate::BakeSettings::default();
        let counted = || Winding {
            shared_edges: 12,
            inconsistent_edges: 0,
        };
        let unused = || -> Winding { panic!("winding counted for no warning") };
        assert_eq!(
            inside_warning(&[true, true, false], &settings, unused, false),
            None
        );
        let w = inside_warning(&[true, false, false], &settings, counted, false).unwrap();
        assert!(
            w.starts_with("2 of 3 probes") && w.contains("(0 of 12 shared edges"),
            "{w}"
        );
        let hinted = inside_warning(&[false; 3], &settings, unused, true).unwrap();
        assert!(hinted.contains("bake with --double-sided"), "{hinted}");
    }

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

    /// A deterministic 64-bit generator (Marsaglia's xorshift) seeded with `state`.
    fn xorshift(mut state: u64) -> impl FnMut() -> u64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        }
    }

    /// No two of 300,000 distinct positions (every bit random, or on a grid of floats as meshes
    /// have them) share a vertex hash, and no two of their edges share an edge key: a collision
    /// is likely only past billions of items, so any here is a weak hash (as when one component
    /// was ORed in rather than mixed: it miscounted 39 of Sponza's 249,798 shared edges).
    #[test]
    fn hashes_of_distinct_vertices_and_edges_differ() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let mut positions: Vec<[u32; 3]> = (0..100_000)
            .map(|_| [next() as u32, next() as u32, next() as u32])
            .collect();
        for i in 0..200_000u32 {
            let v = Vec3::new(
                (i % 97) as f32 * 0.125,
                (i / 97 % 61) as f32 * 0.37,
                (i / 5917) as f32,
            );
            positions.push((v + 1e3).to_array().map(f32::to_bits));
        }
        positions.sort_unstable();
        positions.dedup();
        let vertices: Vec<u64> = positions.iter().map(|&p| vertex_hash(p)).collect();
        let mut distinct = vertices.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), vertices.len(), "vertex hashes collide");
        let mut edges: Vec<u64> = vertices
            .windows(2)
            .chain(vertices.windows(3).step_by(2))
            .map(|w| edge_key(w[0], w[w.len() - 1]) >> 1)
            .collect();
        let count = edges.len();
        edges.sort_unstable();
        edges.dedup();
        assert_eq!(edges.len(), count, "edge keys collide");
    }

    /// The hashed count equals counting directed edges in a hash map (the check it replaced,
    /// self-edges left out) on grids of quads with random flips, duplicated triangles (edges
    /// used up to four times) and triangles with repeated corners, whose corners are shared by
    /// equal positions only.
    #[test]
    fn hashing_counts_as_a_map_of_directed_edges_does() {
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
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        for n in [1usize, 2, 5, 12, 40] {
            // Coordinates that use every bit of a float, as real meshes do.
            let v = |i: usize, j: usize| {
                Vec3::new(
                    i as f32 * 0.731,
                    j as f32 * 1.379,
                    ((i * j) % 7) as f32 * 0.2137,
                ) + 1e3
            };
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
