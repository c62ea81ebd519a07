//! An uncompressed 8-wide BVH traced by packets of rays that leave one point.
//!
//! Every probe shoots its lattice directions from one origin, in Morton order of the octahedral map
//! (`crate::trace::coherent_order`), so consecutive rays span a narrow cone. Tracing `PACKET`
//! of them together (ray packets: Wald, Slusallek, Benthin, Wagner, "Interactive Rendering with
//! Coherent Ray Tracing", 2001) fetches each node once for the packet. Inside a node the work is
//! per ray, SIMD across the node (as Embree's single-ray BVH8 traversal): each ray still in the
//! packet tests the eight child boxes in one AVX vector (two SSE vectors where the CPU lacks AVX,
//! [`Bvh8::closest_hits`] and [`Bvh8::occluded`] choosing at run time), and each leaf's four triangles, stored structure
//! of arrays, in one SSE vector. Rays that left the packet cost nothing, which matters: a packet
//! reaches most nodes, and most leaves, with only a few of its rays.
//! The shared origin makes `box - origin`, `v0 - origin` and `ng . (v0 - origin)` one value per
//! node or leaf, not one per ray. Boxes are plain f32, not obvhs' compressed nodes, which trade
//! decode work per ray for memory.
//!
//! The tree is obvhs' PLOC binary BVH collapsed greedily (open the child with the largest
//! surface area until eight), with subtrees of at most [`TRI_LANES`] triangles as leaves.
//!
//! The closest hit is defined without reference to traversal: the least `t`, ties going to the
//! lowest triangle index. Box tests are conservative (boxes grown past what the triangle test's
//! edge tolerance can reach, the far distance widened by `4 eps` after Ize, "Robust BVH Ray
//! Traversal", JCGT 2013) and a child is entered when its near distance equals a ray's best `t`,
//! so a ray gets the same hit whichever packet carries it, alone or with others (unit tests
//! against a brute-force loop over every triangle). One caveat: rounding in the triangle test of
//! a near-degenerate sliver hit at a grazing angle could put its hit outside its grown box, and
//! then whether it is found depends on the packet; the bake stays deterministic, since packets are
//! fixed runs of the ray order.

use glam::{BVec4A, Vec3, Vec4};
use obvhs::{bvh2::Bvh2, triangle::Triangle};
use rayon::prelude::*;

use crate::accel::leaf_order::{prefetch_children, LeafOrder};

/// Children in a node.
pub const LANES: usize = 8;

/// Rays in a packet. The tracing is bound by the latency of fetching nodes and leaves, so the
/// more rays share a fetch the better, until the packet's cone grows wide enough to visit many
/// nodes that few of its rays need: 32 traced fastest of 8, 16, 32 and 64. The hits are the
/// same for any packet size.
pub(crate) const PACKET: usize = 32;

/// A set of a packet's rays.
type RayMask = u32;
const _: () = assert!(PACKET <= RayMask::BITS as usize);

/// Triangles in a leaf: one SSE vector of them (`Tri4`).
pub const TRI_LANES: usize = 4;

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
    index: [u32; TRI_LANES],
}

impl Tri4 {
    const EMPTY: Tri4 = Tri4 {
        v0: [Vec4::ZERO; 3],
        e1: [Vec4::ZERO; 3],
        e2: [Vec4::ZERO; 3],
        ng: [Vec4::ZERO; 3],
        index: [u32::MAX; TRI_LANES],
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
    mask: RayMask,
    near: f32,
}

thread_local! {
    /// Each thread's traversal stack, reused by every packet it traces: a stack allocated per
    /// packet (of eight rays, then) was a malloc and a free every two microseconds or so.
    static STACK: std::cell::Cell<Vec<Entry>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Up to [`PACKET`] rays from one origin.
struct Packet {
    origin: Vec3,
    dir: [[f32; PACKET]; 3],
    /// Inverse directions ([`TINY`] for zero components).
    inv: [[f32; PACKET]; 3],
    /// Best distance so far (`tmax`: none).
    t: [f32; PACKET],
    /// Triangle (scene index) at `t`, `u32::MAX` for none.
    hit: [u32; PACKET],
}

/// `_mm_min_ps` of one lane: `a` when it is the lesser, else `b`.
#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `_mm_max_ps` of one lane: `a` when it is the greater, else `b`.
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// The set lanes of a mask as bits.
#[inline(always)]
fn bits(m: BVec4A) -> u8 {
    m.bitmask() as u8
}

/// The set bits of `mask`, lowest first.
#[inline(always)]
fn each_bit(mut mask: RayMask) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            k
        })
    })
}

