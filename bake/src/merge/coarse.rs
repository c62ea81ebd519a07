//! Coarse bricks for far hits ([`prt_format::coarse`] says what they are and why).
//!
//! While tracing, each hit is given a level by its distance from its probe ([`FarField`]):
//! level 0 (its own brick) within `far_ratio` brick sizes, then one level more each time the
//! distance doubles up to [`FAR_LEVELS`], so that a level's brick is at most `2 / far_ratio`
//! radians wide where it is used. A probe's hits of one level and one coarse cell (and one
//! normal key) make one factor row, which reads the lowest level whose cell holds all its
//! hits (`tables::factors::probe_rows`). Once every brick is known, [`build`] makes the coarse
//! bricks: per level, the bricks of each coarse cell, unless that is a single brick (the brick
//! itself is used) or the same bricks as the level below (the finer coarse brick is used).
//! [`CoarsePlacement`] then says which brick or coarse brick a row of a given level reads.
//!
//! **A coarse brick is not read across a wall.** A floor, ceiling or wall that runs on under a
//! zero-thickness partition gives bricks of one normal key on both sides of it, and a coarse
//! cell over both was one linear fit of a lit room's floor and a dark room's: the dark room's
//! probes that saw their own floor far away read the lit side's light through it (stop 49: on
//! a generated level nobody had seen, `interior_28`, the dark room's probes beside such a wall
//! came out 1.07x (median) to 2.7x brighter than a bake without coarse bricks). So
//! [`crate::merge::links`] finds which neighbouring bricks see each other, and where that
//! splits a used cell into parts, each part gets its coarse brick too. A factor row names its
//! first hit's brick; it reads that brick's part when the mean of its hits lies in the part's
//! bounds (a probe on one side of a wall sees only that side), else the whole cell, as before:
//! parts split where no wall stands (round a column, whose bricks' lifted centroids the column
//! hides from each other), and rows that span them read the whole. A door joins two rooms'
//! parts, as it lets light through.

use glam::{DMat3, DVec3, Vec3};
use prt_format::coarse::{BrickMoments, CoarseBrick, CoarseBricks, MAX_LEVEL};
use rayon::prelude::*;

use crate::merge::fold::{regularised, BrickFit};
use crate::merge::key::{brick_key, Key};
use crate::merge::links::Links;
use crate::trace::Hit;

/// Where a probe's hits go by their distance from it.
#[derive(Clone, Copy, Debug)]
pub struct FarField {
    /// The probe's ray origin.
    pub origin: Vec3,
    /// The brick lattice's corner and brick size ([`crate::merge::fold::BrickFolder`]).
    pub anchor: Vec3,
    pub brick_size: f32,
    /// Distance from which hits go to level 1 (`far_ratio` brick sizes); 0: never.
    pub near: f32,
}

/// Levels are kept as bits 1..=7 of a byte per brick (`stream::Traced::far_levels`).
const _: () = assert!(MAX_LEVEL <= 7);

/// The coarsest level a far hit goes to: cells of at most 8 bricks a side (four probe
/// spacings at the default cells of an eighth of the spacing). Past it, distance no longer
/// coarsens the cells, so a probe's rays that travel more than 40 brick sizes (at the default
/// ratio of 5) make more rows than the angular rule alone would.
///
/// Why a cap (stop 53): a level-5 cell of an interior is half a room's floor, and one linear
/// fit over a light pool and the dark floor around it carried the pool's light into probes
/// that saw only the dark part. On levels no one had tuned on (`prt-bench surface`), levels
/// up to [`MAX_LEVEL`] against up to 3 (both with rows at their hits' smallest cell):
/// interior_52 23.3% -> 16.0% open mean (15.3% with no coarse bricks at all), interior_60 at
/// half the spacing 7.9% -> 5.0%; on the tuning seeds, the bundled scenes and Sponza the same
/// figures and runtime bytes at the default spacing, and at half of it Cornell 2.26% -> 1.58%
/// for 11% more bytes. A cap of 4 changed nothing; 2 cost 2-12% more bytes at the default
/// spacing (`docs/results/coarse.md`).
pub const FAR_LEVELS: u32 = 3;
const _: () = assert!(FAR_LEVELS <= MAX_LEVEL);

