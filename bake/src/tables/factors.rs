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
use prt_format::{split_row_for_u8, FactorRow, FactorU8, TransferPrecision};

use std::collections::HashMap;

use foldhash::fast::FixedState;

use crate::merge::coarse::{cell, FarField};
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
    // Per row: its index, its first hit's brick key and the lowest level whose cell holds all
    // its hits so far.
    let mut coarse: HashMap<(Key, u32), (u32, Key, u32), FixedState> = HashMap::default();
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
            let fine = far.key(&hits[i], 0);
            let (at, first, need) = coarse.entry((cell(fine, level), level)).or_insert_with(|| {
                rows.push((with_level(brick, level), 0, [0.0; SH_COUNT - 1], [0.0; 3]));
                (rows.len() as u32 - 1, fine, 1)
            });
            *need = (*need).max(common_level(*first, fine));
            *at
        };
        let row = &mut rows[at as usize];
        let y = &basis[ray];
        row.1 += 1;
        row.3 = (Vec3::from(row.3) + hits[i].position).to_array();
        for k in 1..SH_COUNT {
            row.2[k - 1] += weight * y[k];
        }
    }
    // A far row reads the smallest coarse cell that holds all its hits, not its distance's:
    // rows are one per cell of the distance's level, but a row whose rays all land in a
    // corner of that cell (a floor seen through a door, the edge of a spotlight's pool) read
    // a fit over the whole cell, lit parts and dark alike. The same rows (the bytes move only
    // with the u8 slots' scales and the coarse bricks made: Cornell -0.1%); on a level nobody
    // had tuned on (`interior_52`, stop 53), 27.7% -> 23.3% open mean, the dark room's probes
    // nearer those of a bake without coarse bricks. At least level 1: a row whose hits share
    // one brick key may span the parts of a brick split at a wall (`crate::merge::split`),
    // which its first hit's brick alone would not stand for.
    // (Each entry rewrites its own row: the map's order does not matter.)
    for &(at, _, need) in coarse.values() {
        let (brick, level) = brick_and_level(rows[at as usize].0);
        debug_assert!(need <= level, "the hits share their distance's cell");
        rows[at as usize].0 = with_level(brick as u32, need);
    }
    ProbeRows::of(rows, precision, basis.len() as u32)
}

/// The lowest level (at least 1) whose coarse cell holds bricks `a` and `b` of one normal key:
/// the cells of level `l` are the keys shifted right by `l` ([`cell`]), which agree exactly
/// when the keys' bits from `l` up do.
fn common_level(a: Key, b: Key) -> u32 {
    let differ = ((a.0 ^ b.0) | (a.1 ^ b.1) | (a.2 ^ b.2)) as u32;
    (u32::BITS - differ.leading_zeros()).max(1)
}

/// Where a row of sums keeps its level ([`crate::merge::coarse`]) above its provisional brick:
/// far hits go to coarse bricks only in merged bakes, whose provisional bricks are below
/// [`crate::merge::index::MAX_BRICKS`], 2^28 (an unmerged bake's use all 32 bits and carry no
/// level: `tables::encode::Placement::sums_brick`).
const LEVEL_SHIFT: u32 = 28;
const BRICK_BITS: u32 = (1 << LEVEL_SHIFT) - 1;

/// A provisional brick with a row's level.
fn with_level(brick: u32, level: u32) -> u32 {
    debug_assert!(brick <= BRICK_BITS && level < 16);
    brick | level << LEVEL_SHIFT
}