impl Bvh8 {
    /// Collapses `bvh2`, built over `triangles` (whose indices are the scene's), its triangles
    /// in `order`: one walk lays out the nodes and numbers the leaves, then the leaves' triangles
    /// are gathered into their [`Tri4`]s in parallel. The walk chases the binary tree's nodes
    /// (a cache miss each) on the BVH stage's longest serial path, so it does nothing else:
    /// gathering there would add a miss per triangle to that path.
    pub(crate) fn from_bvh2(bvh2: &Bvh2, order: &LeafOrder, triangles: &[Triangle]) -> Bvh8 {
        let below = &order.below;
        if bvh2.nodes.is_empty() || triangles.is_empty() {
            return Bvh8::default();
        }
        let mut nodes = vec![Node::EMPTY];
        // The binary node of each leaf, in the order its Tri4 takes.
        let mut leaves: Vec<usize> = Vec::new();
        let mut work = vec![(0usize, 0usize)];
        while let Some((src, dst)) = work.pop() {
            let mut node = Node::EMPTY;
            let (kids, len) = open(bvh2, below, src);
            for (k, &c) in kids[..len].iter().enumerate() {
                let (lo, hi) = padded(bvh2.nodes[c].aabb());
                for a in 0..3 {
                    node.min[a][k] = lo[a];
                    node.max[a][k] = hi[a];
                }
                if inner(bvh2, below, c) {
                    node.index[k] = nodes.len() as u32;
                    nodes.push(Node::EMPTY);
                    work.push((c, node.index[k] as usize));
                } else {
                    // One Tri4: PLOC's leaves hold one triangle each, and a subtree becomes a
                    // leaf only when it has at most TRI_LANES of them.
                    node.index[k] = leaves.len() as u32;
                    node.count[k] = 1;
                    leaves.push(c);
                }
            }
            node.len = len as u8;
            nodes[dst] = node;
        }
        let triangles = leaves
            .par_iter()
            .map(|&c| {
                let leaf = order.under(c);
                // A panic, not a wrong tree, if a build ever made bigger leaves (the bake reports
                // it as an error of the BVH stage).
                assert!((1..=TRI_LANES).contains(&leaf.len()), "{leaf:?} in a leaf");
                let mut tri4 = Tri4::EMPTY;
                for (n, &p) in leaf.iter().enumerate() {
                    let t = &triangles[p as usize];
                    tri4.set(n, [t.v0, t.v1, t.v2].map(Vec3::from), p);
                }
                tri4
            })
            .collect();
        Bvh8 { nodes, triangles }
    }

    /// Closest hits within `tmax` of up to `PACKET` rays from `origin` along `dirs`: per ray,
    /// the scene's triangle index and the distance in units of `dirs`' length.
    pub fn closest_hits(
        &self,
        origin: Vec3,
        dirs: &[Vec3],
        tmax: f32,
    ) -> [Option<(u32, f32)>; PACKET] {
        let p = self.traced::<false>(origin, dirs, tmax);
        std::array::from_fn(|k| p.hit(k))
    }

    /// Which of up to `PACKET` rays from `origin` along `dirs` hit anything within `tmax`: bit
    /// `k` for ray `k`, set exactly when [`Bvh8::closest_hits`] finds ray `k` a hit. A visibility
    /// test (shadow or any-hit ray) needs no more, and a ray leaves the search at the end of the
    /// first leaf it hits in instead of searching on for a nearer hit. Until then its limit is
    /// `tmax` in both searches, and its own box tests against that limit decide which children
    /// it enters, whatever the order the other rays' hits give the stack: it reaches the same
    /// leaves, so the two agree on whether there is a hit (`tests`).
    pub fn occluded(&self, origin: Vec3, dirs: &[Vec3], tmax: f32) -> u32 {
        let p = self.traced::<true>(origin, dirs, tmax);
        (0..dirs.len())
            .filter(|&k| p.hit[k] != u32::MAX)
            .fold(0, |mask, k| mask | 1 << k)
    }

