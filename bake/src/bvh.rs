//! Acceleration structures over the scene's triangles, both from one obvhs PLOC build
//! (Meister & Bittner, "Parallel Locally-Ordered Clustering for Bounding Volume Hierarchy
//! Construction", 2018, with parallel reinsertion):
//!
//! - a compressed wide BVH8 (Ylitie et al., HPG 2017) that the bake traces its probe rays with;
//! - the binary BVH it was made from, flattened with children after parents and triangles in
//!   leaf order, which the asset carries so that the runtime (CPU reference and WGSL alike) can
//!   trace shadow rays with a plain stack traversal.

use std::collections::VecDeque;

use glam::Vec3;
use obvhs::{
    bvh2::{reinsertion::ReinsertionOptimizer, Bvh2},
    cwbvh::{bvh2_to_cwbvh::bvh2_to_cwbvh, CwBvh},
    ploc::PlocBuilder,
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
    BvhBuildParams,
};
use prt_format::{BvhNode, Geometry};

/// The scene's BVHs.
pub struct SceneBvh {
    cwbvh: CwBvh,
    /// Triangles in CWBVH primitive order, for intersection.
    rt_triangles: Vec<RtTriangle>,
    /// Asset geometry: flattened BVH2 and its triangles.
    pub geometry: Geometry,
}

/// A closest hit: original triangle index and distance.
#[derive(Clone, Copy, Debug)]
pub struct TriangleHit {
    pub triangle: u32,
    pub t: f32,
}

impl SceneBvh {
    /// Builds both BVHs (in parallel on the current rayon pool).
    pub fn build(triangles: &[[Vec3; 3]]) -> SceneBvh {
        if triangles.is_empty() {
            return SceneBvh {
                cwbvh: CwBvh::default(),
                rt_triangles: Vec::new(),
                geometry: Geometry::default(),
            };
        }
        let tris: Vec<Triangle> = triangles
            .iter()
            .map(|t| Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        let params = BvhBuildParams::medium_build();
        let mut bvh2 = PlocBuilder::with_capacity(tris.len()).build(
            params.ploc_search_distance,
            &tris,
            (0..tris.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
        let cwbvh = bvh2_to_cwbvh(&bvh2, params.max_prims_per_leaf.clamp(1, 3), true, false);
        let rt_triangles = cwbvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        let geometry = flatten(&bvh2, triangles);
        SceneBvh {
            cwbvh,
            rt_triangles,
            geometry,
        }
    }

    /// Closest hit along `origin + t dir`, `t` in `(0, inf)`.
    #[inline]
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3) -> Option<TriangleHit> {
        if self.rt_triangles.is_empty() {
            return None;
        }
        let ray = Ray::new_inf(origin.into(), dir.into());
        let mut hit = RayHit::none();
        if self
            .cwbvh
            .ray_traverse(ray, &mut hit, |r, id| self.rt_triangles[id].intersect(r))
        {
            Some(TriangleHit {
                triangle: self.cwbvh.primitive_indices[hit.primitive_id as usize],
                t: hit.t,
            })
        } else {
            None
        }
    }
}

/// Renumbers the BVH2 breadth first (children pairs consecutive and after their parent) and
/// lays the triangles out in leaf order.
fn flatten(bvh2: &Bvh2, triangles: &[[Vec3; 3]]) -> Geometry {
    let mut nodes: Vec<BvhNode> = Vec::with_capacity(bvh2.nodes.len());
    let mut tris = Vec::with_capacity(triangles.len());
    let mut queue = VecDeque::from([0usize]);
    while let Some(src) = queue.pop_front() {
        let n = &bvh2.nodes[src];
        let aabb = n.aabb();
        let mut out = BvhNode {
            min: aabb.min.to_array(),
            max: aabb.max.to_array(),
            count: 0,
            first: 0,
        };
        if n.is_leaf() {
            out.first = tris.len() as u32;
            out.count = n.prim_count;
            for p in n.first_index..n.first_index + n.prim_count {
                let t = triangles[bvh2.primitive_indices[p as usize] as usize];
                tris.push(prt_format::Triangle {
                    v0: t[0].to_array(),
                    v1: t[1].to_array(),
                    v2: t[2].to_array(),
                    ..Default::default()
                });
            }
        } else {
            // Children land at the next two free slots, in queue order.
            out.first = (nodes.len() + queue.len() + 1) as u32;
            queue.push_back(n.first_index as usize);
            queue.push_back(n.first_index as usize + 1);
        }
        nodes.push(out);
    }
    Geometry {
        nodes,
        triangles: tris,
    }
}