impl FarField {
    /// Where a bake with `far_ratio` sends far hits over the fold's brick lattice
    /// ([`crate::merge::fold::BrickFolder::lattice`]; origin left for each probe): nowhere
    /// without merging (every hit its own brick) or with a ratio of 0.
    pub fn of(far_ratio: f32, (anchor, brick_size): (Vec3, f32)) -> FarField {
        FarField {
            origin: Vec3::ZERO,
            anchor,
            brick_size,
            near: match brick_size > 0.0 {
                true => far_ratio * brick_size,
                false => 0.0,
            },
        }
    }

    /// Whether any hit can go to a coarse brick.
    pub fn is_on(&self) -> bool {
        self.near > 0.0
    }

    /// No coarse levels: every hit is a level-0 hit.
    #[cfg(test)]
    pub fn off() -> FarField {
        FarField {
            origin: Vec3::ZERO,
            anchor: Vec3::ZERO,
            brick_size: 0.0,
            near: 0.0,
        }
    }

    /// The level of a hit at `position`: 0 nearer than `near`, else `l` for distances in
    /// `near * [2^(l-1), 2^l)`, at most [`FAR_LEVELS`]. By comparisons with exact powers of
    /// two of `near`, not a logarithm, so that the level is the same on every platform.
    #[inline]
    pub fn level(&self, position: Vec3) -> u32 {
        // Every hit of every default bake comes here: no distance when nothing is far.
        match self.is_on() {
            true => self.level_at((position - self.origin).length()),
            false => 0,
        }
    }

    /// The level of a hit `d` from its probe ([`FarField::level`]).
    #[inline]
    pub fn level_at(&self, d: f32) -> u32 {
        // Also 0 for a NaN `near` (the settings refuse one).
        if self.near.is_nan() || self.near <= 0.0 {
            return 0;
        }
        let mut level = 0;
        let mut bound = self.near;
        while level < FAR_LEVELS && d >= bound {
            level += 1;
            bound *= 2.0;
        }
        level
    }

    /// The coarse cell of `hit` at `level`: its brick's key (the fold's arithmetic), its cell
    /// divided by `2^level`.
    #[inline]
    pub fn key(&self, hit: &Hit, level: u32) -> Key {
        cell(brick_key(hit, self.anchor, self.brick_size), level)
    }
}

/// The level-`level` coarse cell that holds the brick of key `key`: its cell divided by
/// `2^level` (an arithmetic shift, so that cells tile negative coordinates too), the same
/// normal key.
#[inline]
pub fn cell(key: Key, level: u32) -> Key {
    (key.0 >> level, key.1 >> level, key.2 >> level, key.3)
}

/// Which brick or coarse brick a factor row of each level reads, per brick: `targets[l - 1][b]`
/// for brick `b`'s level-`l` cell (a brick index below the brick count, else the coarse
/// brick's index after them), `parts[l - 1][b]` for its part of that cell where the cell is
/// split ([`crate::merge::links`]); and where each coarse brick's offsets are measured from.
pub struct CoarsePlacement {
    targets: Vec<Vec<u32>>,
    /// Empty when the bake computed no links (no far rows).
    parts: Vec<Vec<u32>>,
    /// Per coarse brick: its centroid and `2^level`, the divisor of its factors' offsets.
    frames: Vec<(Vec3, f32)>,
    /// Per brick and coarse brick, the box a row's mean hit point must lie in to read it as a
    /// part ([`Links::bounds`] grown by [`Links::margin`]); empty when there are no links.
    boxes: Vec<[Vec3; 2]>,
    bricks: u32,
}

impl CoarsePlacement {
    /// Whether rows carry levels: some coarse level was made (never for unmerged bakes,
    /// whose rows' brick words use every bit).
    pub fn has_levels(&self) -> bool {
        !self.targets.is_empty()
    }

