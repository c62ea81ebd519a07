//! Fine bricks split where their surfels do not see each other.
//!
//! A brick is one linear radiance fit over the surfels of one normal key in 4x4x4 cells
//! ([`crate::merge::fold`]). Where a zero-thickness wall stands on a floor, or meets another
//! wall, the surface that runs on under it puts both rooms' surfels in one brick, and the fit
//! carries the lit side's light to the dark side: on `interior_32` (a room lit only through a
//! door) a path tracer that reads the bricks' fits at its hits measured 21.9% against 10.9% when
//! it read each hit's nearest surfel (`prt-bench surface --lookup path`, stop 50). A cell that
//! straddles the wall holds a surfel of hits from both sides, whose mean may lie on the lit
//! side; the fit then spreads that surfel's light over the whole brick.
//!
//! So each brick's surfels are linked when the segment between them, each lifted a cell along
//! its own normal ([`LIFT_CELLS`]), hits nothing (the test of [`crate::merge::links`], one
//! level down), and a brick whose links leave several parts becomes a brick per part, largest
//! first, each with its own fit. The parts keep the brick's key, one after another (format
//! 13): the surface lookup's table names the first, whose cells may name any part's surfels
//! (`crate::surface_terms`, `prt_format::surface_key_runs`), and a factor row
//! reads the part nearest its hits' mean ([`FineParts::part_after`]).

use glam::Vec3;
use prt_format::{Brick, Surfel, BRICK_BACKFACE};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::memory::split_runs;
use crate::merge::fold::{brick_of, BrickFit, Bricked};
use crate::merge::key::Key;

/// How far off its surface a surfel's end of a link is lifted, in surfel cells: far enough
/// that a link along a flat surface does not graze it, and that the small relief of a detailed
/// surface does not split it. Sponza (sun and two lights, default spacing): half a cell split
/// 8,818 bricks and measured 15.93% with 6 leaking points, one cell 7,977 and 15.81% with 5
/// (as before splitting), two cells 7,668 and 15.81%; interior_32, cave_31 and interior_4 the
/// same at all three (`prt-bench surface --lookup default`, stop 50).
pub const LIFT_CELLS: f32 = 1.0;

/// Where the bricks of a bake went when they were split ([`split`]): the parts of brick `b`
/// (numbered before the split) are the bricks `first[b]..first[b + 1]` after it. Empty when
/// nothing was split: every brick is itself.
#[derive(Clone, Debug, Default)]
pub struct FineParts {
    first: Vec<u32>,
    /// Per brick after the split: how many parts start at it (1 for a brick not split, 0
    /// for a part after the first).
    span: Vec<u32>,
}

impl FineParts {
    /// How many bricks were split, and into how many parts in all.
    pub fn split_count(&self) -> (usize, usize) {
        (self.span.iter().filter(|&&n| n > 1)).fold((0, 0), |(bricks, parts), &n| {
            (bricks + 1, parts + n as usize)
        })
    }

    /// The bricks after the split that brick `brick` (numbered before it) became.
    pub fn parts(&self, brick: u32) -> std::ops::Range<u32> {
        match self.first.get(brick as usize + 1) {
            Some(&end) => self.first[brick as usize]..end,
            None => brick..brick + 1,
        }
    }

    /// Whether brick `first` (numbered after the split) is the first of several parts.
    #[inline]
    pub fn is_split(&self, first: u32) -> bool {
        self.span.get(first as usize).is_some_and(|&n| n > 1)
    }

    /// Of the parts from `first` on (numbered after the split; `bricks` after it), the one
    /// nearest `mean` by [`part_distance`]: mostly the one whose bounds hold it (a row of hits
    /// of one side lies in that side's part), the centroids deciding among parts whose bounds
    /// hold it.
    #[inline]
    pub fn part_after(&self, first: u32, mean: Vec3, bricks: &[Brick]) -> u32 {
        let n = self.span.get(first as usize).copied().unwrap_or(1).max(1);
        let d = |p: u32| part_distance(&bricks[p as usize], mean);
        (first..first + n)
            .min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b)))
            .unwrap_or(first)
    }
}

/// How far `mean` lies from a part: the squared distance to its surfels' bounds plus a hundredth of the squared distance to its centroid. Continuous
/// in `mean`, so that a row's part does not hang on a discrete tie: ranking by the bounds
/// alone, then by the parts' order (their weights), made the surfels that merge differently at
/// another scene scale move rows between parts (`tests/tests/scale.rs`: Sponza 7.4e-3 of the
/// mean SH0 at x0.001, against at most 2e-3).
fn part_distance(part: &Brick, mean: Vec3) -> f32 {
    let (lo, hi, centroid) = (part.min.into(), part.max.into(), Vec3::from(part.centroid));
    mean.clamp(lo, hi).distance_squared(mean) + 1e-2 * centroid.distance_squared(mean)
}

