//! An uncompressed 8-wide BVH traced by packets of rays that leave one point.
//!
//! Every probe shoots its lattice directions from one origin, in Morton order of the octahedral
//! map ([`crate::trace::coherent_order`]), so consecutive rays span a narrow cone. Tracing eight
//! of them together (ray packets: Wald, Slusallek, Benthin, Wagner, "Interactive Rendering with
//! Coherent Ray Tracing", 2001) fetches each node once for the packet and tests a child box or a
//! triangle against all eight rays as two SSE vectors of four (glam's `Vec4`). The shared origin makes `box - origin`, `v0 - origin` and `ng . (v0 - origin)`
//! one value per packet instead of one per ray. Nodes hold eight children with their boxes in
//! plain f32, structure of arrays, as Embree's BVH8 does: a packet amortises the node fetch, so
//! obvhs' compressed nodes (decoded per ray) would save memory at the price of decode work.
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

/// Most triangles in a leaf.
pub const LEAF_TRIANGLES: u32 = 4;

type Lanes = [f32; LANES];

/// Slack on a box's far distance: rounding of the slab distances can otherwise make a ray that
/// grazes a box's edge miss it (Ize 2013 bounds the error by `1 + 2 gamma_3`; this is a little
/// more).
const FAR_SLACK: f32 = 1.0 + 4.0 * f32::EPSILON;

/// Direction components smaller than this are replaced by it (keeping the sign) for the box
/// tests only, so that `0 * (1 / 0)` never makes a NaN.
const TINY: f32 = 1e-30;

/// Eight children: boxes, and for each either a node index or a run of triangles.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Node {
    min: [Lanes; 3],
    max: [Lanes; 3],
    /// Inner child: its node index; leaf child: its first triangle.
    index: [u32; LANES],
    /// Leaf child: its triangle count; 0 for an inner child.
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

/// A triangle in the layout of obvhs' `RtTriangle` (`e1 = v0 - v1`, `e2 = v2 - v0`,
/// `ng = e1 x e2`), with its index in the scene.
#[derive(Clone, Copy, Debug)]
struct Tri {
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
    ng: Vec3,
    index: u32,
}

/// The wide BVH and its triangles in leaf order.
#[derive(Default)]
pub struct Bvh8 {
    nodes: Vec<Node>,
    triangles: Vec<Tri>,
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

/// Eight lanes as two SSE vectors.
type Wide = [Vec4; 2];

/// Eight rays from one origin.
struct Packet {
    origin: Vec3,
    /// Per axis, the rays' direction components.
    dir: [Wide; 3],
    /// Per axis, their inverses ([`TINY`] for zero).
    inv: [Wide; 3],
    /// Best distance so far (infinite: none).
    t: Wide,
    /// Triangle (scene index) at `t`.
    hit: [u32; LANES],
}

/// The lanes of a mask as bits (lane `k` is bit `k`).
#[inline(always)]
fn bits(m: [BVec4A; 2]) -> u8 {
    (m[0].bitmask() | m[1].bitmask() << 4) as u8
}

/// Lane `k` of `w`.
#[inline(always)]
fn lane(w: &Wide, k: usize) -> f32 {
    w[k / 4][k % 4]
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
            triangles: Vec::with_capacity(triangles.len()),
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
                    node.index[k] = out.triangles.len() as u32;
                    crate::bvh::leaf_primitives(bvh2, c, |p| {
                        let t = &triangles[p as usize];
                        let (v0, v1, v2) = (Vec3::from(t.v0), Vec3::from(t.v1), Vec3::from(t.v2));
                        let (e1, e2) = (v0 - v1, v2 - v0);
                        out.triangles.push(Tri {
                            v0,
                            e1,
                            e2,
                            ng: e1.cross(e2),
                            index: p,
                        });
                    });
                    node.count[k] = (out.triangles.len() as u32 - node.index[k]) as u8;
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
        let mut dir = [[0.0f32; LANES]; 3];
        let mut inv = [[1.0 / TINY; LANES]; 3];
        for (k, d) in dirs.iter().enumerate() {
            for a in 0..3 {
                dir[a][k] = d[a];
                let safe = if d[a].abs() < TINY {
                    TINY.copysign(d[a])
                } else {
                    d[a]
                };
                inv[a][k] = 1.0 / safe;
            }
        }
        let wide = |l: &Lanes| [Vec4::from_slice(&l[..4]), Vec4::from_slice(&l[4..])];
        let mut p = Packet {
            origin,
            dir: dir.each_ref().map(wide),
            inv: inv.each_ref().map(wide),
            t: [Vec4::splat(tmax); 2],
            hit: [u32::MAX; LANES],
        };
        let all = (1u16 << dirs.len()) as u8 - 1;
        let mut stack = Vec::with_capacity(64);
        stack.push(Entry {
            index: 0,
            count: 0,
            mask: all,
            near: 0.0,
        });
        while let Some(e) = stack.pop() {
            // Rays whose best hit is nearer than the box for all of them: skip.
            let far = (0..LANES)
                .filter(|&k| e.mask >> k & 1 != 0)
                .fold(0.0f32, |m, k| m.max(lane(&p.t, k)));
            if e.near > far {
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
                *hit = Some((p.hit[k], lane(&p.t, k)));
            }
        }
        hits
    }