    /// What a level-`level` row of (final) brick `brick` whose hits' mean is `mean` reads, and
    /// the centroid and scale of its offsets, or `None` for the brick itself (level 0, or a
    /// level that has no coarse brick over it of more than itself). Where the cell is split,
    /// the row reads its brick's part when its mean lies in the part's box, as it does when
    /// its hits are all that part's (a probe on one side of a wall; a box is a heuristic: an
    /// L-shaped part's box can hold the mean of a row that spans parts), else it reads the
    /// whole cell, as before parts (a probe that sees round a column whose bricks no link
    /// joins).
    #[inline]
    pub fn place(&self, brick: u32, level: u32, mean: Vec3) -> Option<(u32, Vec3, f32)> {
        let l = level.checked_sub(1)? as usize;
        let whole = *self.targets.get(l)?.get(brick as usize)?;
        let part = self.parts.get(l).map_or(whole, |p| p[brick as usize]);
        let inside = |t: u32| {
            let [lo, hi] = self.boxes[t as usize];
            mean.cmpge(lo).all() && mean.cmple(hi).all()
        };
        let target = match part != whole && inside(part) {
            true => part,
            false => whole,
        };
        let (centroid, scale) = *self.frames.get(target.checked_sub(self.bricks)? as usize)?;
        Some((target, centroid, scale))
    }
}

/// The coarse bricks over `keys`' bricks (with their `fits`), and where each level's rows go;
/// `used[b]` has bit `l` set when a level-`l` row names brick `b`. Only those rows' coarse
/// bricks are made: the cells of the levels up to the highest used are grouped bottom-up (a
/// cell of the same bricks as the one below it is that one), then each used cell's group is
/// numbered, in order of level and cell. Nothing used (no far rows): no level is grouped.
/// Then, where `links` split a used cell, a coarse brick per used part (a part of one brick is
/// that brick).
pub fn build(
    keys: &[Key],
    fits: &[BrickFit],
    used: &[u8],
    links: &Links,
) -> (CoarseBricks, CoarsePlacement) {
    let n = keys.len() as u32;
    let all = used.iter().fold(0u8, |all, &bits| all | bits);
    let levels = (u8::BITS - all.leading_zeros())
        .saturating_sub(1)
        .min(MAX_LEVEL);
    let mut made = Made {
        coarse: CoarseBricks::default(),
        frames: Vec::new(),
        bricks: n,
    };
    let whole = Groups::of(keys, levels, None);
    let (targets, numbers) = made.number(&whole, used, fits, None);
    let split = !links.bounds.is_empty() && levels > 0;
    debug_assert!(
        !split || links.bounds.len() == keys.len(),
        "a box per brick"
    );
    let parts = match split {
        true => {
            let parts = Groups::of(keys, levels, Some(&links.pairs));
            made.number(&parts, used, fits, Some((&whole, &numbers))).0
        }
        false => Vec::new(),
    };
    let boxes = match split {
        true => made.boxes(links),
        false => Vec::new(),
    };
    let Made {
        mut coarse, frames, ..
    } = made;
    if !coarse.bricks.is_empty() {
        coarse.moments = fits.iter().map(moments).collect();
    }
    let placement = CoarsePlacement {
        targets,
        parts,
        frames,
        boxes,
        bricks: n,
    };
    (coarse, placement)
}

/// The whole cells' grouping and, per level, each group's number ([`Made::number`]).
type Whole<'a> = (&'a Groups, &'a [Vec<u32>]);

/// The coarse bricks made so far.
struct Made {
    coarse: CoarseBricks,
    frames: Vec<(Vec3, f32)>,
    bricks: u32,
}

