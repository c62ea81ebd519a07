//! Per-probe factor tables: for every brick a probe's rays hit, the number of those rays and the
//! SH9 projection of their directions, `4pi/N sum_{rays i into the brick} Y_k(w_i)`.
//!
//! The weights come from the probe's own rays, never from a heuristic such as the prior art's
//! rescaled cosine between a brick's normal and the probe direction; every (probe, brick) pair is
//! kept however many there are. With `L_b` the brick's radiance, the probe's SH is
//! `sum_f transfer_k(f) L_{b(f)}` plus the sky term: the Monte Carlo projection of
//! docs/conventions.md section 2 with each hit's radiance replaced by its brick's.

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_format::{
    split_row_for_u8, u8_offset_scale, Brick, FactorF16, FactorF32, FactorRow, FactorU8, Factors,
    TransferPrecision, U8_MAX_BRICK, U8_MAX_RAYS,
};

use bytemuck::Pod;
use rayon::prelude::*;

use std::collections::HashMap;

use foldhash::fast::FixedState;

use crate::merge::coarse::{CoarsePlacement, FarField};
use crate::merge::key::Key;
use crate::tables::row_store::RowStore;
use crate::trace::Hit;
use crate::BakeError;

/// Factor rows of one probe while bricks are provisional ([`crate::merge::fold::BrickFolder`]):
/// one per provisional brick its rays hit, each row's sums taken ray by ray in lattice order,
/// kept in the form `precision` keeps them ([`ProbeRows`]); rows in the order of their first
/// rays (encoding sorts them by final brick).
///
/// Without a sort: the hits are put in ray order through a table of the lattice (a probe's
/// rays are distinct), and grouped through `table`, a row per brick ([`RowTable`]); sorting
/// (brick, ray) keys costs more than either.
pub fn probe_rows(
    hits: &[Hit],
    hit_brick: &[u32],
    (basis, weight): (&[[f32; SH_COUNT]], f32),
    far: &FarField,
    precision: TransferPrecision,
    table: &mut RowTable,
) -> ProbeRows {
    const NO_HIT: u32 = u32::MAX;
    let mut by_ray = vec![NO_HIT; basis.len()];
    for (i, h) in hits.iter().enumerate() {
        debug_assert_eq!(by_ray[h.ray as usize], NO_HIT, "ray {} hit twice", h.ray);
        by_ray[h.ray as usize] = i as u32;
    }
    let low = hit_brick.iter().min().copied().unwrap_or(0);
    let span = hit_brick
        .iter()
        .max()
        .map_or(0, |&b| (b - low) as usize + 1);
    let probe = table.next_probe(span);
    let mut rows: Vec<FactorRow> = Vec::with_capacity(hits.len().min(256));
    // Far hits' rows by coarse cell and level; the row names the first hit's brick, which
    // with the level finds the coarse brick once bricks are numbered (`CoarsePlacement`).
    let mut coarse: HashMap<(Key, u32), u32, FixedState> = HashMap::default();
    for (ray, &i) in by_ray.iter().enumerate().filter(|&(_, &i)| i != NO_HIT) {
        let (brick, i) = (hit_brick[i as usize], i as usize);
        let level = far.level(hits[i].position);
        let at = if level == 0 {
            let entry = &mut table.rows[(brick - low) as usize];
            if entry.0 != probe {
                rows.push((brick, 0, [0.0; SH_COUNT - 1], [0.0; 3]));
                *entry = (probe, rows.len() as u32 - 1);
            }
            entry.1
        } else {
            let key = (far.key(&hits[i], level), level);
            *coarse.entry(key).or_insert_with(|| {
                rows.push((with_level(brick, level), 0, [0.0; SH_COUNT - 1], [0.0; 3]));
                rows.len() as u32 - 1
            })
        };
        let row = &mut rows[at as usize];
        let y = &basis[ray];
        row.1 += 1;
        row.3 = (Vec3::from(row.3) + hits[i].position).to_array();
        for k in 1..SH_COUNT {
            row.2[k - 1] += weight * y[k];
        }
    }
    ProbeRows::of(rows, precision, basis.len() as u32)
}

/// Where a row of sums keeps its level ([`crate::merge::coarse`]) above its provisional brick:
/// far hits go to coarse bricks only in merged bakes, whose provisional bricks are below
/// [`crate::merge::index::MAX_BRICKS`], 2^28 (an unmerged bake's use all 32 bits and carry no
/// level: [`Placement::sums_brick`]).
const LEVEL_SHIFT: u32 = 28;
const BRICK_BITS: u32 = (1 << LEVEL_SHIFT) - 1;

