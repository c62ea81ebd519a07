//! An uncompressed 8-wide BVH traced by packets of rays that leave one point.
//!
//! Every probe shoots its lattice directions from one origin, in Morton order of the octahedral
//! map ([`crate::trace::coherent_order`]), so consecutive rays span a narrow cone. Tracing eight
//! of them together (ray packets: Wald, Slusallek, Benthin, Wagner, "Interactive Rendering with
//! Coherent Ray Tracing", 2001) fetches each node once for the packet. Inside a node the work is
//! per ray, SIMD across the node (as Embree's single-ray BVH8 traversal): each ray still in the
//! packet tests the eight child boxes as two SSE vectors of four (glam's `Vec4`), and each leaf's
//! four triangles, stored structure of arrays, in one vector. Rays that left the packet cost
//! nothing: at Sponza's probes a packet arrives at an inner node with 3.8 of its 8 rays on
//! average, and at a leaf with 2.1. The shared origin makes `box - origin`, `v0 - origin` and
//! `ng . (v0 - origin)` one value per node or leaf, not one per ray. Boxes are plain f32, not
//! obvhs' compressed nodes, which trade decode work per ray for memory.
//!
//! The tree is obvhs' PLOC binary BVH collapsed greedily (open the child with the largest
//! surface area until eight), with subtrees of at most [`LEAF_TRIANGLES`] triangles as leaves.
//!
//! The closest hit is defined without reference to traversal: the least `t`, ties going to the
//! lowest triangle index. Box tests are conservative (the far distance is widened by
//! `4 eps`, after Ize, "Robust BVH Ray Traversal", JCGT 2013) and a child is entered when its
//! near distance equals a ray's best `t`, so a ray gets the same hit whichever packet carries
//! it, alone or with seven others (unit tests against a brute-force loop over every triangle).

use glam::{BVec4A, Vec3, Vec4};
use obvhs::{bvh2::Bvh2, triangle::Triangle};

/// Rays in a packet and children in a node.
pub const LANES: usize = 8;

/// Most triangles in a leaf: one SIMD vector of them.
pub const LEAF_TRIANGLES: u32 = 4;

type Lanes = [f32; LANES];

/// Slack on a box's far distance: rounding of the slab distances can otherwise make a ray that
/// grazes a box's edge miss it (Ize 2013 bounds the error by `1 + 2 gamma_3`; this is a little
/// more).
const FAR_SLACK: f32 = 1.0 + 4.0 * f32::EPSILON;

/// Direction components smaller than this are replaced by it (keeping the sign) for the box
/// tests only, so that `0 * (1 / 0)` never makes a NaN.
const TINY: f32 = 1e-30;

/// Eight children: boxes, and for each either a node index or a leaf.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Node {
    min: [Lanes; 3],
    max: [Lanes; 3],
    /// Inner child: its node index; leaf child: its first [`Tri4`].
    index: [u32; LANES],
    /// Leaf child: its [`Tri4`] count; 0 for an inner child.
    count: [u8; LANES],
    /// Children in use (the first `len`).
    len: u8,
}

impl Node {
    const EMPTY: Node = Node {
        min: [[0.0; LANES]; 3],
        max: [[0.0; LANES]; 3],
        index: [0; LANES],
        count: [0; LANES],
        len: 0,
    };
}

/// Four triangles, structure of arrays, in the layout of obvhs' `RtTriangle` (`e1 = v0 - v1`,
/// `e2 = v2 - v0`, `ng = e1 x e2`), with their indices in the scene. Unused lanes have `ng = 0`,
/// which no ray hits.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Tri4 {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    ng: [Vec4; 3],
    index: [u32; 4],
}

impl Tri4 {
    const EMPTY: Tri4 = Tri4 {
        v0: [Vec4::ZERO; 3],
        e1: [Vec4::ZERO; 3],
        e2: [Vec4::ZERO; 3],
        ng: [Vec4::ZERO; 3],
        index: [u32::MAX; 4],
    };

