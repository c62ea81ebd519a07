//! The binary BVH's triangles in leaf order, which both collapses (the wide BVH and the
//! asset's) read a leaf's triangles from.

use obvhs::bvh2::Bvh2;

use crate::memory::prefetch_lines;

/// The binary BVH's triangles in leaf order, left subtree before right, from one walk over it:
/// every subtree's triangles are then a run of them ([`LeafOrder::under`]), so the two
/// collapses read a leaf's triangles from one run instead of walking its subtree again. The
/// reinsertion optimiser leaves no order between parents and children in the node array, so
/// a walk over it is about a cache miss a node, and one walk is cheaper than three.
pub(crate) struct LeafOrder {
    /// Per node reachable from the root: the triangles under it.
    pub below: Vec<u32>,
    /// Per node reachable from the root: where its run starts in `triangles`.
    first: Vec<u32>,
    /// Triangle indices (the scene's), leaf after leaf.
    triangles: Vec<u32>,
}

impl LeafOrder {
    pub(crate) fn of(bvh2: &Bvh2) -> LeafOrder {
        let mut order = LeafOrder {
            below: vec![0; bvh2.nodes.len()],
            first: vec![0; bvh2.nodes.len()],
            triangles: Vec::with_capacity(bvh2.primitive_indices.len()),
        };
        let mut stack = vec![(0usize, false)];
        while let Some((i, children_done)) = stack.pop() {
            let n = &bvh2.nodes[i];
            if children_done {
                let l = n.first_index as usize;
                order.below[i] = order.below[l].saturating_add(order.below[l + 1]);
            } else if n.is_leaf() {
                order.first[i] = order.triangles.len() as u32;
                order.below[i] = n.prim_count;
                let prims = n.first_index as usize..(n.first_index + n.prim_count) as usize;
                order
                    .triangles
                    .extend_from_slice(&bvh2.primitive_indices[prims]);
            } else {
                order.first[i] = order.triangles.len() as u32;
                // The grandchildren asked for now: the walk reaches the left ones next and the
                // right ones later, and each read of a node waits for the one before.
                let l = n.first_index as usize;
                for c in [l, l + 1] {
                    if !bvh2.nodes[c].is_leaf() {
                        prefetch_children(bvh2, c);
                    }
                }
                stack.push((i, true));
                // Right pushed first, so the left subtree's triangles come first.
                stack.push((l + 1, false));
                stack.push((l, false));
            }
        }
        order
    }

    /// The triangles under `node`, in leaf order.
    pub(crate) fn under(&self, node: usize) -> &[u32] {
        let first = self.first[node] as usize;
        &self.triangles[first..first + self.below[node] as usize]
    }
}

/// Asks for inner node `i`'s two children: every cache line of the pair (64 bytes from a 16-byte
/// boundary with obvhs' `small_bvh2_node`: one or two lines, so its first and last bytes; 96 bytes
/// without it, hence also the 64th). The reinsertion optimiser leaves the node array in no order a
/// walk could stream, so each walk over the binary tree ([`LeafOrder::of`],
/// [`crate::accel::asset::flatten`], the wide BVH's collapse) would wait for a miss a node; the
/// children of the nodes in sight, asked for ahead, arrive while the walk works. Every line, not
/// only a child's first: a pair that straddles two lines otherwise still waits for the second.
pub(crate) fn prefetch_children(bvh2: &Bvh2, i: usize) {
    let first = bvh2.nodes[i].first_index as usize;
    if let Some(pair) = bvh2.nodes.get(first..first + 2) {
        prefetch_lines(bytemuck::cast_slice(pair));
    }
}