/// A provisional brick with a row's level.
fn with_level(brick: u32, level: u32) -> u32 {
    debug_assert!(brick <= BRICK_BITS && level < 16);
    brick | level << LEVEL_SHIFT
}

/// A row's provisional brick and level.
fn brick_and_level(word: u32) -> (usize, u32) {
    ((word & BRICK_BITS) as usize, word >> LEVEL_SHIFT)
}

/// Per provisional brick of the probe being grouped ([`probe_rows`]), counted from the
/// probe's lowest, its row: an entry is that probe's only if it carries the probe's stamp, so
/// nothing is cleared between probes. One table per thread, as long as the widest span of
/// bricks one probe hit: 8 bytes a brick when merging (a probe sees bricks made by the first
/// probes and by itself, a few MB), one entry per ray unmerged (each hit a brick of its own,
/// numbered together). Cheaper than a hash map from brick to row made for every probe.
#[derive(Default)]
pub struct RowTable {
    /// The stamp of the probe being grouped (0: none yet).
    probe: u32,
    /// Per brick (less the probe's lowest): the stamp of the last probe that hit it, and its
    /// row there.
    rows: Vec<(u32, u32)>,
}

impl RowTable {
    /// A new probe's stamp, with room for `span` bricks.
    fn next_probe(&mut self, span: usize) -> u32 {
        if self.rows.len() < span {
            self.rows.resize(span, (0, 0));
        }
        self.probe = self.probe.wrapping_add(1);
        if self.probe == 0 {
            // Once every 2^32 probes: stamps restart, so old entries must go.
            self.rows.fill((0, 0));
            self.probe = 1;
        }
        self.probe
    }
}

/// One probe's factor rows while bricks are provisional, as close to their final form as that
/// allows: f32 sums for f32 and f16 tables (the last field the sum of the rays' hit points until
/// `finish` turns it into the offset); for u8 tables, the transfer already encoded (rows of
/// more than 255 rays split) beside the rays' mean hit point, 28 bytes a row against 52: the
/// rows are the largest thing the bake holds.
pub enum ProbeRows {
    Sums(Vec<FactorRow>),
    U8(Vec<RowU8>),
}

/// A u8 factor waiting for its brick's final number and centroid, in 28 bytes: the provisional
/// brick waits in the factor's own brick field, which [`FactorU8::place`] overwrites (a row
/// beside it took 32 bytes; the rows are the bake's largest working set). A provisional brick
/// past [`U8_MAX_BRICK`] loses its high bits here, but such a bake is refused before
/// `encode_u8` reads them (`pipeline::bricks_and_tables`; provisional and final bricks are as
/// many).
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct RowU8 {
    /// Transfer and rays ([`FactorU8::transfer`]), provisional brick in the brick bits.
    factor: FactorU8,
    /// Mean hit point of the row's rays (all of them, before a split).
    mean: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<RowU8>() == 28);

impl RowU8 {
    /// `word`: the provisional brick and level ([`with_level`]). The level waits in the
    /// factor's last byte, which the encoding leaves zero ([`FactorU8`]).
    fn new(word: u32, factor: FactorU8, mean: Vec3) -> Self {
        let (brick, level) = brick_and_level(word);
        let mut packed = factor.packed;
        packed[2] |= level << 24;
        let factor = FactorU8 {
            brick_rays: factor.brick_rays | (brick as u32) << 8,
            packed,
        };
        RowU8 {
            factor,
            mean: mean.to_array(),
        }
    }

    /// The provisional brick.
    fn brick(&self) -> usize {
        (self.factor.brick_rays >> 8) as usize
    }

    /// The row's level ([`crate::merge::coarse`]).
    fn level(&self) -> u32 {
        self.factor.packed[2] >> 24
    }

    /// The factor without the level.
    fn factor(&self) -> FactorU8 {
        let mut f = self.factor;
        f.packed[2] &= 0x00ff_ffff;
        f
    }
}

impl ProbeRows {
    /// The provisional brick and level of each of its far rows (level 1 and up).
    pub fn far_rows(&self) -> Vec<(usize, u32)> {
        let all: Vec<(usize, u32)> = match self {
            ProbeRows::Sums(rows) => rows.iter().map(|r| brick_and_level(r.0)).collect(),
            ProbeRows::U8(rows) => rows.iter().map(|r| (r.brick(), r.level())).collect(),
        };
        all.into_iter().filter(|&(_, level)| level > 0).collect()
    }

