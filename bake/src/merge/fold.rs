//! Bricks: surfels grouped by world cell and dominant normal axis, merged where they agree.
//!
//! A brick covers 4x4x4 surfel cells of `cell_size` metres and one of the six dominant normal
//! axes (+-X, +-Y, +-Z), so that the two sides of a thin wall, or a floor and the wall beside it,
//! never share a brick (the light leak the prior art suffers from). Back-face hits of single-sided
//! surfaces are black and get bricks of their own.
//!
//! Inside a brick, ray hits in the same surfel cell whose normals agree (cosine above
//! `merge_normal_cos`) and that lie on the same side of any wall in the cell ([`Hit::across`],
//! `crate::merge::sides`) become one surfel whose position, normal, albedo and emission are the
//! means of its hits and whose weight is their count. Relighting then computes one irradiance per
//! surfel and one radiance per brick (the weighted mean), shared by every probe that sees it.
//!
//! `cell_size == 0` switches merging off: every hit is its own surfel and its own brick, which
//! makes the relit probe exactly the Monte Carlo estimate of docs/conventions.md section 5.
//!
//! Hits are folded in as they are traced ([`BrickFolder`]); bricks are numbered by sorted key,
//! so the result does not depend on the number of threads.

use glam::{DMat3, DVec3, Vec3};
use prt_format::{Brick, Surfel, BRICK_BACKFACE};
use rayon::prelude::*;

use crate::memory::chunked::Chunked;
use crate::memory::{prefetch, split_runs};
use crate::merge::index::{BrickIndex, MAX_BRICKS};
use crate::merge::key::{brick_key, cell_in_brick, flags_of, Key};
use crate::trace::Hit;
use crate::BakeError;

/// Bricks and their surfels, in key order.
pub struct Bricked {
    pub bricks: Vec<Brick>,
    pub surfels: Vec<Surfel>,
    /// Per brick, its key (what the coarse bricks over it are found by).
    pub keys: Vec<Key>,
    /// Per brick, the sums of its linear fit (what a coarse brick's fit is made of).
    pub fits: Vec<BrickFit>,
}

/// The sums behind a brick's linear radiance fit (`brick_of`), in f64: the surfels' weight,
/// their weighted mean position, and the weighted second moment of their positions about it.
#[derive(Clone, Copy, Debug, Default)]
pub struct BrickFit {
    pub weight: f64,
    pub centroid: DVec3,
    pub moment: DMat3,
}

/// Merges ray hits into bricks as they arrive, so that the bake never holds every hit at once
/// (the working set is one block of probes; what grows is the bricks and surfels the asset
/// carries). Hits must come in the bake's order (probe by probe, each probe's in the order its rays
/// were traced): a surfel is the running mean of the hits that joined it, and a hit joins the first
/// surfel of its cell, in creation order, whose first normal agrees with its own and whose hits
/// lie on its side of the cell ([`Hit::across`]).
/// [`BrickFolder::finish_placed`] numbers the bricks by key, so the result depends only on the hits
/// and their order, never on how they were blocked or on the thread count
/// (`tests::blocking_does_not_change_the_result`).
///
/// A brick is found by hashing its key (`BrickIndex`, seeded per process), then its cell's
/// surfels through a list per cell: no sort of every hit's key (which held every hit, its key
/// and its rank at once), and no scan of a brick's surfels for the hit's cell.
pub struct BrickFolder {
    anchor: Vec3,
    cell_size: f32,
    merge_normal_cos: f32,
    /// Brick key to provisional brick (arrival order).
    index: BrickIndex,
    /// Per provisional brick: its key.
    keys: Vec<Key>,
    /// Per provisional brick and cell, its first surfel in `clusters` (merging only). Chunks
    /// of 32 MiB, as for `clusters` and `next` ([`Chunked`]).
    heads: Chunked<[u32; 64], 17>,
    /// Per provisional brick, its surfels (merging only): counted as they are made, so that
    /// numbering the bricks does not walk every cell list once more just to count them.
    surfel_counts: Vec<u32>,
    /// Every surfel being merged; a cell's surfels are a list through `next`, in creation
    /// order (unmerged: cluster i is brick i's only surfel).
    clusters: Chunked<Cluster, 19>,
    /// Per surfel (merging only), the next surfel of the same brick and cell: beside the
    /// clusters, not in them, so that a cluster fills one cache line ([`Cluster`]).
    next: Chunked<u32, 23>,
    /// Scratch: one probe's hits as (brick, cell, hit), reused.
    slots: Vec<(u32, u8, u32)>,
    /// Scratch: one probe's hits' brick keys.
    keys_of_hits: Vec<Key>,
    /// Scratch: where each run of one probe's keys is looked up ([`BrickIndex::home`]).
    homes: Vec<usize>,
}