/// `bricked` with every front-face brick whose surfels the links leave in several parts made a
/// brick per part (largest weight first, then in surfel order), each with its own fit and its
/// surfels consecutive, and where each brick went. `cell_size` is the surfel cell's edge;
/// nothing is split when it is 0 (merging off).
pub fn split(bricked: Bricked, cell_size: f32, bvh: &SceneBvh) -> (Bricked, FineParts) {
    if cell_size <= 0.0 {
        return (bricked, FineParts::default());
    }
    let Bricked {
        bricks,
        mut surfels,
        keys,
        fits,
    } = bricked;
    let lift = LIFT_CELLS * cell_size;
    let labels: Vec<Vec<u32>> = bricks
        .par_iter()
        .map(|b| {
            let run = &surfels[b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize];
            match b.flags & BRICK_BACKFACE == 0 && run.len() > 1 {
                true => labels(run, lift, bvh),
                false => Vec::new(),
            }
        })
        .collect();
    let counts: Vec<u32> = labels
        .iter()
        .map(|l| l.iter().max().map_or(1, |&m| m + 1))
        .collect();
    let mut first = Vec::with_capacity(bricks.len() + 1);
    first.push(0u32);
    for &c in &counts {
        first.push(first[first.len() - 1] + c);
    }
    if first[bricks.len()] as usize == bricks.len() {
        let bricked = Bricked {
            bricks,
            surfels,
            keys,
            fits,
        };
        return (bricked, FineParts::default());
    }
    let sizes: Vec<usize> = bricks.iter().map(|b| b.surfel_count as usize).collect();
    let runs = split_runs(&mut surfels, &sizes);
    let made: Vec<Vec<(Brick, BrickFit)>> = (bricks.par_iter().zip(fits).zip(runs))
        .zip(&labels)
        .enumerate()
        .map(
            |(b, (((brick, fit), (_, run)), labels))| match labels.is_empty() {
                true => {
                    for s in run.iter_mut() {
                        s.brick = first[b];
                    }
                    vec![(*brick, fit)]
                }
                false => parts_of(run, labels, (brick, first[b])),
            },
        )
        .collect();
    assemble(made, keys, first, surfels)
}

/// The bricks `made` per brick before the split (with its key), in order, and where each
/// brick went (`first`: where its parts start).
fn assemble(
    made: Vec<Vec<(Brick, BrickFit)>>,
    keys: Vec<Key>,
    first: Vec<u32>,
    surfels: Vec<Surfel>,
) -> (Bricked, FineParts) {
    let count = first[first.len() - 1] as usize;
    let (mut bricks, mut fits, mut new_keys) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for (made, key) in made.into_iter().zip(keys) {
        for (brick, fit) in made {
            bricks.push(brick);
            fits.push(fit);
            new_keys.push(key);
        }
    }
    let mut span = vec![0u32; count];
    for w in first.windows(2) {
        span[w[0] as usize] = w[1] - w[0];
    }
    let bricked = Bricked {
        bricks,
        surfels,
        keys: new_keys,
        fits,
    };
    let parts = FineParts { first, span };
    (bricked, parts)
}