    /// No rows yet, kept as `precision` keeps them.
    pub fn new(precision: TransferPrecision) -> Self {
        match precision {
            TransferPrecision::U8 => ProbeRows::U8(Vec::new()),
            _ => ProbeRows::Sums(Vec::new()),
        }
    }

    /// A probe's finished rows (brick, rays, transfer sums, hit point sum: those of
    /// [`probe_rows`]) of a lattice of `ray_count` rays, kept as `precision` keeps them: sums
    /// as they are; u8 rows encoded ([`push_u8`]) into a vector with room for one factor a row
    /// (more only when a row passes 255 rays and is split).
    fn of(rows: Vec<FactorRow>, precision: TransferPrecision, ray_count: u32) -> Self {
        match precision {
            TransferPrecision::U8 => {
                let dc_per_ray = FactorU8::dc_per_ray(ray_count);
                let mut kept = Vec::with_capacity(rows.len());
                for row in rows {
                    push_u8(&mut kept, row, dc_per_ray);
                }
                ProbeRows::U8(kept)
            }
            _ => ProbeRows::Sums(rows),
        }
    }
}

/// Encodes a finished row ([`ProbeRows::of`]) into `rows`, split into rows of at most
/// [`U8_MAX_RAYS`] rays, for a lattice whose rays carry `dc_per_ray` ([`FactorU8::dc_per_ray`]:
/// worked out once per probe, an f64 division a row otherwise).
fn push_u8(rows: &mut Vec<RowU8>, row: FactorRow, dc_per_ray: f32) {
    let (brick, rays, sh, sum) = row;
    let mean = Vec3::from(sum) / rays as f32;
    for (_, part, sh, _) in split_row_for_u8((brick, rays, sh, mean.to_array())) {
        let factor = FactorU8::transfer_with(part, sh, dc_per_ray);
        rows.push(RowU8::new(brick, factor, mean));
    }
}

/// Every probe's factor rows, probe after probe, kept as `precision` keeps them
/// ([`ProbeRows`]), in memory up to a budget and in a temporary file past it ([`RowStore`]).
/// Each probe's rows are grouped into a vector of their own in parallel ([`probe_rows`]), then
/// copied here in probe order.
pub enum Rows {
    Sums(RowStore<RowSums>),
    U8(RowStore<RowU8>),
}

/// A row of sums ([`FactorRow`]) as words, for the row store's file: brick, rays, the 8
/// transfer sums' bits, the hit point sum's bits.
type RowSums = [u32; 13];

fn to_words(r: &FactorRow) -> RowSums {
    let mut w = [0; 13];
    w[0] = r.0;
    w[1] = r.1;
    for k in 0..8 {
        w[2 + k] = r.2[k].to_bits();
    }
    for a in 0..3 {
        w[10 + a] = r.3[a].to_bits();
    }
    w
}

fn from_words(w: &RowSums) -> FactorRow {
    (
        w[0],
        w[1],
        std::array::from_fn(|k| f32::from_bits(w[2 + k])),
        std::array::from_fn(|a| f32::from_bits(w[10 + a])),
    )
}

impl Rows {
    /// No probes yet; their rows kept as `precision` keeps them, in memory up to about
    /// `budget` bytes ([`RowStore::new`]).
    pub fn new(precision: TransferPrecision, budget: usize) -> Self {
        match precision {
            TransferPrecision::U8 => Rows::U8(RowStore::new(budget)),
            _ => Rows::Sums(RowStore::new(budget)),
        }
    }

    /// [`Rows::new`] with chunks of `chunk_bytes` ([`RowStore::in_chunks_of`]).
    #[cfg(test)]
    fn in_chunks_of(precision: TransferPrecision, chunk_bytes: usize, budget: usize) -> Self {
        match precision {
            TransferPrecision::U8 => Rows::U8(RowStore::in_chunks_of(chunk_bytes, budget)),
            _ => Rows::Sums(RowStore::in_chunks_of(chunk_bytes, budget)),
        }
    }

    /// Appends the next probe's rows; fails when rows past the budget cannot be written to
    /// the temporary file.
    pub fn push(&mut self, rows: &ProbeRows) -> Result<(), BakeError> {
        match (self, rows) {
            (Rows::U8(all), ProbeRows::U8(rows)) => all.push(rows),
            (Rows::Sums(all), ProbeRows::Sums(rows)) => {
                all.push(&rows.iter().map(to_words).collect::<Vec<_>>())
            }
            _ => unreachable!("a bake keeps all its rows in one form"),
        }
    }

    /// Factors probe `p`'s table will have.
    pub(crate) fn len(&self, p: usize) -> usize {
        match self {
            Rows::Sums(all) => all.len(p),
            Rows::U8(all) => all.len(p),
        }
    }