/// No surfel: the end of a cell's list.
const NONE: u32 = u32::MAX;

impl BrickFolder {
    /// `cell_size == 0` switches merging off (one brick per hit, in hit order). The cell lattice
    /// starts at `anchor`: the bake puts it half a cell off the world origin, so that walls at
    /// round coordinates (whole numbers of cells from the origin) lie in the middle of cells.
    /// Anchored at the origin itself, such walls lie exactly on cell boundaries, and float
    /// rounding splits their hits between two cells at random: more bricks and surfels, and
    /// different ones at every scene scale. Anchoring at the bounds' corner instead gave a
    /// larger surface error on the two-room fixture.
    pub fn new(cell_size: f32, merge_normal_cos: f32, anchor: Vec3) -> Self {
        BrickFolder {
            anchor,
            cell_size: cell_size.max(0.0),
            merge_normal_cos,
            index: BrickIndex::default(),
            keys: Vec::new(),
            heads: Chunked::default(),
            surfel_counts: Vec::new(),
            clusters: Chunked::default(),
            next: Chunked::default(),
            slots: Vec::new(),
            keys_of_hits: Vec::new(),
            homes: Vec::new(),
        }
    }

    /// The brick lattice: its corner and brick size (0 unmerged).
    pub fn lattice(&self) -> (Vec3, f32) {
        (self.anchor, 4.0 * self.cell_size)
    }