/// A row's provisional brick and level.
pub(crate) fn brick_and_level(word: u32) -> (usize, u32) {
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
/// brick waits in the factor's own brick field, which [`FactorU8::place`] overwrites (a row beside
/// it took 32 bytes; the rows are the bake's largest working set). A provisional brick past
/// [`prt_format::U8_MAX_BRICK`] loses its high bits here, but such a bake is refused before
/// `encode_u8` reads them (`pipeline::bricks::bricks_and_tables`; provisional and final bricks are
/// as many).
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct RowU8 {
    /// Transfer and rays ([`FactorU8::transfer`]), provisional brick in the brick bits.
    factor: FactorU8,
    /// Mean hit point of the row's rays (all of them, before a split).
    pub(crate) mean: [f32; 3],
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
    pub(crate) fn brick(&self) -> usize {
        (self.factor.brick_rays >> 8) as usize
    }

    /// The row's level ([`crate::merge::coarse`]).
    pub(crate) fn level(&self) -> u32 {
        self.factor.packed[2] >> 24
    }

    /// The factor without the level.
    pub(crate) fn factor(&self) -> FactorU8 {
        let mut f = self.factor;
        f.packed[2] &= 0x00ff_ffff;
        f
    }
}

impl ProbeRows {
    /// The provisional brick and level of each of its far rows (level 1 and up).
    pub fn far_rows(&self) -> Vec<(usize, u32)> {
        let far = |&(_, level): &(usize, u32)| level > 0;
        match self {
            ProbeRows::Sums(rows) => rows
                .iter()
                .map(|r| brick_and_level(r.0))
                .filter(far)
                .collect(),
            ProbeRows::U8(rows) => rows
                .iter()
                .map(|r| (r.brick(), r.level()))
                .filter(far)
                .collect(),
        }
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
    pub(crate) fn of(rows: Vec<FactorRow>, precision: TransferPrecision, ray_count: u32) -> Self {
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
/// [`prt_format::U8_MAX_RAYS`] rays, for a lattice whose rays carry `dc_per_ray`
/// ([`FactorU8::dc_per_ray`]: worked out once per probe, an f64 division a row otherwise).
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
pub(crate) type RowSums = [u32; 13];

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

pub(crate) fn from_words(w: &RowSums) -> FactorRow {
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
    pub(crate) fn in_chunks_of(
        precision: TransferPrecision,
        chunk_bytes: usize,
        budget: usize,
    ) -> Self {
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

#[cfg(test)]
mod tests {
    use super::*;

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

    /// A far row's level is the lowest whose cell holds all its hits (at least 1), whatever
    /// level its distance gave it: hits 20 and 21 brick sizes away (level 2 from 8 bricks)
    /// share a level-1 cell; hits at 16 and 19 need the level-2 cell; one at 24 is a row of
    /// its own level-2 cell, alone in it.
    #[test]
    fn a_far_row_reads_the_smallest_cell_that_holds_its_hits() {
        let basis: Vec<[f32; SH_COUNT]> = vec![[0.1; SH_COUNT]; 8];
        let far = FarField {
            origin: Vec3::new(0.0, 0.5, 0.5),
            anchor: Vec3::ZERO,
            brick_size: 1.0,
            near: 8.0,
        };
        let levels = |xs: &[f32]| {
            let hits: Vec<Hit> = (xs.iter().enumerate())
                .map(|(i, &x)| Hit::grey(i as u32, Vec3::new(x, 0.5, 0.5), Vec3::Y))
                .collect();
            let bricks: Vec<u32> = xs.iter().map(|&x| x as u32).collect();
            let rows = probe_rows(
                &hits,
                &bricks,
                (&basis, 0.1),
                &far,
                TransferPrecision::F32,
                &mut RowTable::default(),
            );
            rows.far_rows()
        };
        assert_eq!(levels(&[20.5, 21.5]), [(20, 1)]);
        assert_eq!(levels(&[16.5, 19.5]), [(16, 2)]);
        assert_eq!(levels(&[16.5, 24.5, 19.5]), [(16, 2), (24, 1)]);
        assert_eq!(
            common_level((-1, 0, 0, 2), (0, 0, 0, 2)),
            32,
            "cells meet at the origin"
        );
        assert_eq!(common_level((5, 9, -3, 2), (5, 9, -3, 2)), 1);
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
}