    /// The traced packet (closest hits, or with `ANY` each ray's first), in the copy for the
    /// CPU's instruction set.
    fn traced<const ANY: bool>(&self, origin: Vec3, dirs: &[Vec3], tmax: f32) -> Packet {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.traced_avx::<ANY>(origin, dirs, tmax) };
        }
        self.traced_in::<ANY>(origin, dirs, tmax)
    }

    /// [`Bvh8::traced`] compiled for AVX (a node's eight boxes in one vector). The results
    /// are the same bits: the same IEEE operations, lane for lane.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn traced_avx<const ANY: bool>(&self, origin: Vec3, dirs: &[Vec3], tmax: f32) -> Packet {
        self.traced_in::<ANY>(origin, dirs, tmax)
    }

    /// The body of [`Bvh8::traced`], inlined into each instruction set's copy. With `ANY`, a
    /// ray that has a hit retires: it leaves `live`, and so every entry's rays from then on
    /// (an entry left with none is skipped), and the traversal ends when every ray has one.
    #[inline(always)]
    fn traced_in<const ANY: bool>(&self, origin: Vec3, dirs: &[Vec3], tmax: f32) -> Packet {
        assert!(dirs.len() <= PACKET, "a packet holds at most {PACKET} rays");
        let mut p = Packet::new(origin, dirs, tmax);
        if self.nodes.is_empty() || dirs.is_empty() {
            return p;
        }
        let all = RayMask::MAX >> (RayMask::BITS as usize - dirs.len());
        let mut live = all;
        // Empty: every traversal leaves it empty before putting it back.
        let mut stack = STACK.take();
        stack.push(Entry {
            index: 0,
            count: 0,
            mask: all,
            near: 0.0,
        });
        while let Some(e) = stack.pop() {
            let mask = if ANY { e.mask & live } else { e.mask };
            // Every ray in the entry has a hit nearer than its box (or none is left live): skip.
            if each_bit(mask).all(|k| e.near > p.t[k]) {
                continue;
            }
            if e.count == 0 {
                self.visit(&self.nodes[e.index as usize], &p, mask, &mut stack);
                continue;
            }
            for tri in self.leaf(e.index, e.count) {
                p.intersect(tri, mask);
            }
            if ANY {
                for k in each_bit(mask).filter(|&k| p.hit[k] != u32::MAX) {
                    live &= !(1 << k);
                }
                if live == 0 {
                    stack.clear();
                }
            }
        }
        STACK.set(stack);
        p
    }

    /// The triangles of the leaf whose first [`Tri4`] is `first`.
    fn leaf(&self, first: u32, count: u8) -> &[Tri4] {
        let first = first as usize;
        &self.triangles[first..first + usize::from(count)]
    }

    /// The leaves (first `Tri4`, count) whose boxes overlap the box `lo..=hi`: every
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
        let mut p = Packet::new(origin, &[dir], tmax);
        for &(first, count) in leaves {
            for tri in self.leaf(first, count) {
                p.intersect(tri, 1);
            }
        }
        p.hit(0)
    }

    /// Tests the packet's rays in `mask` against a node's children and pushes those entered,
    /// nearest last (so popped first).
    ///
    /// Written over plain arrays of eight lanes, one per child, with `min` and `max` as `minps`
    /// and `maxps` compute them (the second operand when either is NaN), so that the compiler
    /// can vectorize it for the instruction set it compiles for: AVX in
    /// [`Bvh8::traced_avx`], SSE elsewhere (`tests` hold the two to the same bits);
    /// written as two glam `Vec4`s, the same test ran slower even than the SSE build of this.
    #[inline(always)]
    fn visit(&self, node: &Node, p: &Packet, mask: RayMask, stack: &mut Vec<Entry>) {
        let rel = |planes: &[Lanes; 3]| -> [Lanes; 3] {
            std::array::from_fn(|a| planes[a].map(|v| v - p.origin[a]))
        };
        let (lo, hi) = (rel(&node.min), rel(&node.max));
        let mut rays = [0 as RayMask; LANES];
        let mut near = [f32::INFINITY; LANES];
        for k in each_bit(mask) {
            let inv = [p.inv[0][k], p.inv[1][k], p.inv[2][k]];
            let limit = p.t[k];
            for c in 0..LANES {
                let (mut tn, mut tf) = (0.0f32, f32::INFINITY);
                for a in 0..3 {
                    let (t0, t1) = (lo[a][c] * inv[a], hi[a][c] * inv[a]);
                    tn = max_ps(tn, min_ps(t0, t1));
                    tf = min_ps(tf, max_ps(t0, t1));
                }
                let enter = tn <= min_ps(tf * FAR_SLACK, limit);
                near[c] = if enter { min_ps(near[c], tn) } else { near[c] };
                rays[c] |= RayMask::from(enter) << k;
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
                near: near[c],
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
    /// The rays from `origin` along `dirs` (at most [`PACKET`]), none hit within `tmax` yet.
    fn new(origin: Vec3, dirs: &[Vec3], tmax: f32) -> Packet {
        let mut p = Packet {
            origin,
            dir: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            t: [tmax; PACKET],
            hit: [u32::MAX; PACKET],
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
        p
    }

    /// Ray `k`'s closest hit so far: triangle and distance.
    fn hit(&self, k: usize) -> Option<(u32, f32)> {
        (self.hit[k] != u32::MAX).then_some((self.hit[k], self.t[k]))
    }

    /// Möller-Trumbore in the form of obvhs' `RtTriangle::intersect` with the barycentric
    /// tests widened by [`prt_format::EDGE_TOLERANCE`] (exact tests let a ray aimed at an edge
    /// two triangles share slip between them when both round it outside:
    /// `tests/tests/geometry.rs`), for each ray in `mask` against four triangles at once,
    /// keeping the nearer hit (ties to the lower triangle index).
    #[inline(always)]
    fn intersect(&mut self, tri: &Tri4, mask: RayMask) {
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
            for j in each_bit(RayMask::from(bits(candidate))) {
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

/// Whether node `i` of `bvh2` (with `below` triangles under each node) becomes an inner node of
/// the wide BVH, not a leaf.
fn inner(bvh2: &Bvh2, below: &[u32], i: usize) -> bool {
    !bvh2.nodes[i].is_leaf() && below[i] as usize > TRI_LANES
}

/// Up to eight nodes of `bvh2` covering `node`'s subtree (the first `len` of the array): the
/// node itself when it is a leaf or small enough to be one, else its children, opening the
/// inner child with the largest surface area until there are eight (ties to the first).
fn open(bvh2: &Bvh2, below: &[u32], node: usize) -> ([usize; LANES], usize) {
    // Each kid's half area, computed once; `None` for a kid that cannot be opened (a leaf, or
    // at most TRI_LANES triangles). A later kid replaces the widest so far unless that one's
    // area is at least its own: ties go to the first, and a kid whose area is NaN (a box with
    // an infinite side and a zero one) is opened too, so that every inner node is opened and
    // the collapse ends. An inner kid is opened here or becomes a node of the walk: its children
    // are asked for as soon as it is seen ([`prefetch_children`]).
    let area = |i: usize| {
        inner(bvh2, below, i).then(|| {
            prefetch_children(bvh2, i);
            bvh2.nodes[i].aabb().half_area()
        })
    };
    let (mut kids, mut areas) = ([node; LANES], [area(node); LANES]);
    let mut len = 1;
    while len < LANES {
        let mut widest: Option<(usize, f32)> = None;
        for (k, a) in areas[..len].iter().enumerate() {
            match (widest, *a) {
                (_, None) => {}
                (Some((_, best)), Some(a)) if best >= a => {}
                (_, Some(a)) => widest = Some((k, a)),
            }
        }
        let Some((k, _)) = widest else { break };
        let first = bvh2.nodes[kids[k]].first_index as usize;
        kids.copy_within(k + 1..len, k + 2);
        areas.copy_within(k + 1..len, k + 2);
        (kids[k], kids[k + 1]) = (first, first + 1);
        (areas[k], areas[k + 1]) = (area(first), area(first + 1));
        len += 1;
    }
    (kids, len)
}

#[cfg(test)]
mod tests;