    /// Folds the next `hits` (one probe's) in and appends the provisional brick of each to
    /// `brick_of_hit`. Fails, before any change, when the surfels would pass 2^32 - 1 or the
    /// bricks what the index numbers (`MAX_BRICKS` merged, 2^32 - 1 unmerged; every hit adds
    /// at most one of each).
    ///
    /// The hits are taken in their order, a brick looked up once for each run of consecutive
    /// hits in it (the coherent ray order makes runs common), all the runs' lookups together so
    /// that their cache misses overlap; then the cells' heads and first surfels are loaded for
    /// every hit before any is merged (`BrickFolder::touch`), instead of each hit waiting for
    /// its own misses. With the loads taken together, sorting the hits by brick first costs
    /// more than it saves. A brick's surfels depend only on the order of its own hits, which
    /// every one of these orders keeps.
    pub fn fold(&mut self, hits: &[Hit], brick_of_hit: &mut Vec<u32>) -> Result<(), BakeError> {
        let room = |limit: u32| limit as usize - hits.len().min(limit as usize);
        let unmerged = self.cell_size == 0.0;
        let brick_room = room(if unmerged { NONE } else { MAX_BRICKS });
        if self.clusters.len() > room(NONE) || self.keys.len() > brick_room {
            return Err(BakeError::Setting {
                name: "spacing",
                value: format!(
                    "{} surfels and {} bricks so far, {} more ray hits",
                    self.clusters.len(),
                    self.keys.len(),
                    hits.len()
                ),
                reason: "more than 2^32 - 1 surfels, or more bricks than can be numbered (2^28 \
                         merged, 2^32 - 1 unmerged): use fewer probes or rays, or larger cells",
            });
        }
        let first = brick_of_hit.len();
        if unmerged {
            for h in hits {
                brick_of_hit.push(self.keys.len() as u32);
                self.keys.push((0, 0, 0, flags_of(h)));
                self.clusters.push(Cluster::of(h));
            }
            return Ok(());
        }
        let brick_size = 4.0 * self.cell_size;
        let mut keys = std::mem::take(&mut self.keys_of_hits);
        keys.clear();
        keys.extend(hits.iter().map(|h| brick_key(h, self.anchor, brick_size)));
        brick_of_hit.resize(first + hits.len(), 0);
        let runs = || keys.chunk_by(|a, b| a == b);
        // Every run's slot asked for before any is looked up, so that their misses overlap.
        self.index.reserve(keys.len());
        let mut homes = std::mem::take(&mut self.homes);
        homes.clear();
        homes.extend(runs().map(|run| self.index.home(&run[0])));
        // Each hit's brick and cell.
        let mut slots = std::mem::take(&mut self.slots);
        slots.clear();
        let mut start = 0u32;
        for (run, &home) in runs().zip(&homes) {
            let key = run[0];
            let b = match self.index.find(&key, home) {
                Ok(b) => b,
                Err(at) => {
                    let b = self.new_brick(key);
                    self.index.insert(at, &key, b);
                    b
                }
            };
            let origin =
                self.anchor + Vec3::new(key.0 as f32, key.1 as f32, key.2 as f32) * brick_size;
            for i in start..start + run.len() as u32 {
                let cell = cell_in_brick(hits[i as usize].position, origin, self.cell_size);
                let cell = cell[0] + 4 * (cell[1] + 4 * cell[2]);
                slots.push((b, cell as u8, i));
                brick_of_hit[first + i as usize] = b;
            }
            start += run.len() as u32;
        }
        self.keys_of_hits = keys;
        self.homes = homes;
        self.touch(&slots);
        for &(b, cell, i) in &slots {
            self.merge(b, usize::from(cell), &hits[i as usize]);
        }
        self.slots = slots;
        Ok(())
    }

    /// Loads the cells' heads, then their first surfels, for every hit before any is merged.
    /// The loads do not depend on each other, so the CPU overlaps their cache misses; merging
    /// hit by hit, each hit would wait for two misses in turn (its cell's head, then the surfel
    /// it points to), most of the fold's time. Merging then finds them in cache. On x86-64 as
    /// prefetches, which the CPU does not wait for, where a load it must finish before the next
    /// instructions retire.
    fn touch(&self, slots: &[(u32, u8, u32)]) {
        for &(b, cell, _) in slots {
            prefetch(&self.heads[b as usize][usize::from(cell)]);
        }
        for &(b, cell, _) in slots {
            let head = self.heads[b as usize][usize::from(cell)];
            if let Some(cl) = self.clusters.get(head as usize) {
                prefetch(cl);
            }
        }
    }

    /// A new provisional brick for `key` (the caller puts it in the index).
    fn new_brick(&mut self, key: Key) -> u32 {
        let b = self.keys.len() as u32;
        self.keys.push(key);
        self.heads.push([NONE; 64]);
        self.surfel_counts.push(0);
        b
    }

    /// Merges `h` into the first surfel of its cell in brick `b` whose normal agrees and whose
    /// hits lie on its side, or starts a new one.
    fn merge(&mut self, b: u32, cell: usize, h: &Hit) {
        let new = self.clusters.len() as u32;
        let head = &mut self.heads[b as usize][cell];
        if *head == NONE {
            *head = new;
        } else {
            let mut at = *head;
            loop {
                let cl = &mut self.clusters[at as usize];
                if cl.direction.dot(h.normal) >= self.merge_normal_cos && cl.across() == h.across {
                    cl.add(h);
                    return;
                }
                let next = &mut self.next[at as usize];
                if *next == NONE {
                    *next = new;
                    break;
                }
                at = *next;
            }
        }
        self.clusters.push(Cluster::of(h));
        self.next.push(NONE);
        self.surfel_counts[b as usize] += 1;
    }