impl Made {
    /// Makes a coarse brick per group of `groups` a row wants (in order of level and group)
    /// and returns, per level and brick, what its rows read, and per level and group its
    /// number ([`NONE`]: not made). With `whole` (`groups` being the parts of its cells, then
    /// the whole cells' grouping and numbers), a part that equals a whole cell the first pass
    /// made is that brick: no brick is made twice. (A part lies in its cell, so it is the cell
    /// when it is as large; equal sets resolve to the same level in both groupings, so a
    /// part that is its whole cell reads what the whole cell does.)
    fn number(
        &mut self,
        groups: &Groups,
        used: &[u8],
        fits: &[BrickFit],
        whole: Option<Whole>,
    ) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
        let n = self.bricks;
        // Per level and group, its number once used (a group the same as below is never
        // used: its rows resolve to the group below).
        let mut numbers: Vec<Vec<u32>> = (groups.levels.iter())
            .map(|l| vec![NONE; l.starts.len() - 1])
            .collect();
        let mut wanted: Vec<(u32, u32)> = Vec::new();
        for (b, &bits) in used.iter().enumerate() {
            for level in 1..=groups.depth() {
                if bits & (1 << level) != 0 {
                    if let Some(at) = groups.resolve(level, b as u32) {
                        wanted.push(at);
                    }
                }
            }
        }
        wanted.sort_unstable();
        wanted.dedup();
        for (level, g) in wanted {
            let members = groups.levels[level as usize - 1].members(g);
            let made_whole = whole.and_then(|(w, made)| {
                let (wl, wg) = w.resolve(level, members[0])?;
                let same = w.levels[wl as usize - 1].members(wg).len() == members.len();
                let number = made[wl as usize - 1][wg as usize];
                (same && number != NONE).then_some(number)
            });
            numbers[level as usize - 1][g as usize] = match made_whole {
                Some(number) => number,
                None => {
                    let first_child = self.coarse.children.len();
                    let (brick, frame) = coarse_brick(members, fits, level, first_child);
                    self.coarse.children.extend_from_slice(members);
                    self.coarse.bricks.push(brick);
                    self.frames.push(frame);
                    n + self.coarse.bricks.len() as u32 - 1
                }
            };
        }
        let targets = (1..=groups.depth())
            .map(|level| {
                (0..n)
                    .map(|b| match groups.resolve(level, b) {
                        Some((l, g)) if numbers[l as usize - 1][g as usize] != NONE => {
                            numbers[l as usize - 1][g as usize]
                        }
                        _ => b,
                    })
                    .collect()
            })
            .collect();
        (targets, numbers)
    }

    /// Per brick and coarse brick, its bounds grown by the margin.
    fn boxes(&self, links: &Links) -> Vec<[Vec3; 2]> {
        let grow = |[lo, hi]: [Vec3; 2]| {
            [
                lo - Vec3::splat(links.margin),
                hi + Vec3::splat(links.margin),
            ]
        };
        let mut boxes: Vec<[Vec3; 2]> = links.bounds.iter().copied().map(grow).collect();
        for c in &self.coarse.bricks {
            let children =
                &self.coarse.children[c.first_child as usize..][..c.child_count as usize];
            let union =
                children
                    .iter()
                    .fold([Vec3::INFINITY, Vec3::NEG_INFINITY], |[lo, hi], &b| {
                        let [l, h] = links.bounds[b as usize];
                        [lo.min(l), hi.max(h)]
                    });
            boxes.push(grow(union));
        }
        boxes
    }
}

/// No number yet.
const NONE: u32 = u32::MAX;

/// Disjoint sets of bricks, each named by its smallest brick once [`Parts::labels`] is taken.
struct Parts(Vec<u32>);

impl Parts {
    fn find(&mut self, mut b: u32) -> u32 {
        while self.0[b as usize] != b {
            let up = self.0[self.0[b as usize] as usize];
            self.0[b as usize] = up;
            b = up;
        }
        b
    }

    fn join(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        // The smaller index is the root, so a part's root is its smallest brick.
        self.0[ra.max(rb) as usize] = ra.min(rb);
    }

    /// Per brick, the smallest brick of its part.
    fn labels(mut self) -> Vec<u32> {
        (0..self.0.len() as u32).map(|b| self.find(b)).collect()
    }
}

/// Per level, the bricks grouped by coarse cell (in order of cell), and each brick's group.
struct Groups {
    levels: Vec<Level>,
}

