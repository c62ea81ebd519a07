//! Coarse bricks for far hits ([`prt_format::coarse`] says what they are and why).
//!
//! While tracing, each hit is given a level by its distance from its probe ([`FarField`]):
//! level 0 (its own brick) within `far_ratio` brick sizes, then one level more each time the
//! distance doubles, so that a level's brick is at most `2 / far_ratio` radians wide where it
//! is used. A probe's hits of one level and one coarse cell (and one normal key) make one
//! factor row. Once every brick is known, [`build`] makes the coarse bricks: per level, the
//! bricks of each coarse cell, unless that is a single brick (the brick itself is used) or the
//! same bricks as the level below (the finer coarse brick is used). [`CoarsePlacement`] then
//! says which brick or coarse brick a row of a given level reads.

use glam::{DMat3, DVec3, Vec3};
use prt_format::coarse::{BrickMoments, CoarseBrick, CoarseBricks, MAX_LEVEL};
use rayon::prelude::*;

use crate::merge::fold::{regularised, BrickFit};
use crate::merge::key::{brick_key, Key};
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
    /// `near * [2^(l-1), 2^l)`, at most [`MAX_LEVEL`]. By comparisons with exact powers of
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
        while level < MAX_LEVEL && d >= bound {
            level += 1;
            bound *= 2.0;
        }
        level
    }

    /// The coarse cell of `hit` at `level`: its brick's key (the fold's arithmetic), its cell
    /// divided by `2^level`.
    #[inline]
    pub fn key(&self, hit: &Hit, level: u32) -> Key {
        let (x, y, z, flags) = brick_key(hit, self.anchor, self.brick_size);
        (x >> level, y >> level, z >> level, flags)
    }
}

/// Which brick or coarse brick a factor row of each level reads, per brick: `targets[l - 1][b]`
/// for brick `b`'s level-`l` cell (a brick index below the brick count, else the coarse
/// brick's index after them); and where each coarse brick's offsets are measured from.
pub struct CoarsePlacement {
    targets: Vec<Vec<u32>>,
    /// Per coarse brick: its centroid and `2^level`, the divisor of its factors' offsets.
    frames: Vec<(Vec3, f32)>,
    bricks: u32,
}

impl CoarsePlacement {
    /// Whether rows carry levels: some coarse level was made (never for unmerged bakes,
    /// whose rows' brick words use every bit).
    pub fn has_levels(&self) -> bool {
        !self.targets.is_empty()
    }

    /// What a level-`level` row of (final) brick `brick` reads, and the centroid and scale of
    /// its offsets, or `None` for the brick itself (level 0, or a level that has no coarse
    /// brick over it of more than itself).
    #[inline]
    pub fn place(&self, brick: u32, level: u32) -> Option<(u32, Vec3, f32)> {
        let target = *self
            .targets
            .get(level.checked_sub(1)? as usize)?
            .get(brick as usize)?;
        let (centroid, scale) = *self.frames.get(target.checked_sub(self.bricks)? as usize)?;
        Some((target, centroid, scale))
    }
}

/// The coarse bricks over `keys`' bricks (with their `fits`), and where each level's rows go;
/// `used[b]` has bit `l` set when a level-`l` row names brick `b`. Only those rows' coarse
/// bricks are made: the cells of the levels up to the highest used are grouped bottom-up (a
/// cell of the same bricks as the one below it is that one), then each used cell's group is
/// numbered, in order of level and cell. Nothing used (no far rows): no level is grouped.
pub fn build(keys: &[Key], fits: &[BrickFit], used: &[u8]) -> (CoarseBricks, CoarsePlacement) {
    let n = keys.len() as u32;
    let all = used.iter().fold(0u8, |all, &bits| all | bits);
    let levels = (u8::BITS - all.leading_zeros()).saturating_sub(1);
    let groups = Groups::of(keys, levels.min(MAX_LEVEL));
    // Per level and group, its number once used (a group the same as below is never used:
    // its rows resolve to the group below).
    let mut numbers: Vec<Vec<u32>> = (groups.levels.iter())
        .map(|l| vec![NONE; l.starts.len() - 1])
        .collect();
    let mut coarse = CoarseBricks::default();
    let mut frames = Vec::new();
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
        let first_child = coarse.children.len();
        let (brick, frame) = coarse_brick(members, fits, level, first_child);
        coarse.children.extend_from_slice(members);
        coarse.bricks.push(brick);
        frames.push(frame);
        numbers[level as usize - 1][g as usize] = n + coarse.bricks.len() as u32 - 1;
    }
    if !coarse.bricks.is_empty() {
        coarse.moments = fits.iter().map(moments).collect();
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
    let placement = CoarsePlacement {
        targets,
        frames,
        bricks: n,
    };
    (coarse, placement)
}

/// No number yet.
const NONE: u32 = u32::MAX;

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
    fn of(keys: &[Key], levels: u32) -> Groups {
        let n = keys.len() as u32;
        let mut out = Groups { levels: Vec::new() };
        for level in 1..=levels {
            let cell = |b: u32| {
                let k = keys[b as usize];
                (k.0 >> level, k.1 >> level, k.2 >> level, k.3)
            };
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
            assert_eq!(at(1e9), MAX_LEVEL);
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
        let (coarse, placement) = build(&keys, &fits, &used);
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
        assert_eq!(placement.place(0, 1).map(|p| p.0), Some(4));
        assert_eq!(placement.place(0, 2).map(|p| (p.0, p.2)), Some((5, 4.0)));
        // Brick 2 at level 1 and brick 3 at any level: the brick itself.
        assert_eq!(placement.place(2, 1), None);
        assert_eq!(placement.place(3, 2), None);
        assert_eq!(placement.place(1, 0), None);
        // Nothing used: nothing made.
        let (none, _) = build(&keys, &fits, &[0; 4]);
        assert!(none.bricks.is_empty() && none.children.is_empty() && none.moments.is_empty());
    }
}