    /// Asks for what [`BrickFolder::finish_placed`] reads next: the first surfel of each of brick
    /// `b`'s cells, and the cell heads of the brick after it, `next`. Bricks are finished in key
    /// order, their surfels were made in arrival order, so each is a cache miss; the loads do not
    /// depend on each other, but the walk of the cells would wait for each in turn.
    fn prefetch_brick(&self, b: u32, next: Option<u32>) {
        if self.cell_size == 0.0 {
            return;
        }
        if let Some(n) = next {
            // 256 bytes, on five lines unless they start on one.
            let heads = &self.heads[n as usize];
            for i in [0, 16, 32, 48, 63] {
                prefetch(&heads[i]);
            }
        }
        for &head in &self.heads[b as usize] {
            if let Some(cl) = self.clusters.get(head as usize) {
                prefetch(cl);
            }
        }
    }

    /// Brick `b`'s surfels: cell by cell, in creation order within a cell.
    fn clusters_of(&self, b: u32) -> impl Iterator<Item = &Cluster> {
        let (heads, single) = match self.cell_size == 0.0 {
            true => (&[][..], Some(&self.clusters[b as usize])),
            false => (&self.heads[b as usize][..], None),
        };
        let listed = heads.iter().flat_map(move |&head| {
            let next = |&at: &u32| Some(self.next[at as usize]).filter(|&n| n != NONE);
            std::iter::successors(Some(head).filter(|&h| h != NONE), next)
                .map(|at| &self.clusters[at as usize])
        });
        single.into_iter().chain(listed)
    }

    /// [`Self::finish_placed`] with no placement (the tests of the merge alone).
    #[cfg(test)]
    fn finish(self) -> (Bricked, Vec<u32>) {
        self.finish_placed(&|_, _| {})
    }

    /// The bricks numbered in key order (merged) or hit order (unmerged), their surfels, and the
    /// final number of every provisional brick. Each merged surfel is first given to `place`
    /// with its brick's cell (min, max), before the bricks' bounds and fits are taken: the bake
    /// puts surfels that lie behind their surface back on it ([`super::snap`]). Unmerged hits
    /// are not placed.
    pub fn finish_placed(
        self,
        place: &(dyn Fn(&mut Surfel, [Vec3; 2]) + Sync),
    ) -> (Bricked, Vec<u32>) {
        let unmerged = self.cell_size == 0.0;
        // Keys sorted beside their bricks, not bricks through their keys, where each comparison
        // reads two keys scattered over the table. Keys are distinct, so any sort gives one
        // order.
        let order: Vec<u32> = match unmerged {
            true => (0..self.keys.len() as u32).collect(),
            false => {
                let mut keyed: Vec<(Key, u32)> = self.keys.iter().copied().zip(0..).collect();
                keyed.par_sort_unstable();
                keyed.into_iter().map(|(_, b)| b).collect()
            }
        };
        let mut remap = vec![0u32; order.len()];
        for (final_index, &b) in order.iter().enumerate() {
            remap[b as usize] = final_index as u32;
        }
        // Each brick's surfels written in parallel straight into their run of the one surfel
        // array: a vector per brick, joined, would hold every surfel twice at the bake's peak.
        let counts: Vec<usize> = order
            .iter()
            .map(|&b| match unmerged {
                true => 1,
                false => self.surfel_counts[b as usize] as usize,
            })
            .collect();
        // Zeroed by the allocator, not filled here: the pages are first touched by the parallel
        // writes below, not by a serial fill.
        let mut surfels: Vec<Surfel> = bytemuck::zeroed_vec(counts.iter().sum());
        let runs = split_runs(&mut surfels, &counts);
        let (bricks, fits): (Vec<Brick>, Vec<BrickFit>) = order
            .par_iter()
            .zip(runs)
            .enumerate()
            .map(|(final_index, (&b, (first, run)))| {
                self.prefetch_brick(b, order.get(final_index + 1).copied());
                let (x, y, z, flags) = self.keys[b as usize];
                let backface = flags & BRICK_BACKFACE != 0;
                let (anchor, brick_size) = self.lattice();
                let lo = anchor + Vec3::new(x as f32, y as f32, z as f32) * brick_size;
                for (out, cl) in run.iter_mut().zip(self.clusters_of(b)) {
                    *out = Surfel {
                        brick: final_index as u32,
                        ..cl.surfel(!unmerged, backface)
                    };
                    if !unmerged {
                        place(out, [lo, lo + Vec3::splat(brick_size)]);
                    }
                }
                // The fold refuses more than 2^32 - 1 surfels.
                brick_of(run, flags, first as u32)
            })
            .collect();
        let keys = order.iter().map(|&b| self.keys[b as usize]).collect();
        let bricked = Bricked {
            bricks,
            surfels,
            keys,
            fits,
        };
        (bricked, remap)
    }
}

