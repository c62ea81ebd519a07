//! Encoding the factor tables once bricks are numbered: every probe's rows read back (from
//! memory or the temporary file, [`crate::tables::row_store`]), their provisional bricks (and,
//! for far rows, coarse cells: [`crate::merge::coarse`]) renumbered, offsets taken from the
//! brick's centroid, and each table written straight into its place in the asset's table.

use bytemuck::Pod;
use glam::Vec3;
use prt_format::{
    u8_offset_scale, Brick, FactorF16, FactorF32, FactorRow, FactorSlot, Factors, LobeFrame,
    TransferPrecision, U8_MAX_BRICK, U8_MAX_RAYS,
};
use rayon::prelude::*;

use crate::merge::coarse::CoarsePlacement;
use crate::merge::split::FineParts;
use crate::tables::factors::{brick_and_level, from_words, RowSums, RowU8, Rows};
use crate::tables::row_store::RowStore;
use crate::BakeError;

/// Per provisional brick: its final number and its centroid, side by side so that a factor
/// finds both in one load, where the renumbering and then the bricks cost two cache misses.
type Placed = (u32, Vec3);

/// Where rows go once bricks are numbered: level-0 rows to their brick ([`Placed`]), far rows
/// to the brick or coarse brick over it ([`CoarsePlacement`]).
#[derive(Clone, Copy)]
struct Placement<'a> {
    placed: &'a [Placed],
    coarse: &'a CoarsePlacement,
    /// Where bricks were split ([`crate::merge::split`]): `placed` names a split brick's
    /// first part.
    parts: &'a FineParts,
    bricks: &'a [Brick],
}

impl Placement<'_> {
    /// The final brick or coarse brick of a row of provisional brick `brick` at `level` whose
    /// hits' mean is `mean`, the point its offset is measured from and what it is divided by.
    #[inline]
    fn locate(&self, brick: usize, level: u32, mean: Vec3) -> (u32, Vec3, f32) {
        let (b, centroid) = self.placed[brick];
        let (b, centroid) = match self.parts.is_split(b) {
            true => {
                let p = self.parts.part_after(b, mean, self.bricks);
                (p, Vec3::from(self.bricks[p as usize].centroid))
            }
            false => (b, centroid),
        };
        self.coarse
            .place(b, level, mean)
            .unwrap_or((b, centroid, 1.0))
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

/// u8 rows encoded and appended to `out`: bricks renumbered, offsets from the bricks'
/// centroids, sorted by brick (a split row's parts in order). Each is one lobe slot where the
/// lobe about the direction from `origin` (the probe's ray origin) to its mean hit point fits
/// its terms, else a full head and its continuation (`prt_format::FactorSlot`); without an
/// origin (a dilation source, whose table dilated probes elsewhere read) all are full.
fn encode_u8(
    rows: &[RowU8],
    out: &mut Vec<FactorSlot>,
    (at, offset_scale, project): (Placement, f32, bool),
    origin: Option<Vec3>,
) {
    debug_assert!(
        at.placed.len() <= U8_MAX_BRICK as usize + 1,
        "every provisional brick fits the row's brick field"
    );
    // By brick; a split row's parts full ones first, as they were split: the key is the final
    // brick above the rays' complement. The rows are sorted as integers, key above row index
    // (distinct, so any sort gives one order), then placed in that order: cheaper than sorting
    // the factors by their key. A brick has several factors when a row was split, and
    // with coarse bricks also when a near row and a far row, or far rows of two levels, end on
    // the same brick or coarse brick (a coarse cell of one brick is that brick); equal keys then
    // keep the rows' order.
    const _: () = assert!(U8_MAX_RAYS == 0xff);
    prefetch_placed(rows.iter().map(RowU8::brick), at.placed);
    let located: Vec<(u32, Vec3, f32)> = rows
        .iter()
        .map(|r| at.locate(r.brick(), r.level(), Vec3::from(r.mean)))
        .collect();
    let mut order: Vec<u64> = rows
        .iter()
        .zip(&located)
        .enumerate()
        .map(|(i, (r, &(b, _, _)))| {
            let key = (b << 8 | r.factor().brick_rays & U8_MAX_RAYS) ^ U8_MAX_RAYS;
            u64::from(key) << 32 | i as u64
        })
        .collect();
    order.sort_unstable();
    for &o in &order {
        let i = o as u32 as usize;
        let (r, (b, centroid, scale)) = (&rows[i], located[i]);
        let mean = Vec3::from(r.mean);
        let frame = |o: Vec3| LobeFrame {
            centroid: centroid.to_array(),
            offset_metres: offset_scale * scale,
            origin: o.to_array(),
        };
        let lobe = origin.and_then(|o| {
            lobe_head((r, mean), frame(o), project, |point| {
                let offset = (point - centroid) / scale;
                r.factor().place(b, offset.to_array(), offset_scale)
            })
        });
        if let Some(head) = lobe {
            out.push(head);
            continue;
        }
        let offset = (mean - centroid) / scale;
        let f = r.factor().place(b, offset.to_array(), offset_scale);
        let (head, rest) = FactorSlot::pack(&f, None);
        out.push(head);
        out.extend(rest);
    }
}

/// Row `r`'s lobe slot, if a lobe fits: its direction is decoded toward its stored point
/// (`place` puts the factor there), which is the mean hit point `mean` if the lobe toward it
/// fits, else, if `project`, the point of the rays' mean direction nearest it
/// (`prt_format::lobe`). An unmerged bake does not project: each of its factors is one hit,
/// already in its ray's direction, and its offsets are in metres, not in brick sizes.
fn lobe_head(
    (r, mean): (&RowU8, Vec3),
    frame: LobeFrame,
    project: bool,
    place: impl Fn(Vec3) -> prt_format::FactorU8,
) -> Option<FactorSlot> {
    let origin = Vec3::from(frame.origin);
    let d = Vec3::from(r.factor().mean_vector()).normalize_or_zero();
    let along = d.dot(mean - origin);
    let projected = (along > 0.0 && project).then_some(origin + d * along);
    std::iter::once(mean).chain(projected).find_map(|point| {
        match FactorSlot::pack(&place(point), Some(frame)) {
            (head, None) => Some(head),
            _ => None,
        }
    })
}

/// How the asset's factor table is laid out: per probe, whose table it reads (its own, a
/// dilation source's, or none), how many factors (rows) that is (a dilated probe's its
/// source's count, or 0 once encoded: [`own_lens`]), and where its rays started.
#[derive(Clone, Copy)]
pub struct Carried<'a> {
    pub from: &'a [Option<usize>],
    pub lens: &'a [usize],
    pub origins: &'a [Vec3],
}

