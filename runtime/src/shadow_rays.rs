//! Shadow rays from surfels to lights: any-hit rays through the binary BVH the asset carries.
//!
//! The traversal is the plain stack loop the WGSL twin runs (`shaders/`), with the same slab
//! test and the same Moller-Trumbore intersection ("Fast, Minimum Storage Ray/Triangle
//! Intersection", 1997), so that CPU and GPU agree ray for ray.

use glam::Vec3;
use prt_format::{BvhNode, Geometry, Triangle};

use crate::contract::{MAX_STACK, RAY_OFFSET_MAGNITUDE, RAY_OFFSET_SCALE};

#[inline]
fn safe_inverse(x: f32) -> f32 {
    if x.abs() < 1e-20 {
        1e20_f32.copysign(x)
    } else {
        1.0 / x
    }
}

#[inline]
fn hits_box(n: &BvhNode, o: Vec3, inv: Vec3, tmax: f32) -> bool {
    let t0 = (Vec3::from(n.min) - o) * inv;
    let t1 = (Vec3::from(n.max) - o) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(tmax);
    near <= far
}

/// Moller-Trumbore: whether the triangle lies on the ray within `(0, tmax)`. Barycentric tests
/// are widened by [`prt_format::EDGE_TOLERANCE`] (no shadow ray slips through a shared edge) and
/// only an exactly zero determinant (a ray in the triangle's plane) is refused: an absolute
/// floor on it (1e-12, before) dropped every triangle below a micrometre.
#[inline]
pub fn intersect(t: &Triangle, o: Vec3, d: Vec3, tmax: f32) -> bool {
    intersect_distance(t, o, d, tmax).is_some()
}

/// [`intersect`]'s distance along the ray, when the triangle lies on it within `(0, tmax)`.
#[inline]
pub fn intersect_distance(t: &Triangle, o: Vec3, d: Vec3, tmax: f32) -> Option<f32> {
    let v0 = Vec3::from(t.v0);
    let e1 = Vec3::from(t.v1) - v0;
    let e2 = Vec3::from(t.v2) - v0;
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = o - v0;
    let eps = prt_format::EDGE_TOLERANCE;
    let u = s.dot(p) * inv_det;
    if !(-eps..=1.0 + eps).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv_det;
    if v < -eps || u + v > 1.0 + eps {
        return None;
    }
    let dist = e2.dot(q) * inv_det;
    (dist > 0.0 && dist < tmax).then_some(dist)
}

/// True when any triangle lies on the segment `o + t d`, `t` in `(0, tmax)`.
pub fn occluded(geo: &Geometry, o: Vec3, d: Vec3, tmax: f32) -> bool {
    if geo.nodes.is_empty() {
        return false;
    }
    let inv = Vec3::new(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    let mut stack = [0u32; MAX_STACK];
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let node = &geo.nodes[stack[top] as usize];
        if !hits_box(node, o, inv, tmax) {
            continue;
        }
        if node.count > 0 {
            let tris = &geo.triangles[node.first as usize..(node.first + node.count) as usize];
            if tris.iter().any(|t| intersect(t, o, d, tmax)) {
                return true;
            }
        } else if top + 2 <= MAX_STACK {
            stack[top] = node.first;
            stack[top + 1] = node.first + 1;
            top += 2;
        }
    }
    false
}

/// The nearest triangle on the segment `o + t d`, `t` in `(0, tmax)`: its distance and index
/// in `geo.triangles`. The same traversal and intersection as [`occluded`], for CPU reference
/// code that needs what a ray hits (no WGSL twin: the GPU only asks whether).
pub fn closest_hit(geo: &Geometry, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, usize)> {
    if geo.nodes.is_empty() {
        return None;
    }
    let inv = Vec3::new(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    let mut best: Option<(f32, usize)> = None;
    let mut stack = [0u32; MAX_STACK];
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let node = &geo.nodes[stack[top] as usize];
        let limit = best.map_or(tmax, |(t, _)| t);
        if !hits_box(node, o, inv, limit) {
            continue;
        }
        if node.count > 0 {
            let first = node.first as usize;
            for (i, tri) in geo.triangles[first..first + node.count as usize]
                .iter()
                .enumerate()
            {
                let limit = best.map_or(tmax, |(t, _)| t);
                if let Some(t) = intersect_distance(tri, o, d, limit) {
                    best = Some((t, first + i));
                }
            }
        } else if top + 2 <= MAX_STACK {
            stack[top] = node.first;
            stack[top + 1] = node.first + 1;
            top += 2;
        }
    }
    best
}