/// Finishes one brick: bounds, centroid, and the surfels' gradient weights.
///
/// The brick's radiance is modelled as linear, `L(p) = L_mean + G . (p - centroid)`, fitted by
/// weighted least squares over its surfels: `G = C^-1 sum_s w_s (p_s - centroid) L_s` with
/// `C = sum_s w_s (p_s - centroid)(p_s - centroid)^T`. `C` depends only on positions, so each
/// surfel stores `g_s = w_s C^-1 (p_s - centroid)` and the runtime gets `G = sum_s g_s L_s`.
/// `C` is regularised by a thousandth of its trace: flat bricks get no gradient along their
/// normal, single-surfel bricks none at all.
pub(crate) fn brick_of(surfels: &mut [Surfel], flags: u32, first_surfel: u32) -> (Brick, BrickFit) {
    let mut min = Vec3::INFINITY;
    let mut max = Vec3::NEG_INFINITY;
    let mut sum = DVec3::ZERO;
    let mut weight = 0.0f64;
    for s in surfels.iter() {
        let p = Vec3::from(s.position);
        min = min.min(p);
        max = max.max(p);
        sum += p.as_dvec3() * f64::from(s.weight);
        weight += f64::from(s.weight);
    }
    let centroid = sum / weight;
    let mut c = DMat3::ZERO;
    for s in surfels.iter() {
        let d = Vec3::from(s.position).as_dvec3() - centroid;
        c += DMat3::from_cols(d * d.x, d * d.y, d * d.z) * f64::from(s.weight);
    }
    let trace = c.x_axis.x + c.y_axis.y + c.z_axis.z;
    if trace > 0.0 {
        let inv = regularised(c).inverse();
        for s in surfels.iter_mut() {
            let d = Vec3::from(s.position).as_dvec3() - centroid;
            s.gradient = (inv * d * f64::from(s.weight)).as_vec3().to_array();
        }
    }
    let brick = Brick {
        min: min.to_array(),
        first_surfel,
        max: max.to_array(),
        surfel_count: surfels.len() as u32,
        centroid: centroid.as_vec3().to_array(),
        flags,
    };
    let fit = BrickFit {
        weight,
        centroid,
        moment: c,
    };
    (brick, fit)
}

/// The regularisation of a fit's moment (`brick_of`): a thousandth of its trace on the
/// diagonal.
pub fn regularised(moment: DMat3) -> DMat3 {
    let trace = moment.x_axis.x + moment.y_axis.y + moment.z_axis.z;
    moment + DMat3::IDENTITY * (1e-3 * trace)
}

/// Running sums of one surfel being merged, in one cache line: merging a hit reads the
/// cluster's direction and adds to its sums. The cell's list link is kept beside it
/// ([`BrickFolder`]'s `next`) and the back-face flag is its brick's: with both inside, a
/// cluster takes 72 bytes and most straddle two lines.
#[repr(C, align(64))]
struct Cluster {
    /// Hits merged, and [`ACROSS`] when they are across a wall from the cell's centre.
    count: u32,
    position: Vec3,
    normal: Vec3,
    /// Normal of the cluster's first hit: later hits join when they agree with it.
    direction: Vec3,
    albedo: Vec3,
    emission: Vec3,
}
const _: () = assert!(std::mem::size_of::<Cluster>() == 64);

