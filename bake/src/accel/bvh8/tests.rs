//! Tests of the packet tracer against a brute-force loop over every triangle.
use super::*;

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
    /// `n` triangles, each with corners up to `size` from a point up to `spread` from `offset`
    /// along each axis.
    fn soup(&mut self, n: usize, offset: Vec3, spread: f32, size: f32) -> Vec<Triangle> {
        (0..n)
            .map(|_| {
                let c = offset + self.vec(spread);
                Triangle {
                    v0: (c + self.vec(size)).into(),
                    v1: (c + self.vec(size)).into(),
                    v2: (c + self.vec(size)).into(),
                }
            })
            .collect()
    }
}

/// The bake's wide BVH over `tris`, built with obvhs' `medium_build` preset or (`fast`) its
/// `fast_build` ([`crate::accel::bvh::build_params`]): hits must not depend on which.
fn build(tris: &[Triangle], fast: bool) -> Bvh8 {
    let rays = if fast { 0 } else { u64::MAX };
    let bvh2 = crate::accel::bvh::ploc(
        tris,
        &crate::accel::bvh::build_params(tris.len(), rays),
        None,
    );
    Bvh8::from_bvh2(&bvh2, &LeafOrder::of(&bvh2), tris)
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
    let hits = check_with(&build(tris, false), tris, origins, dirs);
    assert_eq!(check_with(&build(tris, true), tris, origins, dirs), hits);
    hits
}

fn check_with(bvh: &Bvh8, tris: &[Triangle], origins: &[Vec3], dirs: &[Vec3]) -> usize {
    let mut hits = 0;
    // Whole packets, and packets of 8 and 5 rays: each ray's hit must not depend on which (the
    // hits are counted once, in whole packets).
    for (&o, size) in origins.iter().flat_map(|o| [PACKET, 8, 5].map(|n| (o, n))) {
        for packet in dirs.chunks(size) {
            let got = bvh.closest_hits(o, packet, f32::INFINITY);
            // The copy compiled for the baseline instruction set agrees with the one the CPU
            // runs (AVX where it has it).
            let baseline = bvh.traced_in::<false>(o, packet, f32::INFINITY);
            assert_eq!(std::array::from_fn(|k| baseline.hit(k)), got);
            // The any-hit test finds a hit for exactly the rays that have one, in either copy.
            let occluded = bvh.occluded(o, packet, f32::INFINITY);
            let any = bvh.traced_in::<true>(o, packet, f32::INFINITY);
            for (k, hit) in got.iter().enumerate().take(packet.len()) {
                assert_eq!(occluded >> k & 1 == 1, hit.is_some(), "origin {o}, ray {k}");
                assert_eq!(any.hit[k] != u32::MAX, hit.is_some());
            }
            for (k, &d) in packet.iter().enumerate() {
                let want = brute(tris, o, d);
                assert_eq!(got[k], want, "origin {o}, direction {d}");
                // Among the triangles near its first stretch, the same hit within it.
                let reach = want.map_or(2.0, |(_, t)| t.min(2.0));
                let r = Vec3::splat(reach);
                let near = bvh.leaves_in(o - r, o + r);
                let short = bvh.closest_hits(o, &[d], reach)[0];
                assert_eq!(bvh.occluded(o, &[d], reach) == 1, short.is_some());
                assert_eq!(bvh.closest_hit_among(&near, o, d, reach), short);
                // Alone, the ray gets the same hit as in its packet.
                assert_eq!(bvh.closest_hits(o, &[d], f32::INFINITY)[0], want);
                // Within the hit's distance, the same hit; within less, none.
                if let Some((_, t)) = want.filter(|&(_, t)| t > 0.0) {
                    assert_eq!(bvh.closest_hits(o, &[d], t)[0], want);
                    assert_eq!(bvh.closest_hits(o, &[d], t * 0.999)[0], None);
                    assert_eq!(bvh.occluded(o, &[d], t), 1);
                    assert_eq!(bvh.occluded(o, &[d], t * 0.999), 0);
                }
                hits += usize::from(size == PACKET && want.is_some());
            }
        }
    }
    hits
}