    /// Puts triangle `v` (scene index `index`) in lane `j`.
    fn set(&mut self, j: usize, v: [Vec3; 3], index: u32) {
        let (e1, e2) = (v[0] - v[1], v[2] - v[0]);
        let ng = e1.cross(e2);
        for a in 0..3 {
            self.v0[a][j] = v[0][a];
            self.e1[a][j] = e1[a];
            self.e2[a][j] = e2[a];
            self.ng[a][j] = ng[a];
        }
        self.index[j] = index;
    }
}

/// The wide BVH and its triangles in leaf order.
#[derive(Default)]
pub struct Bvh8 {
    nodes: Vec<Node>,
    triangles: Vec<Tri4>,
}

/// A stack entry: an inner node or a leaf's triangles, the rays that entered its box and the
/// nearest of their entry distances.
#[derive(Clone, Copy)]
struct Entry {
    index: u32,
    count: u8,
    mask: u8,
    near: f32,
}

/// Up to eight rays from one origin.
struct Packet {
    origin: Vec3,
    dir: [Lanes; 3],
    /// Inverse directions ([`TINY`] for zero components).
    inv: [Lanes; 3],
    /// Best distance so far (`tmax`: none).
    t: Lanes,
    /// Triangle (scene index) at `t`, `u32::MAX` for none.
    hit: [u32; LANES],
}

/// The set lanes of a mask as bits.
#[inline(always)]
fn bits(m: BVec4A) -> u8 {
    m.bitmask() as u8
}

/// The set bits of `mask`, lowest first.
#[inline(always)]
fn each_bit(mut mask: u8) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            k
        })
    })
}

impl Bvh8 {
    /// Collapses `bvh2`, built over `triangles` (whose indices are the scene's).
    pub fn from_bvh2(bvh2: &Bvh2, triangles: &[Triangle]) -> Bvh8 {
        if bvh2.nodes.is_empty() || triangles.is_empty() {
            return Bvh8::default();
        }
        let below = crate::bvh::subtree_triangles(bvh2);
        let is_leaf = |i: usize| bvh2.nodes[i].is_leaf() || below[i] <= LEAF_TRIANGLES;
        let mut out = Bvh8 {
            nodes: vec![Node::EMPTY],
            triangles: Vec::with_capacity(triangles.len() / 2),
        };
        let mut work = vec![(0usize, 0usize)];
        while let Some((src, dst)) = work.pop() {
            let mut node = Node::EMPTY;
            for (k, &c) in open(bvh2, &below, src).iter().enumerate() {
                let (lo, hi) = padded(bvh2.nodes[c].aabb());
                for a in 0..3 {
                    node.min[a][k] = lo[a];
                    node.max[a][k] = hi[a];
                }
                if is_leaf(c) {
                    let first = out.triangles.len();
                    let mut n = 0;
                    crate::bvh::leaf_primitives(bvh2, c, |p| {
                        if n % 4 == 0 {
                            out.triangles.push(Tri4::EMPTY);
                        }
                        let t = &triangles[p as usize];
                        let v = [t.v0, t.v1, t.v2].map(Vec3::from);
                        if let Some(q) = out.triangles.last_mut() {
                            q.set(n % 4, v, p);
                        }
                        n += 1;
                    });
                    node.index[k] = first as u32;
                    node.count[k] = (out.triangles.len() - first) as u8;
                } else {
                    node.index[k] = out.nodes.len() as u32;
                    out.nodes.push(Node::EMPTY);
                    work.push((c, node.index[k] as usize));
                }
                node.len = k as u8 + 1;
            }
            out.nodes[dst] = node;
        }
        out
    }