    /// All rows are in ([`RowStore::end`]).
    pub fn end(&mut self) -> Result<(), BakeError> {
        match self {
            Rows::Sums(all) => all.end(),
            Rows::U8(all) => all.end(),
        }
    }

    /// Bytes of rows written to the temporary file.
    pub fn spilled_bytes(&self) -> u64 {
        match self {
            Rows::Sums(all) => all.spilled_bytes(),
            Rows::U8(all) => all.spilled_bytes(),
        }
    }
}

/// Per provisional brick: its final number and its centroid, side by side so that a factor
/// finds both in one load, where the renumbering and then the bricks cost two cache misses.
type Placed = (u32, Vec3);

/// Where rows go once bricks are numbered: level-0 rows to their brick ([`Placed`]), far rows
/// to the brick or coarse brick over it ([`CoarsePlacement`]).
#[derive(Clone, Copy)]
struct Placement<'a> {
    placed: &'a [Placed],
    coarse: &'a CoarsePlacement,
}

impl Placement<'_> {
    /// The final brick or coarse brick of a row of provisional brick `brick` at `level`, the
    /// point its offset is measured from and what it is divided by.
    #[inline]
    fn locate(&self, brick: usize, level: u32) -> (u32, Vec3, f32) {
        let (b, centroid) = self.placed[brick];
        self.coarse.place(b, level).unwrap_or((b, centroid, 1.0))
    }

    /// A row of sums' provisional brick and level: the word as it is unless rows carry
    /// levels (an unmerged bake's provisional bricks use all 32 bits).
    #[inline]
    fn sums_brick(&self, word: u32) -> (usize, u32) {
        match self.coarse.has_levels() {
            true => brick_and_level(word),
            false => (word as usize, 0),
        }
    }
}

/// u8 rows encoded into `out` (one factor each): bricks renumbered, offsets from the bricks'
/// centroids, sorted by brick (a split row's parts in order).
fn encode_u8(rows: &[RowU8], out: &mut [FactorU8], at: Placement, offset_scale: f32) {
    debug_assert!(
        at.placed.len() <= U8_MAX_BRICK as usize + 1,
        "every provisional brick fits the row's brick field"
    );
    // By brick; a split row's parts full ones first, as they were split: the key is the final
    // brick above the rays' complement. The rows are sorted as integers, key above row index
    // (distinct, so any sort gives one order), then placed in that order: cheaper than sorting
    // the 16-byte factors by their key. A brick has several factors when a row was split, and
    // with coarse bricks also when a near row and a far row, or far rows of two levels, end on
    // the same brick or coarse brick (a coarse cell of one brick is that brick); equal keys then
    // keep the rows' order.
    const _: () = assert!(U8_MAX_RAYS == 0xff);
    prefetch_placed(rows.iter().map(RowU8::brick), at.placed);
    let located: Vec<(u32, Vec3, f32)> = rows
        .iter()
        .map(|r| at.locate(r.brick(), r.level()))
        .collect();
    let mut order: Vec<u64> = rows
        .iter()
        .zip(&located)
        .enumerate()
        .map(|(i, (r, &(b, _, _)))| {
            let key = (b << 8 | r.factor.brick_rays & U8_MAX_RAYS) ^ U8_MAX_RAYS;
            u64::from(key) << 32 | i as u64
        })
        .collect();
    order.sort_unstable();
    for (f, &o) in out.iter_mut().zip(&order) {
        let i = o as u32 as usize;
        let (r, (b, centroid, scale)) = (&rows[i], located[i]);
        let offset = (Vec3::from(r.mean) - centroid) / scale;
        *f = r.factor().place(b, offset.to_array(), offset_scale);
    }
}

/// How the asset's factor table is laid out: per probe, whose table it carries (its own, a
/// dilation source's, or none), and how many factors that is.
#[derive(Clone, Copy)]
pub struct Carried<'a> {
    pub from: &'a [Option<usize>],
    pub lens: &'a [usize],
}