/// The asset's factor table, every probe's own table put in its place in probe order, and each
/// probe's length in factors (in slots for u8 tables, whose factors take one or two): tables
/// in parallel, none for a dilated probe (it reads its source's,
/// [`prt_format::PROBE_DILATED`]), an invalid probe's rows dropped unencoded. Fails when rows
/// in the temporary file cannot be read back ([`RowStore`]).
pub fn encode_tables(
    rows: Rows,
    carried: Carried,
    (remap, bricks, (coarse, parts)): (&[u32], &[Brick], (&CoarsePlacement, &FineParts)),
    (precision, brick_size): (TransferPrecision, f32),
) -> Result<(Factors, Vec<usize>), BakeError> {
    let placed: Vec<Placed> = remap
        .par_iter()
        .map(|&b| {
            let first = parts.parts(b).start;
            (first, Vec3::from(bricks[first as usize].centroid))
        })
        .collect();
    let placed = Placement {
        placed: &placed,
        coarse,
        parts,
        bricks,
    };
    let lens = || own_lens(carried);
    Ok(match (precision, rows) {
        (TransferPrecision::U8, Rows::U8(rows)) => {
            let offset_scale = u8_offset_scale(brick_size);
            let (factors, lens) = place_slots(rows, carried, |rows, out, origin| {
                encode_u8(rows, out, (placed, offset_scale, brick_size > 0.0), origin)
            })?;
            let factors = Factors::U8 {
                factors,
                offset_scale,
            };
            (factors, lens)
        }
        (TransferPrecision::F16, Rows::Sums(rows)) => {
            let table = place_tables(rows, carried, |rows, out| {
                encode_sums(rows, out, placed, FactorF16::of)
            })?;
            (Factors::F16(table), lens())
        }
        (TransferPrecision::F32, Rows::Sums(rows)) => {
            let table = place_tables(rows, carried, |rows, out| {
                encode_sums(rows, out, placed, FactorF32::of)
            })?;
            (Factors::F32(table), lens())
        }
        _ => unreachable!("u8 rows are kept as u8, f16 and f32 rows as sums"),
    })
}