    /// Closest hits within `tmax` of up to [`LANES`] rays from `origin` along `dirs`: per ray,
    /// the scene's triangle index and the distance in units of `dirs`' length.
    pub fn closest_hits(
        &self,
        origin: Vec3,
        dirs: &[Vec3],
        tmax: f32,
    ) -> [Option<(u32, f32)>; LANES] {
        assert!(dirs.len() <= LANES, "a packet holds at most {LANES} rays");
        let mut hits = [None; LANES];
        if self.nodes.is_empty() || dirs.is_empty() {
            return hits;
        }
        let mut p = Packet {
            origin,
            dir: [[0.0; LANES]; 3],
            inv: [[0.0; LANES]; 3],
            t: [tmax; LANES],
            hit: [u32::MAX; LANES],
        };
        for (k, d) in dirs.iter().enumerate() {
            for a in 0..3 {
                p.dir[a][k] = d[a];
                let safe = if d[a].abs() < TINY {
                    TINY.copysign(d[a])
                } else {
                    d[a]
                };
                p.inv[a][k] = 1.0 / safe;
            }
        }
        let all = (1u16 << dirs.len()) as u8 - 1;
        let mut stack = Vec::with_capacity(64);
        stack.push(Entry {
            index: 0,
            count: 0,
            mask: all,
            near: 0.0,
        });
        while let Some(e) = stack.pop() {
            // Every ray in the entry has a hit nearer than its box: skip.
            if each_bit(e.mask).all(|k| e.near > p.t[k]) {
                continue;
            }
            if e.count == 0 {
                self.visit(&self.nodes[e.index as usize], &p, e.mask, &mut stack);
            } else {
                let first = e.index as usize;
                for tri in &self.triangles[first..first + usize::from(e.count)] {
                    p.intersect(tri, e.mask);
                }
            }
        }
        for (k, hit) in hits.iter_mut().enumerate().take(dirs.len()) {
            if p.hit[k] != u32::MAX {
                *hit = Some((p.hit[k], p.t[k]));
            }
        }
        hits
    }

    /// The leaves (first [`Tri4`], count) whose boxes overlap the box `lo..=hi`: every
    /// triangle a ray inside that box can hit there.
    pub fn leaves_in(&self, lo: Vec3, hi: Vec3) -> Vec<(u32, u8)> {
        let mut leaves = Vec::new();
        let mut stack = vec![0u32];
        while let Some(i) = stack.pop() {
            let Some(node) = self.nodes.get(i as usize) else {
                break;
            };
            for c in 0..usize::from(node.len) {
                let overlaps = (0..3).all(|a| node.min[a][c] <= hi[a] && node.max[a][c] >= lo[a]);
                if !overlaps {
                    continue;
                }
                if node.count[c] == 0 {
                    stack.push(node.index[c]);
                } else {
                    leaves.push((node.index[c], node.count[c]));
                }
            }
        }
        leaves
    }

    /// [`Bvh8::closest_hits`] of one ray, among the triangles of `leaves` only (exact when they
    /// are [`Bvh8::leaves_in`] a box that holds the ray's first `tmax` of length).
    pub fn closest_hit_among(
        &self,
        leaves: &[(u32, u8)],
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
    ) -> Option<(u32, f32)> {
        let mut p = Packet {
            origin,
            dir: [[dir.x; LANES], [dir.y; LANES], [dir.z; LANES]],
            inv: [[0.0; LANES]; 3],
            t: [tmax; LANES],
            hit: [u32::MAX; LANES],
        };
        for &(first, count) in leaves {
            let first = first as usize;
            for tri in &self.triangles[first..first + usize::from(count)] {
                p.intersect(tri, 1);
            }
        }
        (p.hit[0] != u32::MAX).then_some((p.hit[0], p.t[0]))
    }