/// The asset's factor table, every carried table put in its place in probe order: tables in
/// parallel, each encoded straight into its place,
/// a dilated probe's copied from its source's, an invalid probe's rows dropped unencoded (a
/// table per probe, joined, would copy every factor once more). Fails when rows in the
/// temporary file cannot be read back ([`RowStore`]).
pub fn encode_tables(
    rows: Rows,
    carried: Carried,
    (remap, bricks, coarse): (&[u32], &[Brick], &CoarsePlacement),
    (precision, brick_size): (TransferPrecision, f32),
) -> Result<Factors, BakeError> {
    let placed: Vec<Placed> = remap
        .par_iter()
        .map(|&b| (b, Vec3::from(bricks[b as usize].centroid)))
        .collect();
    let placed = Placement {
        placed: &placed,
        coarse,
    };
    Ok(match (precision, rows) {
        (TransferPrecision::U8, Rows::U8(rows)) => {
            let offset_scale = u8_offset_scale(brick_size);
            let factors = place_tables(rows, carried, |rows, out| {
                encode_u8(rows, out, placed, offset_scale)
            })?;
            Factors::U8 {
                factors,
                offset_scale,
            }
        }
        (TransferPrecision::F16, Rows::Sums(rows)) => {
            Factors::F16(place_tables(rows, carried, |rows, out| {
                encode_sums(rows, out, placed, FactorF16::of)
            })?)
        }
        (TransferPrecision::F32, Rows::Sums(rows)) => {
            Factors::F32(place_tables(rows, carried, |rows, out| {
                encode_sums(rows, out, placed, FactorF32::of)
            })?)
        }
        _ => unreachable!("u8 rows are kept as u8, f16 and f32 rows as sums"),
    })
}

/// [`encode_tables`] for one factor type: `encode` fills a probe's place from its rows. Chunk
/// by chunk, its probes in parallel, then the chunk freed ([`RowStore::drain`]).
fn place_tables<R: Pod + Sync + Send, T: bytemuck::Zeroable + Copy + Send + Sync>(
    rows: RowStore<R>,
    carried: Carried,
    encode: impl Fn(&[R], &mut [T]) + Sync,
) -> Result<Vec<T>, BakeError> {
    debug_assert_eq!(
        rows.probe_count(),
        carried.from.len(),
        "a row entry per probe"
    );
    let mut out: Vec<T> = bytemuck::zeroed_vec(carried.lens.iter().sum());
    let places = crate::memory::split_runs(&mut out, carried.lens);
    let starts: Vec<usize> = places.iter().map(|&(start, _)| start).collect();
    let mut places = places.into_iter();
    rows.drain(|first, runs, chunk| {
        let these: Vec<_> = places.by_ref().take(runs.len()).collect();
        these
            .into_par_iter()
            .zip(runs)
            .enumerate()
            .for_each(|(i, ((_, place), &(start, len)))| {
                let p = first + i;
                if carried.from[p] == Some(p) {
                    encode(&chunk[start..start + len], place);
                }
            });
    })?;
    drop(places);
    for (p, from) in carried.from.iter().enumerate() {
        if let Some(q) = from.filter(|&q| q != p) {
            debug_assert_eq!(
                carried.from[q],
                Some(q),
                "a dilation source carries its own table"
            );
            out.copy_within(starts[q]..starts[q] + carried.lens[q], starts[p]);
        }
    }
    Ok(out)
}

/// Asks for the [`Placed`] entries of the provisional bricks `bricks` (one probe's rows) before
/// any is read: a probe's bricks are scattered over the table, a cache miss each, and the
/// loads that follow do not wait for one another once the lines are on their way. Rows of
/// sums (f16 and f32 tables) read the same table the same way.
fn prefetch_placed(bricks: impl Iterator<Item = usize>, placed: &[Placed]) {
    for b in bricks {
        if let Some(p) = placed.get(b) {
            crate::memory::prefetch(p);
        }
    }
}

/// Rows of sums finished ([`finish`]) and encoded into `out` by `of`, one factor each.
fn encode_sums<T>(rows: &[RowSums], out: &mut [T], at: Placement, of: fn(&FactorRow) -> T) {
    prefetch_placed(rows.iter().map(|w| at.sums_brick(w[0]).0), at.placed);
    let mut rows: Vec<FactorRow> = rows.iter().map(from_words).collect();
    finish(&mut rows, at);
    for (f, row) in out.iter_mut().zip(&rows) {
        *f = of(row);
    }
}