/// One level's groups, as runs of one array (no vector per group: a level of a million bricks
/// has about as many groups).
struct Level {
    /// The bricks in order of cell, then index.
    order: Vec<u32>,
    /// Group `g` is `order[starts[g]..starts[g + 1]]`.
    starts: Vec<u32>,
    /// Per brick, its group.
    group_of: Vec<u32>,
    /// Per group, whether it has the same bricks as a group of the level below (or, at level
    /// 1, is one brick).
    same_below: Vec<bool>,
}

impl Level {
    fn members(&self, g: u32) -> &[u32] {
        &self.order[self.starts[g as usize] as usize..self.starts[g as usize + 1] as usize]
    }
}

impl Groups {
    /// A level's group is the bricks of one cell, or with `links` those that links within the
    /// cell connect; a level's links include the level below's, so its groups are unions of
    /// that level's.
    fn of(keys: &[Key], levels: u32, links: Option<&[(u32, u32)]>) -> Groups {
        let n = keys.len() as u32;
        let mut out = Groups { levels: Vec::new() };
        for level in 1..=levels {
            let cell = |b: u32| cell(keys[b as usize], level);
            // Without links, one group per cell (the label 0 for every brick).
            let part = match links {
                Some(links) => {
                    let mut parts = Parts((0..n).collect());
                    for &(a, b) in links.iter().filter(|&&(a, b)| cell(a) == cell(b)) {
                        parts.join(a, b);
                    }
                    parts.labels()
                }
                None => vec![0; n as usize],
            };
            let cell = |b: u32| (cell(b), part[b as usize]);
            let mut order: Vec<u32> = (0..n).collect();
            order.par_sort_unstable_by_key(|&b| (cell(b), b));
            let mut group_of = vec![0u32; n as usize];
            let mut starts = vec![0u32];
            let mut same_below = Vec::new();
            let below = |b: u32| out.levels.last().map_or(b, |l| l.group_of[b as usize]);
            for group in order.chunk_by(|&a, &b| cell(a) == cell(b)) {
                same_below.push(group.iter().all(|&b| below(b) == below(group[0])));
                for &b in group {
                    group_of[b as usize] = starts.len() as u32 - 1;
                }
                starts.push(starts[starts.len() - 1] + group.len() as u32);
            }
            out.levels.push(Level {
                order,
                starts,
                group_of,
                same_below,
            });
        }
        out
    }

    /// Levels grouped.
    fn depth(&self) -> u32 {
        self.levels.len() as u32
    }

    /// The coarse brick brick `b`'s level-`level` rows read: the lowest level's group of the
    /// same bricks, or `None` when that is `b` alone.
    fn resolve(&self, level: u32, b: u32) -> Option<(u32, u32)> {
        let mut level = level.min(self.depth());
        while level >= 1 {
            let l = &self.levels[level as usize - 1];
            let g = l.group_of[b as usize];
            if !l.same_below[g as usize] {
                return Some((level, g));
            }
            level -= 1;
        }
        None
    }
}

/// A brick's weight and regularised moment, as the runtime's coarse fit reads them.
fn moments(fit: &BrickFit) -> BrickMoments {
    BrickMoments {
        weight: fit.weight as f32,
        moment: symmetric(regularised(fit.moment)),
        _pad: 0,
    }
}

/// The coarse brick over `group` (brick indices, at least two) at `level`, its children
/// starting at `first_child`: the fit over all their surfels, whose moment about the joint
/// centroid is the sum of theirs plus each one's weight times its centroid's offset squared.
fn coarse_brick(
    group: &[u32],
    fits: &[BrickFit],
    level: u32,
    first_child: usize,
) -> (CoarseBrick, (Vec3, f32)) {
    let weight: f64 = group.iter().map(|&b| fits[b as usize].weight).sum();
    let centroid = group
        .iter()
        .map(|&b| fits[b as usize].centroid * fits[b as usize].weight)
        .sum::<DVec3>()
        / weight;
    let mut moment = DMat3::ZERO;
    for &b in group {
        let f = &fits[b as usize];
        let d = f.centroid - centroid;
        moment += f.moment + DMat3::from_cols(d * d.x, d * d.y, d * d.z) * f.weight;
    }
    let trace = moment.x_axis.x + moment.y_axis.y + moment.z_axis.z;
    let scale = f64::from(1u32 << level);
    let inverse = match trace > 0.0 {
        true => regularised(moment).inverse() * scale,
        false => DMat3::ZERO,
    };
    let brick = CoarseBrick {
        first_child: first_child as u32,
        child_count: group.len() as u32,
        weight: weight as f32,
        level,
        centroid: centroid.as_vec3().to_array(),
        _pad0: 0,
        inverse: symmetric(inverse),
        _pad1: [0; 2],
    };
    (brick, (centroid.as_vec3(), scale as f32))
}