/// Offset of shadow-ray origins along the surface normal: [`RAY_OFFSET_MAGNITUDE`] (1e-6) of
/// the coordinates' magnitude (about 8 float32 ulps: the rounding of a stored position grows
/// with it), and at least [`RAY_OFFSET_SCALE`] (1e-4) of `scale`, the scene's own length scale
/// (the probe spacing), near the origin. Nothing
/// absolute: a 2 mm room and a 20 km one get the same shadows (tests/tests/scale.rs). The
/// magnitude term was 1e-4 before, a 10 m offset at 1e5 m from the origin that skipped every
/// nearby occluder: the Cornell room moved 1 km, 10 km and 100 km away baked and relit 9%, 85%
/// and 129% off (of SH0), against 0.5%, 2.4% and 9.5% now (`tests/tests/scale.rs`; 3e-7
/// measured better still, but leaves 2.5 ulps).
#[inline]
pub fn ray_offset(p: Vec3, scale: f32) -> f32 {
    (RAY_OFFSET_MAGNITUDE * p.abs().max_element()).max(RAY_OFFSET_SCALE * scale)
}

/// Whether light reaches the surface point `p` (unit normal `n`, in an asset of probe
/// `spacing`) along unit `l`: a shadow ray from [`ray_offset`] off the surface, up to the
/// light at `light_at`, or without end for a directional light (`None`; `f32::MAX`, not
/// infinity: the same slab arithmetic as the WGSL twin, `shaders/shadow_rays.wgsl`).
pub fn lit(
    geo: &Geometry,
    p: Vec3,
    n: Vec3,
    spacing: f32,
    l: Vec3,
    light_at: Option<Vec3>,
) -> bool {
    let off = ray_offset(p, spacing);
    let o = p + n * off;
    let tmax = light_at.map_or(f32::MAX, |at| (at - o).length() - off);
    !occluded(geo, o, l, tmax)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two squares across the x axis, the far one (x = 2) first in the leaf.
    fn two_walls() -> Geometry {
        let wall = |x: f32| {
            let (a, b, c, d) = (
                [x, -1.0, -1.0],
                [x, 1.0, -1.0],
                [x, 1.0, 1.0],
                [x, -1.0, 1.0],
            );
            let tri = |v0, v1, v2| Triangle {
                v0,
                v1,
                v2,
                ..Triangle::default()
            };
            [tri(a, b, c), tri(a, c, d)]
        };
        let [f0, f1] = wall(2.0);
        let [n0, n1] = wall(1.0);
        Geometry {
            triangles: vec![f0, f1, n0, n1],
            nodes: vec![BvhNode {
                min: [1.0, -1.0, -1.0],
                max: [2.0, 1.0, 1.0],
                first: 0,
                count: 4,
            }],
        }
    }

    /// The nearest hit wins whatever the leaf order, `tmax` bounds it, and an axis-aligned ray
    /// (zero direction components) finds it.
    #[test]
    fn closest_hit_is_the_nearest_within_tmax() {
        let geo = two_walls();
        let x = Vec3::X;
        let (t, i) = closest_hit(&geo, Vec3::ZERO, x, 10.0).unwrap();
        assert!((t - 1.0).abs() < 1e-6 && (2..4).contains(&i), "{t} {i}");
        assert_eq!(closest_hit(&geo, Vec3::ZERO, x, 0.5), None);
        let (t, i) = closest_hit(&geo, Vec3::new(1.5, 0.2, 0.3), x, 10.0).unwrap();
        assert!((t - 0.5).abs() < 1e-6 && i < 2, "{t} {i}");
        // Zero y and z components (no NaN from 0 x inf in the slab test), and the same answer
        // as the any-hit test.
        let off_axis = Vec3::new(0.0, 0.5, -0.5);
        let (t, _) = closest_hit(&geo, off_axis, x, 10.0).unwrap();
        assert!((t - 1.0).abs() < 1e-6, "{t}");
        assert!(occluded(&geo, off_axis, x, 10.0));
    }
}