    /// Tests the packet's rays in `mask` against a node's children and pushes those entered,
    /// nearest last (so popped first).
    #[inline(always)]
    fn visit(&self, node: &Node, p: &Packet, mask: u8, stack: &mut Vec<Entry>) {
        // Per axis and half, the children's planes relative to the origin.
        let rel = |planes: &[Lanes; 3], a: usize, h: usize| {
            Vec4::from_slice(&planes[a][4 * h..]) - Vec4::splat(p.origin[a])
        };
        let lo: [[Vec4; 2]; 3] =
            std::array::from_fn(|a| [rel(&node.min, a, 0), rel(&node.min, a, 1)]);
        let hi: [[Vec4; 2]; 3] =
            std::array::from_fn(|a| [rel(&node.max, a, 0), rel(&node.max, a, 1)]);
        let mut rays = [0u8; LANES];
        let mut near = [Vec4::INFINITY; 2];
        for k in each_bit(mask) {
            let inv = [0, 1, 2].map(|a| Vec4::splat(p.inv[a][k]));
            for h in 0..2 {
                let (mut tn, mut tf) = (Vec4::ZERO, Vec4::INFINITY);
                for a in 0..3 {
                    let (t0, t1) = (lo[a][h] * inv[a], hi[a][h] * inv[a]);
                    tn = tn.max(t0.min(t1));
                    tf = tf.min(t0.max(t1));
                }
                let enter = tn.cmple((tf * FAR_SLACK).min(Vec4::splat(p.t[k])));
                near[h] = Vec4::select(enter, near[h].min(tn), near[h]);
                for c in each_bit(bits(enter)) {
                    rays[4 * h + c] |= 1 << k;
                }
            }
        }
        let base = stack.len();
        for c in 0..usize::from(node.len) {
            if rays[c] == 0 {
                continue;
            }
            let entry = Entry {
                index: node.index[c],
                count: node.count[c],
                mask: rays[c],
                near: near[c / 4][c % 4],
            };
            // Insertion by descending distance among this node's entries.
            let mut i = stack.len();
            stack.push(entry);
            while i > base && stack[i - 1].near < entry.near {
                stack[i] = stack[i - 1];
                i -= 1;
            }
            stack[i] = entry;
        }
    }
}

impl Packet {
    /// Möller-Trumbore in the form of obvhs' `RtTriangle::intersect` with the barycentric
    /// tests widened by [`prt_format::EDGE_TOLERANCE`] (exact tests let a ray aimed at an edge
    /// two triangles share slip between them when both round it outside:
    /// `tests/tests/geometry.rs`), for each ray in `mask` against four triangles at once,
    /// keeping the nearer hit (ties to the lower triangle index).
    #[inline(always)]
    fn intersect(&mut self, tri: &Tri4, mask: u8) {
        let o = self.origin;
        let c = [0, 1, 2].map(|a| tri.v0[a] - Vec4::splat(o[a]));
        let [ngx, ngy, ngz] = tri.ng;
        let ngc = ngx * c[0] + ngy * c[1] + ngz * c[2];
        let eps = Vec4::splat(-prt_format::EDGE_TOLERANCE);
        for k in each_bit(mask) {
            let [dx, dy, dz] = [0, 1, 2].map(|a| Vec4::splat(self.dir[a][k]));
            // r = d x c, in glam's operand order.
            let rx = dy * c[2] - c[1] * dz;
            let ry = dz * c[0] - c[2] * dx;
            let rz = dx * c[1] - c[0] * dy;
            let inv_det = Vec4::ONE / (ngx * dx + ngy * dy + ngz * dz);
            let u = (rx * tri.e2[0] + ry * tri.e2[1] + rz * tri.e2[2]) * inv_det;
            let v = (rx * tri.e1[0] + ry * tri.e1[1] + rz * tri.e1[2]) * inv_det;
            let w = Vec4::ONE - u - v;
            let t = ngc * inv_det;
            let candidate = inv_det.abs().cmplt(Vec4::INFINITY)
                & u.cmpge(eps)
                & v.cmpge(eps)
                & w.cmpge(eps)
                & t.cmpge(Vec4::ZERO)
                & t.cmple(Vec4::splat(self.t[k]));
            for j in each_bit(bits(candidate)) {
                let (t, index) = (t[j], tri.index[j]);
                if t < self.t[k] || (t == self.t[k] && index < self.hit[k]) {
                    self.t[k] = t;
                    self.hit[k] = index;
                }
            }
        }
    }
}