#[test]
fn packets_find_the_brute_force_hit_in_a_triangle_soup() {
    // At the origin, and 10 km off it (where a float step is 1 mm: the boxes' growth by float
    // steps of their coordinates matters there).
    for offset in [Vec3::ZERO, Vec3::new(1e4, -1e4, 3e3)] {
        let mut rng = Rng(0x9e37_79b9);
        let tris = rng.soup(600, offset, 10.0, 3.0);
        let origins: Vec<Vec3> = (0..20).map(|_| offset + rng.vec(10.0)).collect();
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
}

/// PLOC in memory made ready beforehand ([`crate::accel::bvh::PlocMemory`]), too small, exact or too
/// large, builds the tree it builds in its own: the same nodes and primitive order, bit for bit.
/// (5,000 triangles stay below obvhs' parallel passes, from 4,000 to 500,000 primitives
/// depending on the pass; they size their work from the arrays' lengths, which obvhs sets,
/// never from their capacity.)
#[test]
fn ploc_in_memory_made_ready_builds_the_same_tree() {
    let mut rng = Rng(0x5eed_0001);
    let tris = rng.soup(5000, Vec3::ZERO, 50.0, 2.0);
    for params in [
        obvhs::BvhBuildParams::fast_build(),
        obvhs::BvhBuildParams::medium_build(),
    ] {
        let own = crate::accel::bvh::ploc(&tris, &params, None);
        for room in [0, 1000, tris.len(), 3 * tris.len()] {
            let memory = crate::accel::bvh::PlocMemory::faulted(room);
            let given = crate::accel::bvh::ploc(&tris, &params, Some(memory));
            let bytes = |b: &Bvh2| bytemuck::cast_slice::<_, u8>(&b.nodes).to_vec();
            assert_eq!(bytes(&given), bytes(&own), "room for {room}");
            assert_eq!(
                given.primitive_indices, own.primitive_indices,
                "room for {room}"
            );
        }
    }
}

/// Slivers (one vertex almost on the opposite edge) and rays grazing them.
#[test]
fn packets_find_the_brute_force_hit_on_slivers() {
    let mut rng = Rng(0x1234_5678);
    let tris: Vec<Triangle> = (0..300)
        .map(|_| {
            let (a, b) = (rng.vec(8.0), rng.vec(8.0));
            let on_edge = a.lerp(b, rng.next()) + rng.vec(1e-4);
            Triangle {
                v0: a.into(),
                v1: b.into(),
                v2: on_edge.into(),
            }
        })
        .collect();
    // Origins on the slivers' lines, rays along and across them.
    let origins: Vec<Vec3> = tris
        .iter()
        .take(10)
        .map(|t| Vec3::from(t.v0).lerp(Vec3::from(t.v1), 0.5))
        .collect();
    let dirs: Vec<Vec3> = prt_format::directions::fibonacci_directions(301)
        .into_iter()
        .map(Vec3::from)
        .chain(
            tris.iter()
                .take(10)
                .map(|t| (Vec3::from(t.v1) - Vec3::from(t.v0)).normalize()),
        )
        .collect();
    let hits = check(&tris, &origins, &dirs);
    assert!(hits > 100, "{hits} hits");
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

/// [`Bvh8::visit`] compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn visit_avx(bvh: &Bvh8, node: &Node, p: &Packet, mask: RayMask, stack: &mut Vec<Entry>) {
    bvh.visit(node, p, mask, stack);
}

/// The box test compiled for AVX pushes the same entries, nearest distances bit for bit, as
/// the baseline copy, at every node, for packets with zero direction components (infinite
/// inverse directions replaced by `TINY`), origins on box planes, and finite `tmax`.
#[cfg(target_arch = "x86_64")]
#[test]
fn box_test_compiled_for_avx_gives_the_same_bits() {
    if !std::arch::is_x86_feature_detected!("avx") {
        eprintln!("this CPU has no AVX: only the baseline copy runs here");
        return;
    }
    let mut rng = Rng(0x0bad_cafe);
    let tris = rng.soup(500, Vec3::ZERO, 10.0, 2.0);
    let bvh = build(&tris, false);
    let mut dirs: Vec<Vec3> = prt_format::directions::fibonacci_directions(256)
        .into_iter()
        .map(Vec3::from)
        .collect();
    for a in 0..3 {
        for s in [-1.0, 1.0, -0.0] {
            let mut d = Vec3::splat(0.0);
            d[a] = s;
            dirs.push(d);
        }
    }
    let entries = |stack: &[Entry]| -> Vec<(u32, u8, RayMask, u32)> {
        stack
            .iter()
            .map(|e| (e.index, e.count, e.mask, e.near.to_bits()))
            .collect()
    };
    let mut compared = 0;
    for (n, node) in bvh.nodes.iter().enumerate() {
        let corner = Vec3::new(node.min[0][0], node.min[1][0], node.min[2][0]);
        for origin in [rng.vec(10.0), corner] {
            for (packet, tmax) in dirs
                .chunks(PACKET)
                .zip([f32::INFINITY, 3.0, 0.5].iter().cycle())
            {
                let p = Packet::new(origin, packet, *tmax);
                let mask = RayMask::MAX >> (RayMask::BITS as usize - packet.len());
                let (mut base, mut avx) = (Vec::new(), Vec::new());
                bvh.visit(node, &p, mask, &mut base);
                // SAFETY: the CPU has AVX (checked above).
                unsafe { visit_avx(&bvh, node, &p, mask, &mut avx) };
                assert_eq!(entries(&base), entries(&avx), "node {n}, origin {origin}");
                compared += base.len();
            }
        }
    }
    assert!(
        compared > 1000,
        "{compared} entries: the test needs entries"
    );
}
