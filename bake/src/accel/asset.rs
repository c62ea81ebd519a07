//! The binary BVH the asset carries: obvhs' tree renumbered breadth first, small subtrees
//! collapsed into leaves, triangles in leaf order and back in world units, so that the runtime
//! (CPU reference and WGSL alike) traces shadow rays with a plain stack traversal.

use std::collections::VecDeque;

use glam::Vec3;
use obvhs::bvh2::Bvh2;
use prt_format::{BvhNode, Geometry};

use crate::accel::leaf_order::LeafOrder;
use crate::memory::prefetch_lines;

/// Most triangles in a leaf of the asset's BVH: subtrees of at most this many become one leaf.
/// PLOC leaves hold one triangle each, so without collapsing the node array outgrew the
/// triangles themselves; leaves of four shrink it to under half their size and leave the
/// runtime's shadow rays as fast.
pub const LEAF_TRIANGLES: u32 = 4;

/// How far ahead in its queue [`flatten`] asks for the node it will read: the queue of a
/// breadth-first walk says which nodes come next, so their cache misses can overlap.
const PREFETCH_AHEAD: usize = 8;

/// Renumbers the BVH2 breadth first (children pairs consecutive and after their parent),
/// collapses subtrees of at most [`LEAF_TRIANGLES`] triangles into one leaf, and lays the
/// triangles out in leaf order, back in world units (boxes times `unscale`, exact for a power of
/// two).
pub(crate) fn flatten(
    bvh2: &Bvh2,
    order: &LeafOrder,
    triangles: &[[Vec3; 3]],
    unscale: f32,
) -> Geometry {
    let mut nodes: Vec<BvhNode> = Vec::with_capacity(bvh2.nodes.len());
    let mut tris = Vec::with_capacity(triangles.len());
    let mut queue = VecDeque::from([0usize]);
    while let Some(src) = queue.pop_front() {
        if let Some(&ahead) = queue.get(PREFETCH_AHEAD) {
            prefetch_lines(bytemuck::bytes_of(&bvh2.nodes[ahead]));
        }
        let n = &bvh2.nodes[src];
        let aabb = n.aabb();
        let mut out = BvhNode {
            min: (aabb.min * unscale).to_array(),
            max: (aabb.max * unscale).to_array(),
            count: 0,
            first: 0,
        };
        if n.is_leaf() || order.below[src] <= LEAF_TRIANGLES {
            out.first = tris.len() as u32;
            tris.extend(order.under(src).iter().map(|&p| {
                let t = triangles[p as usize];
                prt_format::Triangle {
                    v0: t[0].to_array(),
                    v1: t[1].to_array(),
                    v2: t[2].to_array(),
                    ..Default::default()
                }
            }));
            out.count = tris.len() as u32 - out.first;
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