/// A symmetric matrix's six entries: xx, xy, xz, yy, yz, zz.
fn symmetric(m: DMat3) -> [f32; 6] {
    [
        m.x_axis.x, m.y_axis.x, m.z_axis.x, m.y_axis.y, m.z_axis.y, m.z_axis.z,
    ]
    .map(|v| v as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(x: f64, weight: f64) -> BrickFit {
        BrickFit {
            weight,
            centroid: DVec3::new(x, 0.0, 0.0),
            moment: DMat3::ZERO,
        }
    }

    /// Levels change where the distance passes `near` times a power of two, at any scale: a
    /// level depends on the distance over the brick size only.
    #[test]
    fn levels_double_with_distance_at_any_scale() {
        for scale in [1e-3f32, 1.0, 4096.0] {
            let far = FarField {
                origin: Vec3::splat(3.0 * scale),
                anchor: Vec3::ZERO,
                brick_size: 0.5 * scale,
                near: 2.0 * 0.5 * scale,
            };
            let at = |bricks: f32| far.level_at(bricks * 0.5 * scale);
            assert_eq!(at(0.0), 0);
            assert_eq!(at(1.999), 0);
            assert_eq!(at(2.0), 1);
            assert_eq!(at(3.999), 1);
            assert_eq!(at(4.0), 2);
            assert_eq!(at(8.0), 3);
            assert_eq!(at(1e9), FAR_LEVELS);
            assert_eq!(far.level(far.origin + Vec3::X * 8.5 * 0.5 * scale), 3);
        }
        assert_eq!(FarField::off().level_at(1e30), 0);
    }

    /// Coarse bricks only where a row needs one; a cell of one brick is that brick; a cell of
    /// the same bricks as the cell below it is the finer coarse brick; each coarse brick's fit
    /// is its bricks' weights and centroids combined.
    #[test]
    fn coarse_bricks_are_made_for_used_cells_only() {
        // Bricks 0 and 1 share level-1 cell 0; brick 2 is alone in level-1 cell 1 and joins
        // them at level 2; brick 3 (another axis) is alone at every level.
        let keys: Vec<Key> = vec![(0, 0, 0, 2), (1, 0, 0, 2), (2, 0, 0, 2), (0, 0, 0, 3)];
        let fits = vec![
            fit(0.25, 1.0),
            fit(0.75, 3.0),
            fit(1.25, 2.0),
            fit(0.25, 1.0),
        ];
        let used = [1 << 1, 0, 1 << 2, (1 << 1) | (1 << 2)];
        let (coarse, placement) = build(&keys, &fits, &used, &Links::default());
        assert_eq!(coarse.bricks.len(), 2, "{:?}", coarse.bricks);
        assert_eq!(coarse.children, [0, 1, 0, 1, 2]);
        assert_eq!(coarse.moments.len(), 4);
        let (first, second) = (&coarse.bricks[0], &coarse.bricks[1]);
        assert_eq!((first.level, first.child_count, first.weight), (1, 2, 4.0));
        assert_eq!(
            (second.level, second.child_count, second.weight),
            (2, 3, 6.0)
        );
        assert!((first.centroid[0] - 0.625).abs() < 1e-6);
        assert!((second.centroid[0] - (0.25 + 2.25 + 2.5) / 6.0).abs() < 1e-6);
        // Brick 0's level-1 rows read coarse brick 4 (after the 4 bricks), its level-2 rows 5.
        assert_eq!(placement.place(0, 1, Vec3::ZERO).map(|p| p.0), Some(4));
        assert_eq!(
            placement.place(0, 2, Vec3::ZERO).map(|p| (p.0, p.2)),
            Some((5, 4.0))
        );
        // Brick 2 at level 1 and brick 3 at any level: the brick itself.
        assert_eq!(placement.place(2, 1, Vec3::ZERO), None);
        assert_eq!(placement.place(3, 2, Vec3::ZERO), None);
        assert_eq!(placement.place(1, 0, Vec3::ZERO), None);
        // Nothing used: nothing made.
        let (none, _) = build(&keys, &fits, &[0; 4], &Links::default());
        assert!(none.bricks.is_empty() && none.children.is_empty() && none.moments.is_empty());
    }

    /// Bricks of one cell that no link joins (a wall between them) make a coarse brick each
    /// part, read by rows whose mean hit point lies in the part; a row whose mean lies outside
    /// its brick's part reads the whole cell's.
    #[test]
    fn a_cell_is_split_where_its_bricks_do_not_see_each_other() {
        // Four bricks along x in one level-2 cell; 0 | 1 split by a wall, 1 - 2 - 3 linked.
        let keys: Vec<Key> = vec![(0, 0, 0, 2), (1, 0, 0, 2), (2, 0, 0, 2), (3, 0, 0, 2)];
        let xs = [0.25, 0.75, 1.25, 1.75];
        let fits: Vec<BrickFit> = xs.iter().map(|&x| fit(x, 1.0)).collect();
        let links = Links {
            pairs: vec![(1, 2), (2, 3)],
            bounds: (xs.iter())
                .map(|&x| {
                    [
                        Vec3::new(x as f32 - 0.25, 0.0, 0.0),
                        Vec3::new(x as f32 + 0.25, 0.0, 0.0),
                    ]
                })
                .collect(),
            margin: 0.01,
        };
        let used = [1 << 2, 1 << 2, 0, 0];
        let (coarse, placement) = build(&keys, &fits, &used, &links);
        // Level 2: the whole cell (4), then the part {1, 2, 3} (5); {0} is brick 0 itself.
        assert_eq!(coarse.children, [0, 1, 2, 3, 1, 2, 3]);
        let at = |b: u32, x: f32| placement.place(b, 2, Vec3::new(x, 0.0, 0.0)).map(|p| p.0);
        assert_eq!(at(0, 0.3), None, "brick 0's part is itself");
        assert_eq!(
            at(0, 1.0),
            Some(4),
            "a mean outside the part: the whole cell"
        );
        assert_eq!(at(1, 1.5), Some(5));
        assert_eq!(at(1, 0.2), Some(4));
        // Linked throughout: one coarse brick, as without links.
        let all = Links {
            pairs: vec![(0, 1), (1, 2), (2, 3)],
            ..links
        };
        let (coarse, placement) = build(&keys, &fits, &used, &all);
        assert_eq!(coarse.children, [0, 1, 2, 3]);
        assert_eq!(placement.place(0, 2, Vec3::ZERO).map(|p| p.0), Some(4));

        // A part that equals a whole cell of the level below (0-1 | 2-3 at level 2 is 0-1,
        // the level-1 cell) is that cell's brick, not a second one.
        let halves = Links {
            pairs: vec![(0, 1), (2, 3)],
            ..all
        };
        let (coarse, placement) = build(&keys, &fits, &[(1 << 1) | (1 << 2), 0, 0, 0], &halves);
        assert_eq!(coarse.children, [0, 1, 0, 1, 2, 3]);
        let at = |level: u32, x: f32| {
            let place = placement.place(0, level, Vec3::new(x, 0.0, 0.0));
            place.map(|p| p.0)
        };
        assert_eq!(
            (at(1, 0.5), at(2, 0.5), at(2, 1.5)),
            (Some(4), Some(4), Some(5))
        );
    }
}
