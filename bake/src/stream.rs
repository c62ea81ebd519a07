//! Tracing and merging streamed in probe blocks: each block of probes is traced in parallel
//! while the block before it is folded into bricks ([`BrickFolder`]), so that the bake holds at
//! most two blocks of ray hits, never all of them: the hits grow with probes times rays, past
//! any machine's memory on large grids.
//!
//! What a probe keeps once its block is folded is what the asset needs from it: its sky mask, sky
//! transfer and ray counts, its visibility map, and its factor rows (keyed by provisional brick
//! until [`BrickFolder::finish_placed`] numbers the bricks). Blocks are folded in probe order and a
//! probe's hits in the order its rays were traced (`crate::trace::coherent_order`), so the result
//! is the same for any block size or thread count.

use std::sync::{Mutex, PoisonError};

use glam::Vec3;
use prt_format::{TransferPrecision, DEPTH_WORDS};
use rayon::prelude::*;

use crate::depth::DepthFilter;
use crate::merge::coarse::FarField;
use crate::merge::fold::BrickFolder;
use crate::tables::factors::{self, RowTable, Rows};
use crate::trace::{ProbeRays, Tracer};
use crate::{BakeError, Progress};

/// Probes traced per block: enough parallel work per block for many cores, few enough hits
/// (about 5 MB at 512 rays) that a block's merge stays in cache, and enough blocks that the
/// last one's merge, which runs alone, is short.
pub const BLOCK_PROBES: usize = 256;

/// Probes in the smallest block: the blocks taper towards the end ([`block_len`]).
pub const TAIL_PROBES: usize = 32;

/// The length of the block that starts with `remaining` probes left: [`BLOCK_PROBES`], then
/// halves over the last ones down to [`TAIL_PROBES`]. The last block's fold has no tracing
/// beside it to overlap, so a short last block leaves less of the pool idle. On 2 threads a
/// block's fold (on one thread, about a third of its tracing time there) still fits beside the
/// tracing of the next, half as long; on many, the fold of a block may outlast it. The blocks
/// depend only on the probe count, so the result does not depend on the threads.
pub fn block_len(remaining: usize) -> usize {
    (remaining / 2)
        .clamp(TAIL_PROBES, BLOCK_PROBES)
        .min(remaining)
}

/// Everything the bake keeps of its probes after tracing.
pub struct Traced {
    /// Per probe: where it was traced from, and whether that is off its grid point.
    pub positions: Vec<(Vec3, bool)>,
    /// Per probe: sky mask, sky transfer and ray counts (the hits are folded and dropped).
    pub rays: Vec<ProbeRays>,
    /// Per probe: factor rows keyed by provisional brick ([`factors::Rows`]).
    pub rows: Rows,
    /// Per placed probe, its packed visibility map ([`DepthFilter::map`]), probe after probe.
    pub depth: Vec<u32>,
    pub folder: BrickFolder,
    /// Per provisional brick, bit `l` set when some probe has a level-`l` row naming it:
    /// the coarse bricks to make ([`crate::merge::coarse::build`]).
    pub far_levels: Vec<u8>,
}

/// How one probe is traced: from its grid point (its index) to its position and rays.
pub type TraceProbe<'a> = dyn Fn(usize) -> (Vec3, ProbeRays, bool) + Sync + 'a;

/// One block of traced probes, hits still attached.
type Block = Vec<(Vec3, ProbeRays, bool)>;

/// How [`trace_and_fold`] keeps what it folds.
pub struct Keep<'a> {
    /// The grid's spacing (for the visibility maps).
    pub spacing: f32,
    /// How factor rows are kept ([`factors::ProbeRows`]).
    pub precision: TransferPrecision,
    /// Bytes of factor rows held in memory; the rest wait in a temporary file
    /// ([`crate::tables::row_store`]).
    pub row_memory: usize,
    /// Whether a probe's factor rows are kept: an invalid probe's table is never encoded (a
    /// dilated probe reads its valid source's), so its rows are not even made.
    pub rows_of: &'a (dyn Fn(&ProbeRays) -> bool + Sync),
    /// Where far hits go ([`crate::merge::coarse`]), but for its origin: each probe's own.
    pub far: FarField,
}

/// Traces `probe_count` probes with `trace` and folds their hits into `folder`; fails when the
/// surfels or bricks outgrow 32-bit indices, or when rows past the memory budget cannot be
/// written to the temporary file.
pub fn trace_and_fold(
    probe_count: usize,
    trace: &TraceProbe,
    tracer: &Tracer,
    folder: BrickFolder,
    keep: &Keep,
    progress: &dyn Progress,
) -> Result<Traced, BakeError> {
    let depth_filter = DepthFilter::new(tracer.directions);
    let tables = RowTables::new();
    let mut out = Traced {
        positions: Vec::with_capacity(probe_count),
        rays: Vec::with_capacity(probe_count),
        rows: Rows::new(keep.precision, keep.row_memory),
        depth: Vec::with_capacity(probe_count * DEPTH_WORDS),
        folder,
        far_levels: Vec::new(),
    };
    let trace_block = |probes: std::ops::Range<usize>| -> Block {
        probes
            .into_par_iter()
            .map(|p| {
                let traced = trace(p);
                progress.advance(1);
                traced
            })
            .collect()
    };
    let mut pending: Option<Block> = None;
    let mut next = 0;
    while next < probe_count || pending.is_some() {
        let (start, end) = (next, next + block_len(probe_count - next));
        let (traced, folded) = rayon::join(
            || (start < end).then(|| trace_block(start..end)),
            || match pending.take() {
                Some(block) => {
                    let per_probe = PerProbe {
                        tracer,
                        depth_filter: &depth_filter,
                        tables: &tables,
                        keep,
                    };
                    fold_block(block, &mut out, &per_probe)
                }
                None => Ok(()),
            },
        );
        folded?;
        next = end;
        pending = traced;
    }
    out.rows.end()?;
    Ok(out)
}