/// A box grown so that the box test is conservative: by `8 EDGE_TOLERANCE` of its largest
/// extent, as far as a triangle widened by [`prt_format::EDGE_TOLERANCE`] can reach past its own
/// box (about `3 sqrt(3)` tolerances of the diagonal), and by four float steps of each
/// coordinate, so that a ray starting on a box's face, e.g. a probe on a wall's plane, is inside
/// it even when a direction component is zero (replaced by [`TINY`]). The growth is monotone in
/// the box, so a parent still contains its children.
fn padded(aabb: &obvhs::aabb::Aabb) -> (Vec3, Vec3) {
    let (lo, hi) = (Vec3::from(aabb.min), Vec3::from(aabb.max));
    let grow = 8.0 * prt_format::EDGE_TOLERANCE * (hi - lo).max_element();
    let ulps = |v: Vec3| v.abs() * (4.0 * f32::EPSILON);
    (lo - ulps(lo) - grow, hi + ulps(hi) + grow)
}

/// Up to eight nodes of `bvh2` covering `node`'s subtree: the node itself when it is a leaf or
/// small enough to be one, else its children, opening the inner child with the largest surface
/// area until there are eight (ties to the first).
fn open(bvh2: &Bvh2, below: &[u32], node: usize) -> Vec<usize> {
    let inner = |i: usize| !bvh2.nodes[i].is_leaf() && below[i] > LEAF_TRIANGLES;
    let mut kids = vec![node];
    while kids.len() < LANES {
        let widest = kids
            .iter()
            .enumerate()
            .filter(|&(_, &i)| inner(i))
            .map(|(k, &i)| (k, bvh2.nodes[i].aabb().half_area()))
            .fold(None, |best: Option<(usize, f32)>, (k, a)| match best {
                Some((_, b)) if b >= a => best,
                _ => Some((k, a)),
            });
        let Some((k, _)) = widest else { break };
        let first = bvh2.nodes[kids[k]].first_index as usize;
        kids[k] = first;
        kids.insert(k + 1, first + 1);
    }
    kids
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::{ploc::PlocBuilder, BvhBuildParams};

    /// A deterministic generator (xorshift) of floats in [0, 1).
    struct Rng(u32);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 17;
            self.0 ^= self.0 << 5;
            (self.0 >> 8) as f32 / (1 << 24) as f32
        }
        fn vec(&mut self, scale: f32) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next()) * scale
        }
    }

    fn build(tris: &[Triangle]) -> Bvh8 {
        let params = BvhBuildParams::medium_build();
        let bvh2 = PlocBuilder::with_capacity(tris.len()).build(
            params.ploc_search_distance,
            tris,
            (0..tris.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        Bvh8::from_bvh2(&bvh2, tris)
    }

    /// The hit a loop over every triangle finds: the same test, one ray and one triangle at a
    /// time in scalar code, and the same tie rule.
    fn brute(tris: &[Triangle], o: Vec3, d: Vec3) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for (i, t) in tris.iter().enumerate() {
            let v = [t.v0, t.v1, t.v2].map(Vec3::from);
            let (e1, e2) = (v[0] - v[1], v[2] - v[0]);
            let ng = e1.cross(e2);
            let c = v[0] - o;
            let r = d.cross(c);
            let inv_det = 1.0 / ng.dot(d);
            let (u, v) = (r.dot(e2) * inv_det, r.dot(e1) * inv_det);
            let w = 1.0 - u - v;
            let t = ng.dot(c) * inv_det;
            let eps = -prt_format::EDGE_TOLERANCE;
            let inside = inv_det.is_finite() && u >= eps && v >= eps && w >= eps && t >= 0.0;
            if inside && best.is_none_or(|(_, b)| t < b) {
                best = Some((i as u32, t));
            }
        }
        best
    }

    fn check(tris: &[Triangle], origins: &[Vec3], dirs: &[Vec3]) -> usize {
        let bvh = build(tris);
        let mut hits = 0;
        for &o in origins {
            for packet in dirs.chunks(LANES) {
                let got = bvh.closest_hits(o, packet, f32::INFINITY);
                for (k, &d) in packet.iter().enumerate() {
                    let want = brute(tris, o, d);
                    assert_eq!(got[k], want, "origin {o}, direction {d}");
                    // Among the triangles near its first stretch, the same hit within it.
                    let reach = want.map_or(2.0, |(_, t)| t.min(2.0));
                    let r = Vec3::splat(reach);
                    let near = bvh.leaves_in(o - r, o + r);
                    let short = bvh.closest_hits(o, &[d], reach)[0];
                    assert_eq!(bvh.closest_hit_among(&near, o, d, reach), short);
                    // Alone, the ray gets the same hit as in its packet.
                    assert_eq!(bvh.closest_hits(o, &[d], f32::INFINITY)[0], want);
                    // Within the hit's distance, the same hit; within less, none.
                    if let Some((_, t)) = want.filter(|&(_, t)| t > 0.0) {
                        assert_eq!(bvh.closest_hits(o, &[d], t)[0], want);
                        assert_eq!(bvh.closest_hits(o, &[d], t * 0.999)[0], None);
                    }
                    hits += usize::from(want.is_some());
                }
            }
        }
        hits
    }

    #[test]
    fn packets_find_the_brute_force_hit_in_a_triangle_soup() {
        let mut rng = Rng(0x9e37_79b9);
        let tris: Vec<Triangle> = (0..600)
            .map(|_| {
                let c = rng.vec(10.0);
                Triangle {
                    v0: (c + rng.vec(3.0)).into(),
                    v1: (c + rng.vec(3.0)).into(),
                    v2: (c + rng.vec(3.0)).into(),
                }
            })
            .collect();
        let origins: Vec<Vec3> = (0..20).map(|_| rng.vec(10.0)).collect();
        let dirs: Vec<Vec3> = prt_format::directions::fibonacci_directions(203)
            .into_iter()
            .map(Vec3::from)
            .collect();
        let hits = check(&tris, &origins, &dirs);
        assert!(
            hits > 1000,
            "{hits} hits: the test needs hits to mean anything"
        );
    }

    /// Axis-aligned rays along the faces of an axis-aligned box (zero direction components,
    /// rays in the planes of flat bounding boxes, edges shared by two triangles, ties).
    #[test]
    fn packets_find_the_brute_force_hit_on_axis_aligned_faces() {
        let v = |x: f32, y: f32, z: f32| glam::Vec3A::new(x, y, z);
        let mut tris = Vec::new();
        for a in 0..3 {
            for side in [0.0, 1.0] {
                let p = |u: f32, w: f32| {
                    let mut c = [0.0; 3];
                    c[a] = side;
                    c[(a + 1) % 3] = u;
                    c[(a + 2) % 3] = w;
                    v(c[0], c[1], c[2])
                };
                tris.push(Triangle {
                    v0: p(0.0, 0.0),
                    v1: p(1.0, 0.0),
                    v2: p(1.0, 1.0),
                });
                tris.push(Triangle {
                    v0: p(0.0, 0.0),
                    v1: p(1.0, 1.0),
                    v2: p(0.0, 1.0),
                });
            }
        }
        let mut dirs = Vec::new();
        for a in 0..3 {
            for s in [-1.0, 1.0] {
                let mut d = Vec3::ZERO;
                d[a] = s;
                dirs.push(d);
            }
        }
        dirs.extend([Vec3::ONE.normalize(), Vec3::new(1.0, 1.0, 0.0).normalize()]);
        let grid = [0.0, 0.25, 0.5, 1.0];
        let origins: Vec<Vec3> = grid
            .iter()
            .flat_map(|&x| {
                grid.iter()
                    .flat_map(move |&y| grid.map(|z| Vec3::new(x, y, z)))
            })
            .collect();
        let hits = check(&tris, &origins, &dirs);
        assert!(hits > 300, "{hits} hits");
    }
}