    /// Tests the packet against a node's children and pushes those it enters, nearest last (so
    /// popped first).
    #[inline(always)]
    fn visit(&self, node: &Node, p: &Packet, mask: u8, stack: &mut Vec<Entry>) {
        let base = stack.len();
        for c in 0..usize::from(node.len) {
            let mut enter = [BVec4A::FALSE; 2];
            let mut near = [Vec4::ZERO; 2];
            for h in 0..2 {
                let (mut tn, mut tf) = (Vec4::ZERO, p.t[h]);
                for a in 0..3 {
                    let lo = Vec4::splat(node.min[a][c] - p.origin[a]);
                    let hi = Vec4::splat(node.max[a][c] - p.origin[a]);
                    let (t0, t1) = (lo * p.inv[a][h], hi * p.inv[a][h]);
                    tn = tn.max(t0.min(t1));
                    tf = tf.min(t0.max(t1) * FAR_SLACK);
                }
                enter[h] = tn.cmple(tf);
                near[h] = Vec4::select(enter[h], tn, Vec4::INFINITY);
            }
            let hit = bits(enter) & mask;
            if hit == 0 {
                continue;
            }
            let near = if hit == bits(enter) {
                near[0].min(near[1]).min_element()
            } else {
                (0..LANES)
                    .filter(|&k| hit >> k & 1 != 0)
                    .fold(f32::INFINITY, |m, k| m.min(lane(&near, k)))
            };
            let entry = Entry {
                index: node.index[c],
                count: node.count[c],
                mask: hit,
                near,
            };
            // Insertion by descending distance among this node's entries.
            let mut i = stack.len();
            stack.push(entry);
            while i > base && stack[i - 1].near < near {
                stack[i] = stack[i - 1];
                i -= 1;
            }
            stack[i] = entry;
        }
    }
}

impl Packet {
    /// Möller-Trumbore as `crate::bvh`'s single-ray test, lane by lane, keeping the nearer hit
    /// (ties to the lower triangle index).
    #[inline(always)]
    fn intersect(&mut self, tri: &Tri, mask: u8) {
        let c = tri.v0 - self.origin;
        let ngc = Vec4::splat(tri.ng.dot(c));
        let eps = Vec4::splat(-prt_format::EDGE_TOLERANCE);
        let s = |v: f32| Vec4::splat(v);
        let mut candidate = [BVec4A::FALSE; 2];
        let mut ts = [Vec4::ZERO; 2];
        for h in 0..2 {
            let (dx, dy, dz) = (self.dir[0][h], self.dir[1][h], self.dir[2][h]);
            // r = d x c, in glam's operand order.
            let rx = dy * s(c.z) - s(c.y) * dz;
            let ry = dz * s(c.x) - s(c.z) * dx;
            let rz = dx * s(c.y) - s(c.x) * dy;
            let inv_det = Vec4::ONE / (s(tri.ng.x) * dx + s(tri.ng.y) * dy + s(tri.ng.z) * dz);
            let u = (rx * s(tri.e2.x) + ry * s(tri.e2.y) + rz * s(tri.e2.z)) * inv_det;
            let v = (rx * s(tri.e1.x) + ry * s(tri.e1.y) + rz * s(tri.e1.z)) * inv_det;
            let w = Vec4::ONE - u - v;
            let t = ngc * inv_det;
            ts[h] = t;
            candidate[h] = inv_det.abs().cmplt(Vec4::INFINITY)
                & u.cmpge(eps)
                & v.cmpge(eps)
                & w.cmpge(eps)
                & t.cmpge(Vec4::ZERO)
                & t.cmple(self.t[h]);
        }
        let mut m = bits(candidate) & mask;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let (t, best) = (lane(&ts, k), lane(&self.t, k));
            if t < best || tri.index < self.hit[k] {
                self.t[k / 4][k % 4] = t;
                self.hit[k] = tri.index;
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

    /// The hit a loop over every triangle finds, with the same test and tie rule.
    fn brute(tris: &[Triangle], o: Vec3, d: Vec3) -> Option<(u32, f32)> {
        let w = |x: f32| [Vec4::splat(x); 2];
        let mut p = Packet {
            origin: o,
            dir: [w(d.x), w(d.y), w(d.z)],
            inv: [w(0.0); 3],
            t: w(f32::INFINITY),
            hit: [u32::MAX; LANES],
        };
        for (i, t) in tris.iter().enumerate() {
            let (v0, v1, v2) = (Vec3::from(t.v0), Vec3::from(t.v1), Vec3::from(t.v2));
            let (e1, e2) = (v0 - v1, v2 - v0);
            let tri = Tri {
                v0,
                e1,
                e2,
                ng: e1.cross(e2),
                index: i as u32,
            };
            p.intersect(&tri, 1);
        }
        (p.hit[0] != u32::MAX).then_some((p.hit[0], p.t[0].x))
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