/// Per surfel of `run` (one brick's), its part: parts numbered largest weight first (ties
/// in order of their first surfel). Empty when the brick is one part.
fn labels(run: &[Surfel], lift: f32, bvh: &SceneBvh) -> Vec<u32> {
    let lifted: Vec<Vec3> = run
        .iter()
        .map(|s| Vec3::from(s.position) + lift * Vec3::from(s.normal))
        .collect();
    let mut parent: Vec<u32> = (0..run.len() as u32).collect();
    for i in 0..run.len() {
        let others: Vec<usize> = (i + 1..run.len())
            .filter(|&j| root(&mut parent, i as u32) != root(&mut parent, j as u32))
            .collect();
        for chunk in others.chunks(PACKET) {
            let dirs: Vec<Vec3> = chunk.iter().map(|&j| lifted[j] - lifted[i]).collect();
            let blocked = bvh.occluded(lifted[i], &dirs, 1.0);
            for (n, &j) in chunk.iter().enumerate() {
                if blocked >> n & 1 == 0 {
                    let (a, b) = (root(&mut parent, i as u32), root(&mut parent, j as u32));
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
    }
    let roots: Vec<u32> = (0..run.len() as u32)
        .map(|i| root(&mut parent, i))
        .collect();
    let mut weights: Vec<(u32, f32)> = Vec::new();
    for (i, &r) in roots.iter().enumerate() {
        match weights.iter_mut().find(|(root, _)| *root == r) {
            Some((_, w)) => *w += run[i].weight,
            None => weights.push((r, run[i].weight)),
        }
    }
    if weights.len() <= 1 {
        return Vec::new();
    }
    // Largest first; a root is its part's first surfel, so ties keep surfel order.
    weights.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    roots
        .iter()
        .map(|r| weights.iter().position(|(root, _)| root == r).unwrap_or(0) as u32)
        .collect()
}

/// The union-find root of `i`, halving the path on the way.
fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Brick `brick`'s surfels `run` reordered part by part (`labels`), each part a brick of its
/// own from `first` on, fitted anew.
fn parts_of(
    run: &mut [Surfel],
    labels: &[u32],
    (brick, first): (&Brick, u32),
) -> Vec<(Brick, BrickFit)> {
    let mut order: Vec<usize> = (0..run.len()).collect();
    order.sort_by_key(|&i| (labels[i], i));
    let sorted: Vec<Surfel> = order.iter().map(|&i| run[i]).collect();
    run.copy_from_slice(&sorted);
    let mut out = Vec::new();
    let mut at = 0usize;
    let parts = labels.iter().max().map_or(1, |&m| m + 1);
    for p in 0..parts {
        let n = labels.iter().filter(|&&l| l == p).count();
        let sub = &mut run[at..at + n];
        let index = first + p;
        for s in sub.iter_mut() {
            s.brick = index;
            s.gradient = [0.0; 3];
        }
        out.push(brick_of(sub, brick.flags, brick.first_surfel + at as u32));
        at += n;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One floor brick (+Y) of 4x4 surfels of 0.25 m cells over x, z in [0, 1], and with
    /// `wall` a zero-thickness wall across it at x = 0.8 (surfels at x = 0.125 + 0.25 i).
    fn floor(wall: bool) -> (Bricked, SceneBvh) {
        let mut surfels: Vec<Surfel> = (0..16)
            .map(|i| Surfel {
                position: [
                    0.125 + 0.25 * (i % 4) as f32,
                    0.0,
                    0.125 + 0.25 * (i / 4) as f32,
                ],
                normal: [0.0, 1.0, 0.0],
                // The lit side's column weighs less: the dark side is the first part.
                weight: if i % 4 >= 3 { 1.0 } else { 2.0 },
                ..Surfel::default()
            })
            .collect();
        let (brick, fit) = brick_of(&mut surfels, 2, 0);
        let bricked = Bricked {
            bricks: vec![brick],
            surfels,
            keys: vec![(0, 0, 0, 2)],
            fits: vec![fit],
        };
        let triangles = match wall {
            true => vec![
                [
                    Vec3::new(0.8, -1.0, -1.0),
                    Vec3::new(0.8, 2.0, -1.0),
                    Vec3::new(0.8, 2.0, 2.0),
                ],
                [
                    Vec3::new(0.8, -1.0, -1.0),
                    Vec3::new(0.8, 2.0, 2.0),
                    Vec3::new(0.8, -1.0, 2.0),
                ],
            ],
            // A far-away triangle: the BVH needs one.
            false => vec![[
                Vec3::splat(50.0),
                Vec3::new(51.0, 50.0, 50.0),
                Vec3::new(50.0, 51.0, 50.0),
            ]],
        };
        (bricked, SceneBvh::build(&triangles, 1.0))
    }

    #[test]
    fn a_brick_is_split_where_a_wall_stands_on_it() {
        let (bricked, bvh) = floor(true);
        let (split, parts) = split(bricked, 0.25, &bvh);
        assert_eq!(split.bricks.len(), 2);
        assert_eq!(parts.parts(0), 0..2);
        assert_eq!(parts.split_count(), (1, 2));
        // The larger part (x < 0.8: three columns) first, each fitted alone.
        let [a, b] = [&split.bricks[0], &split.bricks[1]];
        assert_eq!((a.first_surfel, a.surfel_count), (0, 12));
        assert_eq!((b.first_surfel, b.surfel_count), (12, 4));
        assert!(a.max[0] < 0.8 && b.min[0] > 0.8);
        assert_eq!(split.keys, vec![(0, 0, 0, 2); 2]);
        for (i, s) in split.surfels.iter().enumerate() {
            assert_eq!(s.brick, u32::from(i >= 12), "surfel {i}");
        }
        // A part's gradient weights fit its own surfels: they sum to zero about its centroid
        // and reproduce a linear ramp's slope along x.
        for brick in &split.bricks {
            let run = &split.surfels[brick.first_surfel as usize..][..brick.surfel_count as usize];
            let slope: f32 = run.iter().map(|s| s.gradient[0] * s.position[0]).sum();
            let sum: f32 = run.iter().map(|s| s.gradient[0]).sum();
            assert!(sum.abs() < 1e-4, "{sum}");
            if brick.max[0] > brick.min[0] {
                assert!((slope - 1.0).abs() < 1e-2, "{slope}");
            }
        }
        // Rows read the part their hits lie in.
        assert!(parts.is_split(0));
        let part = |x: f32| parts.part_after(0, Vec3::new(x, 0.0, 0.5), &split.bricks);
        assert_eq!(part(0.3), 0);
        assert_eq!(part(0.9), 1);
    }

    #[test]
    fn a_brick_without_a_wall_is_left_as_it_is() {
        let (bricked, bvh) = floor(false);
        let before = (bricked.bricks.clone(), bricked.surfels.clone());
        let (split, parts) = split(bricked, 0.25, &bvh);
        assert_eq!(split.bricks, before.0);
        assert_eq!(split.surfels, before.1);
        assert_eq!(parts.parts(0), 0..1);
        assert!(!parts.is_split(0));
        assert_eq!(parts.split_count(), (0, 0));
    }
}