/// [`Cluster::count`]'s bit for hits across a wall ([`Hit::across`]).
const ACROSS: u32 = 1 << 31;

impl Cluster {
    fn of(h: &Hit) -> Cluster {
        Cluster {
            count: 1 | if h.across { ACROSS } else { 0 },
            position: h.position,
            normal: h.normal,
            direction: h.normal,
            albedo: Vec3::from(h.albedo),
            emission: Vec3::from(h.emission),
        }
    }

    fn across(&self) -> bool {
        self.count & ACROSS != 0
    }

    /// How many hits were merged.
    fn hits(&self) -> f32 {
        (self.count & !ACROSS) as f32
    }

    fn add(&mut self, h: &Hit) {
        debug_assert!(
            self.count & !ACROSS < !ACROSS,
            "hit count into the across bit"
        );
        self.count += 1;
        self.position += h.position;
        self.normal += h.normal;
        self.albedo += Vec3::from(h.albedo);
        self.emission += Vec3::from(h.emission);
    }

    /// The merged surfel: means of its hits, weight their count (a half's value), back face
    /// as its brick (a brick's hits all have the same flags). An unmerged hit keeps its unit
    /// normal bit for bit (renormalising could move the last bit).
    fn surfel(&self, renormalise: bool, backface: bool) -> Surfel {
        let n = if renormalise {
            self.normal.normalize_or(self.normal.signum())
        } else {
            self.normal
        };
        let count = self.hits();
        Surfel {
            position: (self.position / count).to_array(),
            brick: 0,
            normal: n.to_array(),
            // A half's value, as packed surfels keep it (exact to 2048 hits), so that the
            // brick fits use the weight the runtime reads.
            weight: prt_format::surfel::half_weight(count),
            albedo: (self.albedo / count).to_array(),
            flags: if backface { BRICK_BACKFACE } else { 0 },
            emission: (self.emission / count).to_array(),
            ..Surfel::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Folds `hits` in one go: bricks and each hit's final brick.
    fn build(hits: &[Hit], cell_size: f32, cos: f32, anchor: Vec3) -> (Bricked, Vec<u32>) {
        let mut folder = BrickFolder::new(cell_size, cos, anchor);
        let mut ids = Vec::new();
        folder.fold(hits, &mut ids).unwrap();
        let (bricked, remap) = folder.finish();
        (bricked, ids.iter().map(|&b| remap[b as usize]).collect())
    }

    fn hit(p: [f32; 3], n: [f32; 3]) -> Hit {
        Hit::grey(0, Vec3::from(p), Vec3::from(n))
    }

    #[test]
    fn merges_close_agreeing_hits_and_keeps_opposite_normals_apart() {
        let hits = [
            hit([0.01, 0.0, 0.01], [0.0, 1.0, 0.0]),
            hit([0.02, 0.0, 0.02], [0.0, 1.0, 0.0]),
            hit([0.02, 0.0, 0.02], [0.0, -1.0, 0.0]),
            hit([0.35, 0.0, 0.02], [0.0, 1.0, 0.0]),
        ];
        let (b, hit_brick) = build(&hits, 0.1, 0.9, Vec3::ZERO);
        assert_eq!(b.bricks.len(), 2, "up and down facing bricks");
        assert_eq!(
            b.surfels.len(),
            3,
            "two up-facing cells plus one down-facing"
        );
        let total: f32 = b.surfels.iter().map(|s| s.weight).sum();
        assert_eq!(total, 4.0);
        assert_eq!(hit_brick[0], hit_brick[1]);
        assert_ne!(hit_brick[0], hit_brick[2]);
    }

    /// Hits of one cell whose normals agree but that a wall parts ([`Hit::across`]) make two
    /// surfels, each weighing its own hits.
    #[test]
    fn hits_across_a_wall_stay_apart() {
        let near = |x: f32, across: bool| Hit {
            across,
            ..hit([x, 0.0, 0.01], [0.0, 1.0, 0.0])
        };
        let hits = [
            near(0.01, false),
            near(0.08, true),
            near(0.02, false),
            near(0.09, true),
            near(0.07, true),
        ];
        let (b, _) = build(&hits, 0.1, 0.9, Vec3::ZERO);
        assert_eq!(b.surfels.len(), 2);
        let mut weights: Vec<f32> = b.surfels.iter().map(|s| s.weight).collect();
        weights.sort_by(f32::total_cmp);
        assert_eq!(weights, [2.0, 3.0]);
    }

    #[test]
    fn zero_cell_size_keeps_every_hit() {
        let hits = [
            hit([0.0; 3], [0.0, 1.0, 0.0]),
            hit([0.0; 3], [0.0, 1.0, 0.0]),
        ];
        let (b, hit_brick) = build(&hits, 0.0, 0.9, Vec3::ZERO);
        assert_eq!(b.bricks.len(), 2);
        assert_eq!(hit_brick, vec![0, 1]);
    }

    /// Folding hits in blocks of any size gives the same bricks, surfels and hit bricks as
    /// folding them at once, and bricks come out in key order whatever order they arrived in.
    #[test]
    fn blocking_does_not_change_the_result() {
        let mut state = 12345u64;
        let mut next = |m: u32| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
            ((state >> 33) % u64::from(m)) as f32
        };
        let hits: Vec<Hit> = (0..3000)
            .map(|_| {
                let p = [next(100) * 0.013, next(50) * 0.021, next(20) * 0.05];
                let n = Vec3::new(next(9) - 4.0, next(9) - 4.0, next(9) - 4.0 + 0.5).normalize();
                Hit {
                    backface: next(7) == 0.0,
                    ..hit(p, n.to_array())
                }
            })
            .collect();
        for cell in [0.0, 0.05] {
            let (whole, whole_ids) = build(&hits, cell, 0.9, Vec3::splat(-0.025));
            let mut folder = BrickFolder::new(cell, 0.9, Vec3::splat(-0.025));
            let mut ids = Vec::new();
            let mut start = 0;
            while start < hits.len() {
                let end = (start + 1 + next(400) as usize).min(hits.len());
                folder.fold(&hits[start..end], &mut ids).unwrap();
                start = end;
            }
            let (blocked, remap) = folder.finish();
            let ids: Vec<u32> = ids.iter().map(|&b| remap[b as usize]).collect();
            assert_eq!(ids, whole_ids, "cell {cell}");
            assert_eq!(
                bytemuck::cast_slice::<Brick, u8>(&blocked.bricks),
                bytemuck::cast_slice::<Brick, u8>(&whole.bricks)
            );
            assert_eq!(
                bytemuck::cast_slice::<Surfel, u8>(&blocked.surfels),
                bytemuck::cast_slice::<Surfel, u8>(&whole.surfels)
            );
            let weight: f32 = whole.surfels.iter().map(|s| s.weight).sum();
            assert_eq!(weight, hits.len() as f32, "cell {cell}");
            if cell > 0.0 {
                // Brick numbers follow the keys of the hits in them.
                let mut numbered: Vec<(u32, (i32, i32, i32, u32))> = hits
                    .iter()
                    .zip(&whole_ids)
                    .map(|(h, &b)| {
                        let c = ((h.position + 0.025) / (4.0 * cell)).floor();
                        (b, (c.x as i32, c.y as i32, c.z as i32, flags_of(h)))
                    })
                    .collect();
                numbered.sort_unstable();
                assert!(numbered
                    .windows(2)
                    .all(|w| (w[0].0 == w[1].0) == (w[0].1 == w[1].1) && w[0].1 <= w[1].1));
            }
        }
    }
}
