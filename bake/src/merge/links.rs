//! Which neighbouring bricks of one normal key see each other: where a zero-thickness wall
//! stands between two bricks of the floor, ceiling or wall that runs on under it, the segment
//! between them is blocked. [`crate::merge::coarse`] makes a coarse brick per connected part of
//! a coarse cell, which the far rows of a probe on one side read instead of the whole cell's
//! fit over both rooms.

use glam::Vec3;
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::merge::fold::BrickFit;
use crate::merge::key::Key;

/// Neighbouring bricks that see each other ([`links`]) and the bricks' bounds, by which
/// [`crate::merge::coarse::build`] splits coarse cells into parts. Empty: no cell is split.
#[derive(Clone, Debug, Default)]
pub struct Links {
    /// Linked bricks, `(a, b)` with `a < b`, sorted ([`links`]).
    pub pairs: Vec<(u32, u32)>,
    /// Per brick, the bounds of its surfels.
    pub bounds: Vec<[Vec3; 2]>,
    /// How far outside a part's bounds a row's mean hit point may lie and still read the part
    /// (hits lie within their surfel cells, a little beyond their surfels).
    pub margin: f32,
}

/// Offsets to the 13 neighbouring cells after a cell (the other 13 link back to it).
fn forward_neighbours() -> impl Iterator<Item = [i32; 3]> {
    (0..27)
        .map(|i| [i % 3 - 1, i / 3 % 3 - 1, i / 9 - 1])
        .filter(|d| (d[2], d[1], d[0]) > (0, 0, 0))
}

/// Pairs `(a, b)`, `a < b`, of bricks of one normal key in neighbouring cells (at most one
/// apart on every axis) that see each other: the segment between their centroids, each moved
/// `lift` off its surface along its key's axis, hits no triangle. Sorted, so the same at any
/// thread count. `lift` is a share of the brick lattice (the bake passes one brick size, four
/// cells: a lift of a quarter of a cell split the cells of Sponza's columns, whose centroids
/// lie inside them), so the test is the same at every scene scale.
pub fn links(keys: &[Key], fits: &[BrickFit], lift: f32, bvh: &SceneBvh) -> Vec<(u32, u32)> {
    use std::collections::HashMap;
    // The parts of a split fine brick share its key and are consecutive
    // (`crate::merge::split`): a key names its first brick and how many there are.
    let mut index: HashMap<Key, (u32, u32)> = HashMap::with_capacity(keys.len());
    for (b, &k) in keys.iter().enumerate() {
        index.entry(k).or_insert((b as u32, 0)).1 += 1;
    }
    let lifted = |b: u32| {
        let axis = keys[b as usize].3 & prt_format::BRICK_AXIS_MASK;
        let mut up = Vec3::ZERO;
        up[(axis / 2) as usize] = if axis.is_multiple_of(2) { 1.0 } else { -1.0 };
        fits[b as usize].centroid.as_vec3() + lift * up
    };
    let mut pairs: Vec<(u32, u32)> = (0..keys.len() as u32)
        .into_par_iter()
        .flat_map_iter(|a| {
            let k = keys[a as usize];
            let others: Vec<u32> = forward_neighbours()
                .filter_map(|d| {
                    let at = (
                        k.0.checked_add(d[0])?,
                        k.1.checked_add(d[1])?,
                        k.2.checked_add(d[2])?,
                        k.3,
                    );
                    index.get(&at).copied()
                })
                .flat_map(|(first, n)| first..first + n)
                .collect();
            let from = lifted(a);
            let dirs: Vec<Vec3> = others.iter().map(|&b| lifted(b) - from).collect();
            let seen: Vec<(u32, u32)> = (others.chunks(PACKET).zip(dirs.chunks(PACKET)))
                .flat_map(|(others, dirs)| {
                    let blocked = bvh.occluded(from, dirs, 1.0);
                    (others.iter().enumerate())
                        .filter(|&(j, _)| blocked >> j & 1 == 0)
                        .map(|(_, &b)| (a.min(b), a.max(b)))
                        .collect::<Vec<_>>()
                })
                .collect();
            seen.into_iter()
        })
        .collect();
    pairs.par_sort_unstable();
    pairs
}