/// [`encode_tables`] for u8 slots, whose count per table is known once encoded: chunk by
/// chunk, its probes encoded in parallel (`encode` appends a probe's slots, given its ray
/// origin unless it is a dilation source), then appended in probe order and the chunk freed
/// ([`RowStore::drain`]). A dilation source's factors are all full, so that the dilated probes
/// that read its table decode it where they are (two slots a row); they have none of their
/// own. Returns the table and each probe's slot count (a dilated probe's 0).
fn place_slots(
    rows: RowStore<RowU8>,
    carried: Carried,
    encode: impl Fn(&[RowU8], &mut Vec<FactorSlot>, Option<Vec3>) + Sync,
) -> Result<(Vec<FactorSlot>, Vec<usize>), BakeError> {
    let n = carried.from.len();
    debug_assert_eq!(rows.probe_count(), n, "a row entry per probe");
    let mut source = vec![false; n];
    for (p, from) in carried.from.iter().enumerate() {
        if let Some(q) = from.filter(|&q| q != p) {
            source[q] = true;
        }
    }
    let rows_in_all: usize = own_lens(carried).iter().sum();
    let mut out: Vec<FactorSlot> = Vec::with_capacity(rows_in_all + rows_in_all / 64);
    let mut lens = vec![0; n];
    rows.drain(|first, runs, chunk| {
        let tables: Vec<Vec<FactorSlot>> = (runs.par_iter().enumerate())
            .map(|(i, &(start, len))| {
                let p = first + i;
                let mut table = Vec::new();
                if carried.from[p] == Some(p) {
                    table.reserve(len + len / 16);
                    let origin = (!source[p]).then(|| carried.origins[p]);
                    encode(&chunk[start..start + len], &mut table, origin);
                }
                table
            })
            .collect();
        for (i, table) in tables.into_iter().enumerate() {
            lens[first + i] = table.len();
            out.extend_from_slice(&table);
        }
    })?;
    Ok((out, lens))
}

/// Each probe's rows in the asset's table: its own, none for a dilated probe (it reads its
/// source's) or a probe without data.
pub fn own_lens(carried: Carried) -> Vec<usize> {
    own(carried.from, carried.lens).collect()
}

/// Each probe's own count of `lens` (`from`: whose table it reads): 0 for a dilated probe.
pub fn own<'a>(from: &'a [Option<usize>], lens: &'a [usize]) -> impl Iterator<Item = usize> + 'a {
    (from.iter().zip(lens).enumerate()).map(|(p, (&from, &len))| match from == Some(p) {
        true => len,
        false => 0,
    })
}