/// The final rows of one probe, sorted by brick: provisional bricks renumbered ([`Placed`]), hit
/// sums turned into offsets, the mean of the rays' hit points minus the brick's centroid (see
/// `prt_format::FactorF32`).
fn finish(rows: &mut [FactorRow], at: Placement) {
    for row in rows.iter_mut() {
        let (brick, level) = at.sums_brick(row.0);
        let (b, centroid, scale) = at.locate(brick, level);
        row.0 = b;
        row.3 = ((Vec3::from(row.3) / row.1 as f32 - centroid) / scale).to_array();
    }
    rows.sort_unstable_by_key(|r| r.0);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A placement without coarse bricks.
    fn no_coarse() -> CoarsePlacement {
        crate::merge::coarse::build(&[], &[], (0, &[])).1
    }

    /// Far hits of one coarse cell make one row, which reads the coarse brick over their bricks
    /// with its offset from the coarse brick's centroid divided by 2^level, in every encoding;
    /// near hits keep their bricks.
    #[test]
    fn far_hits_share_a_coarse_row() {
        use crate::merge::fold::BrickFit;
        use glam::{DMat3, DVec3};
        let n = 64usize;
        let basis: Vec<[f32; SH_COUNT]> = (0..n)
            .map(|r| prt_format::sh::basis([0.0, 1.0, 0.0]).map(|y| y * (1.0 + r as f32 * 0.01)))
            .collect();
        // Bricks of 1 m from the origin; hits at 0.5, 1.5 (level 0) and 10.5, 11.5 m (level 1
        // from 8 m: one coarse cell).
        let xs = [0.5f32, 1.5, 10.5, 11.5];
        let hits: Vec<Hit> = xs
            .iter()
            .enumerate()
            .map(|(i, &x)| Hit::grey(i as u32 * 3, Vec3::new(x, 0.5, 0.5), Vec3::Y))
            .collect();
        let far = FarField {
            origin: Vec3::new(0.0, 0.5, 0.5),
            anchor: Vec3::ZERO,
            brick_size: 1.0,
            near: 8.0,
        };
        let keys: Vec<Key> = xs.iter().map(|&x| (x as i32, 0, 0, 2)).collect();
        let weights = [1.0, 1.0, 1.0, 3.0];
        let fits: Vec<BrickFit> = xs
            .iter()
            .zip(weights)
            .map(|(&x, weight)| BrickFit {
                weight,
                centroid: DVec3::new(f64::from(x), 0.5, 0.5),
                moment: DMat3::ZERO,
            })
            .collect();
        let bricks: Vec<Brick> = xs
            .iter()
            .map(|&x| Brick {
                centroid: [x, 0.5, 0.5],
                ..Brick::default()
            })
            .collect();
        let remap = [0u32, 1, 2, 3];
        let (coarse, placement) =
            crate::merge::coarse::build(&keys, &fits, (1, &[0, 0, 1 << 1, 0]));
        assert_eq!(coarse.children, [2, 3]);
        let centroid = (10.5 + 3.0 * 11.5) / 4.0;
        for precision in [TransferPrecision::F32, TransferPrecision::U8] {
            let probe = probe_rows(
                &hits,
                &[0, 1, 2, 3],
                (&basis, 0.1),
                &far,
                precision,
                &mut RowTable::default(),
            );
            assert_eq!(probe.far_rows(), [(2, 1)]);
            let mut rows = Rows::new(precision, usize::MAX);
            rows.push(&probe).unwrap();
            let carried = Carried {
                from: &[Some(0)],
                lens: &[rows.len(0)],
            };
            let numbering = (&remap[..], &bricks[..], &placement);
            let factors = encode_tables(rows, carried, numbering, (precision, 1.0)).unwrap();
            assert_eq!(factors.len(), 3, "{precision:?}");
            let (b, rays) = factors.brick_and_rays(2);
            assert_eq!(
                (b, rays),
                (4, 2),
                "{precision:?}: the coarse brick, after the 4"
            );
            let offset = factors.offset(2);
            let want = (11.0 - centroid) / 2.0;
            assert!((offset[0] - want).abs() < 1e-2, "{precision:?}: {offset:?}");
            assert_eq!(factors.brick_and_rays(0), (0, 1));
            assert_eq!(factors.offset(0), [0.0; 3]);
        }
    }

    /// Rows equal those of the sort by (brick, ray) that grouping by a map replaced, sums bit
    /// for bit: hits in a shuffled ray order, on bricks that recur far apart.
    #[test]
    fn rows_sum_rays_in_lattice_order_per_brick() {
        let n = 512usize;
        let basis: Vec<[f32; SH_COUNT]> = (0..n)
            .map(|r| std::array::from_fn(|k| ((r * 7 + k * 13) % 17) as f32 * 0.1 - 0.8))
            .collect();
        let mut state = 0x9e37_79b9u32;
        let mut next = |m: u32| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state % m
        };
        let mut rays: Vec<u32> = (0..n as u32).filter(|r| r % 5 != 0).collect();
        for i in (1..rays.len()).rev() {
            rays.swap(i, next(i as u32 + 1) as usize);
        }
        let hits: Vec<Hit> = rays
            .iter()
            .map(|&ray| {
                let position = Vec3::new(next(1000) as f32 * 0.01, 0.3, -(ray as f32) * 0.001);
                Hit::grey(ray, position, Vec3::Y)
            })
            .collect();
        let bricks: Vec<u32> = hits.iter().map(|_| next(40) * 3).collect();
        let weight = 4.0 * std::f32::consts::PI / n as f32;
        let ProbeRows::Sums(mut got) = probe_rows(
            &hits,
            &bricks,
            (&basis, weight),
            &FarField::off(),
            TransferPrecision::F32,
            &mut RowTable::default(),
        ) else {
            panic!("f32 rows are sums");
        };
        got.sort_by_key(|r| r.0);
        let mut order: Vec<usize> = (0..hits.len()).collect();
        order.sort_by_key(|&i| (bricks[i], hits[i].ray));
        let mut want: Vec<FactorRow> = Vec::new();
        for i in order {
            if want.last().is_none_or(|r| r.0 != bricks[i]) {
                want.push((bricks[i], 0, [0.0; SH_COUNT - 1], [0.0; 3]));
            }
            let row = want.last_mut().unwrap();
            row.1 += 1;
            row.3 = (Vec3::from(row.3) + hits[i].position).to_array();
            for k in 1..SH_COUNT {
                row.2[k - 1] += weight * basis[hits[i].ray as usize][k];
            }
        }
        let bits = |rows: &[FactorRow]| -> Vec<u32> {
            rows.iter()
                .flat_map(|r| {
                    [r.0, r.1]
                        .into_iter()
                        .chain(r.2.map(f32::to_bits))
                        .chain(r.3.map(f32::to_bits))
                })
                .collect()
        };
        assert_eq!(want.len(), got.len());
        assert_eq!(bits(&got), bits(&want));
    }

    /// The table is each carried probe's own table, encoded alone, in probe order, whatever
    /// the chunks and whether they went through the temporary file: probes of no rows before
    /// any chunk, a probe larger than a chunk, a dilated probe and an invalid one, in chunks
    /// of one row with no budget (a chunk per probe, every one through the file), of 1,000
    /// bytes with a budget of one chunk (through the file) and of all of them (held), and in
    /// chunks of 64 MiB; and no rows at all.
    #[test]
    fn chunks_do_not_change_the_table() {
        let bricks: Vec<Brick> = (0..40)
            .map(|i| Brick {
                centroid: [0.1 * i as f32, 0.5, -0.2],
                ..Brick::default()
            })
            .collect();
        let remap: Vec<u32> = (0..40).map(|i| (i * 7) % 40).collect();
        let probe = |p: usize, rows: usize, precision| {
            let rows = (0..rows)
                .map(|r| {
                    let brick = ((p * 13 + r * 7) % 40) as u32;
                    let rays = 1 + ((p + r) % 300) as u32;
                    let sh = std::array::from_fn(|k| (k as f32 - 3.0) * 0.002 * rays as f32);
                    (brick, rays, sh, [0.1 * rays as f32, 0.0, 0.3])
                })
                .collect();
            ProbeRows::of(rows, precision, 4096)
        };
        let from = [0, 1, 2, 3, 4, 5, 6, 7, 8].map(|p| match p {
            6 => Some(3),
            7 => None,
            p => Some(p),
        });
        let encode = |sizes: &[usize], from: &[Option<usize>], (chunk, budget), precision| {
            let mut rows = Rows::in_chunks_of(precision, chunk, budget);
            for (p, &n) in sizes.iter().enumerate() {
                rows.push(&probe(p, n, precision)).unwrap();
            }
            let spilled = rows.spilled_bytes() > 0;
            assert_eq!(spilled, budget < 10_000 && sizes.iter().sum::<usize>() > 0);
            let lens: Vec<usize> = from.iter().map(|f| f.map_or(0, |q| rows.len(q))).collect();
            let carried = Carried { from, lens: &lens };
            let numbering = (&remap[..], &bricks[..], &no_coarse());
            encode_tables(rows, carried, numbering, (precision, 0.5)).unwrap()
        };
        let bytes = |f: &Factors| -> Vec<u8> {
            match f {
                Factors::U8 { factors, .. } => bytemuck::cast_slice(factors).to_vec(),
                Factors::F16(v) => bytemuck::cast_slice(v).to_vec(),
                Factors::F32(v) => bytemuck::cast_slice(v).to_vec(),
            }
        };
        let sizes = [0, 0, 3, 17, 90, 0, 5, 40, 2];
        for precision in [TransferPrecision::U8, TransferPrecision::F16] {
            let mut alone = Vec::new();
            for q in from.iter().flatten() {
                let mut one = vec![0; sizes.len()];
                one[*q] = sizes[*q];
                let mut only = vec![None; sizes.len()];
                only[*q] = Some(*q);
                alone.extend(bytes(&encode(
                    &one,
                    &only,
                    (1 << 26, usize::MAX),
                    precision,
                )));
            }
            for (chunk, budget) in [(1, 0), (1000, 1000), (1000, usize::MAX), (1 << 26, 1 << 26)] {
                let table = encode(&sizes, &from, (chunk, budget), precision);
                assert!(!table.is_empty());
                let what = format!("{precision:?}, chunks of {chunk} bytes, budget {budget}");
                assert_eq!(bytes(&table), alone, "{what}");
            }
            let none = encode(&[0; 9], &from, (1000, 1000), precision);
            assert!(none.is_empty());
        }
    }

    /// One table grouping probe after probe, its stamps wrapping around, gives the rows that a
    /// fresh table gives each probe.
    #[test]
    fn row_table_stamps_keep_probes_apart() {
        let basis: Vec<[f32; SH_COUNT]> = (0..64)
            .map(|r| std::array::from_fn(|k| ((r + k) % 5) as f32 * 0.1))
            .collect();
        let hit = |ray: u32| Hit::grey(ray, Vec3::new(ray as f32, 0.0, 1.0), Vec3::Y);
        let probes: Vec<(Vec<Hit>, Vec<u32>)> = (0..4)
            .map(|p| {
                let hits: Vec<Hit> = (0..64).filter(|r| (r + p) % 3 != 0).map(hit).collect();
                let bricks = hits.iter().map(|h| 100 + (h.ray * (p + 1)) % 9).collect();
                (hits, bricks)
            })
            .collect();
        let rows = |hits: &[Hit], bricks: &[u32], table: &mut RowTable| match probe_rows(
            hits,
            bricks,
            (&basis, 0.2),
            &FarField::off(),
            TransferPrecision::F32,
            table,
        ) {
            ProbeRows::Sums(rows) => rows,
            ProbeRows::U8(_) => unreachable!("f32 rows are sums"),
        };
        let mut shared = RowTable {
            probe: u32::MAX - 1,
            ..RowTable::default()
        };
        for (hits, bricks) in &probes {
            let fresh = rows(hits, bricks, &mut RowTable::default());
            assert_eq!(rows(hits, bricks, &mut shared), fresh);
        }
        assert_eq!(
            shared.probe, 3,
            "stamps wrapped past u32::MAX and restarted at 1"
        );
    }

    /// Rows encoded as u8 while bricks are provisional give the table that finishing the f32
    /// sums, splitting them and encoding them at the end gives, byte for byte.
    #[test]
    fn early_u8_rows_encode_as_late_ones() {
        let rows: Vec<FactorRow> = [(2u32, 600u32), (0, 3), (1, 255), (3, 256)]
            .iter()
            .map(|&(brick, rays)| {
                let sh = std::array::from_fn(|k| (k as f32 - 3.5) * 0.01 * rays as f32);
                let sum = [0.3 * rays as f32, -1.7 * rays as f32, 0.05 * rays as f32];
                (brick, rays, sh, sum)
            })
            .collect();
        let remap = [3, 0, 2, 1];
        let bricks: Vec<Brick> = (0..4)
            .map(|i| Brick {
                centroid: [0.25 * i as f32, -1.6, 0.1],
                ..Brick::default()
            })
            .collect();
        let (n, size) = (4096, 0.5);
        let mut late = rows.clone();
        let placed: Vec<Placed> = remap
            .iter()
            .map(|&b| (b, Vec3::from(bricks[b as usize].centroid)))
            .collect();
        let coarse = no_coarse();
        let at = Placement {
            placed: &placed,
            coarse: &coarse,
        };
        finish(&mut late, at);
        let late: Vec<FactorRow> = late.into_iter().flat_map(split_row_for_u8).collect();
        let late = Factors::build(&late, TransferPrecision::U8, n, size);
        let early = ProbeRows::of(rows, TransferPrecision::U8, n);
        let mut rows = Rows::new(TransferPrecision::U8, usize::MAX);
        rows.push(&early).unwrap();
        let carried = Carried {
            from: &[Some(0)],
            lens: &[rows.len(0)],
        };
        let settings = (TransferPrecision::U8, size);
        let numbering = (&remap[..], &bricks[..], &coarse);
        let early = encode_tables(rows, carried, numbering, settings).unwrap();
        assert_eq!(early.len(), 7, "600 and 256 rays split in three and two");
        assert_eq!(early, late);
    }
}
