//! What is wrong with a scene, told before the user wonders why the light is wrong: inconsistent
//! triangle winding (the usual reason a scene bakes with most probes invalid) and grids whose
//! probes are mostly inside geometry.

use glam::Vec3;

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
/// positions are bit-identical (as when triangles share an index).
pub fn winding(triangles: &[[Vec3; 3]]) -> Winding {
    let key = |v: Vec3| v.to_array().map(f32::to_bits);
    // foldhash, seeded per process: keys are float bits the file's author chose, so a fixed
    // fast hash (FxHash) could be made to collide; Sponza's 187k triangles took 0.17 s with the
    // standard library's SipHash. Only counts are read, so the seed never changes the result.
    let mut directed: foldhash::HashMap<([u32; 3], [u32; 3]), u32> =
        foldhash::HashMap::with_capacity_and_hasher(3 * triangles.len(), Default::default());
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *directed.entry((key(a), key(b))).or_default() += 1;
        }
    }
    let mut w = Winding::default();
    for (&(a, b), &forward) in &directed {
        // Each undirected edge once: from its smaller key.
        if a > b && directed.contains_key(&(b, a)) {
            continue;
        }
        let backward = directed.get(&(b, a)).copied().unwrap_or(0);
        if forward + backward == 2 {
            w.shared_edges += 1;
            if forward == 2 || backward == 2 {
                w.inconsistent_edges += 1;
            }
        }
    }
    w
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
}