/// [`encode_tables`] for one factor type: `encode` fills a probe's place from its rows (a
/// dilated probe has none: it reads its source's). Chunk by chunk, its probes in parallel,
/// then the chunk freed ([`RowStore::drain`]).
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
    let lens = own_lens(carried);
    let mut out: Vec<T> = bytemuck::zeroed_vec(lens.iter().sum());
    let mut places = crate::memory::split_runs(&mut out, &lens).into_iter();
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
        let mean = Vec3::from(row.3) / row.1 as f32;
        let (b, centroid, scale) = at.locate(brick, level, mean);
        row.0 = b;
        row.3 = ((mean - centroid) / scale).to_array();
    }
    rows.sort_unstable_by_key(|r| r.0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::merge::coarse::FarField;
    use crate::merge::key::Key;
    use crate::tables::factors::{probe_rows, ProbeRows, RowTable};
    use crate::trace::Hit;
    use prt_format::sh::SH_COUNT;
    use prt_format::split_row_for_u8;

    /// A placement without coarse bricks.
    fn no_coarse() -> CoarsePlacement {
        crate::merge::coarse::build(&[], &[], &[], &Default::default()).1
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
        let used = [0, 0, 1 << 1, 0];
        let links = Default::default();
        let (coarse, placement) = crate::merge::coarse::build(&keys, &fits, &used, &links);
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
                origins: &[far.origin],
            };
            let numbering = (&remap[..], &bricks[..], (&placement, &FineParts::default()));
            let (factors, lens) =
                encode_tables(rows, carried, numbering, (precision, 1.0)).unwrap();
            // Three factors (u8: the transfers point up, the hits lie along x: no lobe fits,
            // two slots each).
            let heads: Vec<usize> = (0..factors.len())
                .filter(|&f| factors.brick_and_rays(f).1 > 0)
                .collect();
            assert_eq!((heads.len(), lens[0]), (3, factors.len()), "{precision:?}");
            let (b, rays) = factors.brick_and_rays(heads[2]);
            assert_eq!(
                (b, rays),
                (4, 2),
                "{precision:?}: the coarse brick, after the 4"
            );
            let offset = factors.offset(heads[2]);
            let want = (11.0 - centroid) / 2.0;
            assert!((offset[0] - want).abs() < 1e-2, "{precision:?}: {offset:?}");
            assert_eq!(factors.brick_and_rays(0), (0, 1));
            assert_eq!(factors.offset(0), [0.0; 3]);
        }
    }

    /// The table is each probe's own table, encoded alone, in probe order, whatever the chunks
    /// and whether they went through the temporary file: probes of no rows before any chunk, a
    /// probe larger than a chunk, a dilated probe (no table) and an invalid one, in chunks
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
            let origins = vec![Vec3::new(0.3, 2.0, 0.1); from.len()];
            let carried = Carried {
                from,
                lens: &lens,
                origins: &origins,
            };
            let numbering = (
                &remap[..],
                &bricks[..],
                (&no_coarse(), &FineParts::default()),
            );
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
            let mut alone_lens = vec![0; sizes.len()];
            for (p, q) in from.iter().enumerate() {
                // A dilated probe (6) has no table of its own: it reads its source's.
                let Some(q) = q.filter(|&q| q == p) else {
                    continue;
                };
                let mut one = vec![0; sizes.len()];
                one[q] = sizes[q];
                // Probe 3 is probe 6's source: its table alone, as a source, is all full.
                let mut only = vec![None; sizes.len()];
                only[q] = Some(q);
                if q == 3 {
                    only[6] = Some(3);
                }
                let (table, lens) = encode(&one, &only, (1 << 26, usize::MAX), precision);
                alone.extend(bytes(&table.select(std::slice::from_ref(&(0..lens[q])))));
                alone_lens[p] = lens[q];
            }
            for (chunk, budget) in [(1, 0), (1000, 1000), (1000, usize::MAX), (1 << 26, 1 << 26)] {
                let (table, lens) = encode(&sizes, &from, (chunk, budget), precision);
                assert!(!table.is_empty());
                let what = format!("{precision:?}, chunks of {chunk} bytes, budget {budget}");
                assert_eq!(bytes(&table), alone, "{what}");
                assert_eq!(lens, alone_lens, "{what}");
            }
            if precision == TransferPrecision::U8 {
                // The source's factors take two slots each.
                assert_eq!(alone_lens[3], 2 * 17);
            }
            let (none, _) = encode(&[0; 9], &from, (1000, 1000), precision);
            assert!(none.is_empty());
        }
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
            parts: &FineParts::default(),
            bricks: &bricks,
        };
        finish(&mut late, at);
        let late: Vec<FactorRow> = late.into_iter().flat_map(split_row_for_u8).collect();
        let late = Factors::build(&late, TransferPrecision::U8, n, size);
        let early = ProbeRows::of(rows, TransferPrecision::U8, n);
        let mut rows = Rows::new(TransferPrecision::U8, usize::MAX);
        rows.push(&early).unwrap();
        // A dilation source: all full, as `Factors::build` makes them.
        let carried = Carried {
            from: &[Some(0), Some(0)],
            lens: &[rows.len(0), 0],
            origins: &[Vec3::ZERO; 2],
        };
        rows.push(&ProbeRows::of(Vec::new(), TransferPrecision::U8, n))
            .unwrap();
        let settings = (TransferPrecision::U8, size);
        let numbering = (&remap[..], &bricks[..], (&coarse, &FineParts::default()));
        let (early, lens) = encode_tables(rows, carried, numbering, settings).unwrap();
        assert_eq!(
            lens,
            [14, 0],
            "600 and 256 rays split in three and two, two slots each; none for the dilated probe"
        );
        assert_eq!(early.select(std::slice::from_ref(&(0..14))), late);
    }
}