/// What a probe's factor rows and visibility map are made with once its block is folded.
struct PerProbe<'a> {
    tracer: &'a Tracer<'a>,
    depth_filter: &'a DepthFilter,
    tables: &'a RowTables,
    keep: &'a Keep<'a>,
}

/// A [`RowTable`] per thread of the pool, for the bake's duration.
struct RowTables(Vec<Mutex<RowTable>>);

impl RowTables {
    fn new() -> Self {
        RowTables(
            (0..rayon::current_num_threads())
                .map(|_| Mutex::default())
                .collect(),
        )
    }

    /// Runs `f` with the current thread's table (uncontended: one per worker; a caller outside
    /// the pool shares the first). A table whose user panicked is still sound: its entries are
    /// stamped with the probe they belong to ([`RowTable`]).
    fn with<R>(&self, f: impl FnOnce(&mut RowTable) -> R) -> R {
        let i = rayon::current_thread_index().unwrap_or(0) % self.0.len();
        f(&mut self.0[i].lock().unwrap_or_else(PoisonError::into_inner))
    }
}

/// Folds one block's hits into the bricks (in probe and ray order), then per probe, in
/// parallel: factor rows, visibility map, and the hits dropped.
fn fold_block(block: Block, out: &mut Traced, per_probe: &PerProbe) -> Result<(), BakeError> {
    let PerProbe {
        tracer,
        depth_filter,
        tables,
        keep,
    } = *per_probe;
    let Keep {
        spacing, precision, ..
    } = *keep;
    let mut brick_of_hit = Vec::new();
    let mut hit_start = Vec::with_capacity(block.len() + 1);
    // Only probes whose rows are kept make surfels: a probe inside geometry sees faces no
    // valid probe sees (a double-sided roof's underside within a thick wall), whose surfels the
    // surface lookup then found for points on the real surface beside them.
    for (_, r, _) in &block {
        hit_start.push(brick_of_hit.len());
        if (keep.rows_of)(r) {
            out.folder.fold(&r.hits, &mut brick_of_hit)?;
        }
    }
    hit_start.push(brick_of_hit.len());
    let finished: Vec<_> = block
        .into_par_iter()
        .enumerate()
        .map(|(i, (p, mut r, moved))| {
            let ids = &brick_of_hit[hit_start[i]..hit_start[i + 1]];
            let rows = match (keep.rows_of)(&r) {
                true => tables.with(|table| {
                    let lattice = (&tracer.basis[..], tracer.weight);
                    let far = FarField {
                        origin: p,
                        ..keep.far
                    };
                    factors::probe_rows(&r.hits, ids, lattice, &far, precision, table)
                }),
                false => factors::ProbeRows::new(precision),
            };
            let depth = r
                .placed
                .then(|| depth_filter.map(p, &r, tracer.directions.len(), spacing));
            r.hits = Vec::new();
            ((p, moved), r, rows, depth)
        })
        .collect();
    for (position, r, rows, depth) in finished {
        // Rows carry levels only when far hits have somewhere to go (unmerged rows use every
        // bit of their brick word: up to 2^32 - 1 bricks).
        let far_rows = match keep.far.is_on() {
            true => rows.far_rows(),
            false => Vec::new(),
        };
        for (brick, level) in far_rows {
            if brick >= out.far_levels.len() {
                out.far_levels.resize(brick + 1, 0);
            }
            out.far_levels[brick] |= 1 << level;
        }
        out.positions.push(position);
        out.rays.push(r);
        out.rows.push(&rows)?;
        if let Some(depth) = depth {
            out.depth.extend_from_slice(&depth);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blocks cover every probe once, never grow, and end with one of at most
    /// [`TAIL_PROBES`] (unless the bake has fewer probes in all).
    #[test]
    fn blocks_taper_to_a_short_last_one() {
        for count in [1, 31, 32, 33, 100, 256, 257, 511, 512, 3024, 16758] {
            let mut lens = Vec::new();
            let mut start = 0;
            while start < count {
                let len = block_len(count - start);
                assert!((1..=BLOCK_PROBES).contains(&len), "{count}: {len}");
                lens.push(len);
                start += len;
            }
            assert_eq!(start, count);
            assert!(lens.windows(2).all(|w| w[0] >= w[1]), "{count}: {lens:?}");
            assert!(*lens.last().unwrap() <= TAIL_PROBES, "{count}: {lens:?}");
        }
    }
}
