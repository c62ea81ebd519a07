//! The asset's arrays larger than one storage binding, split into chunks of whole items that
//! each fit one: factor tables by probe, surfel arrays by brick (a stage dispatches once per
//! chunk). An item that alone passes the limit is refused with [`GpuError::Limit`].

use prt_format::{Asset, Factors, Probe};

use super::alloc::Alloc;
use crate::contract::*;
use crate::gpu::{GpuError, RuntimeSettings};

/// The factor tables split into chunks of whole probes, each chunk's buffer and uniform.
pub(super) fn factor_buffers(
    alloc: &Alloc,
    asset: &Asset,
    settings: &RuntimeSettings,
) -> Result<FactorBuffers, GpuError> {
    let none = wgpu::BufferUsages::empty();
    let factor_bytes: &[u8] = match &asset.factors {
        Factors::F16(f) => bytemuck::cast_slice(f),
        Factors::F32(f) => bytemuck::cast_slice(f),
        Factors::U8 { factors, .. } => bytemuck::cast_slice(factors),
    };
    let chunks = factor_chunks(asset, alloc.chunk_bytes(settings.max_factor_chunk_bytes))?;
    let per_factor = asset.factors.bytes_per_factor();
    let chunk_factors: Vec<wgpu::Buffer> = chunks
        .iter()
        .map(|c| {
            let first = c.first_factor as usize;
            let end = chunk_end(asset, c) as usize;
            alloc.storage(
                "prt factors",
                &factor_bytes[first * per_factor..end * per_factor],
                none,
            )
        })
        .collect::<Result<_, _>>()?;
    let chunk_uniforms: Vec<wgpu::Buffer> = chunks
        .iter()
        .map(|c| alloc.uniform("prt factor chunk", c))
        .collect();
    Ok((chunks, chunk_factors, chunk_uniforms))
}

/// The surfel arrays split into chunks of whole bricks: per chunk its surfels, their direct
/// radiance, their bounce radiance (one word without bounces) and its uniform.
pub(super) fn surfel_buffers(
    alloc: &Alloc,
    asset: &Asset,
    settings: &RuntimeSettings,
) -> Result<SurfelBuffers, GpuError> {
    let none = wgpu::BufferUsages::empty();
    let surfel_chunks = surfel_chunks(asset, alloc.chunk_bytes(settings.max_surfel_chunk_bytes))?;
    let feeds_back = settings.bounces.feeds_back();
    let precision = asset.header.settings.surfel_precision;
    let radiance_bytes = 4 * u64::from(crate::radiance_word::words_per_surfel(precision));
    // Per chunk: its surfels, their direct radiance and their bounce radiance.
    let chunk_surfels: Vec<[wgpu::Buffer; 4]> = surfel_chunks
        .iter()
        .map(|c| {
            let range = c.surfel_begin as usize..c.surfel_end as usize;
            let n = range.len() as u64;
            Ok([
                alloc.storage(
                    "prt surfels",
                    &asset
                        .header
                        .settings
                        .surfel_precision
                        .stored(&asset.surfels[range], &asset.bricks),
                    none,
                )?,
                alloc.zeroed("prt surfel radiance", radiance_bytes * n, none)?,
                alloc.zeroed(
                    "prt surfel bounce",
                    if feeds_back { radiance_bytes * n } else { 0 },
                    none,
                )?,
                alloc.uniform("prt surfel chunk", c),
            ])
        })
        .collect::<Result<_, GpuError>>()?;
    Ok((surfel_chunks, chunk_surfels))
}

/// Factor chunks and, per chunk, its factors and its uniform.
pub(super) type FactorBuffers = (Vec<FactorChunk>, Vec<wgpu::Buffer>, Vec<wgpu::Buffer>);

/// Surfel chunks and, per chunk, its surfels, direct and bounce radiance, and uniform.
pub(super) type SurfelBuffers = (Vec<SurfelChunk>, Vec<[wgpu::Buffer; 4]>);

/// Where runs of whole items start, as `(item, first element)`, for items that each own the
/// elements `first..first + count` (contiguous, in item order), so that no run's elements take
/// more than `limit` bytes of `element_bytes` each. The first run starts at (0, 0); an item whose
/// own elements exceed the limit is an error naming `what`.
fn run_starts(
    items: impl Iterator<Item = (u32, u32)>,
    element_bytes: u64,
    limit: u64,
    what: &'static str,
) -> Result<Vec<(usize, u32)>, GpuError> {
    let mut starts = vec![(0usize, 0u32)];
    for (i, (first, count)) in items.enumerate() {
        let own = u64::from(count) * element_bytes;
        if own > limit {
            return Err(GpuError::Limit {
                what,
                needed: own,
                limit,
            });
        }
        let run_first = starts.last().map_or(0, |s| s.1);
        if (u64::from(first) + u64::from(count) - u64::from(run_first)) * element_bytes > limit {
            starts.push((i, first));
        }
    }
    Ok(starts)
}

/// Splits the probes into runs whose factor tables fit `limit` bytes each (at least one chunk).
/// A chunk's factors are the span from the lowest to the end of the highest run its probes
/// read. A dilated probe reads its source's run (format 12), which lies up to two grid steps
/// away: in probe order up to two layers of the grid, so spans may overlap, and where a binding
/// holds less than two layers of tables a dilated probe whose source lies outside the span
/// costs a chunk of its own (and the next probe another).
pub fn factor_chunks(asset: &Asset, limit: u64) -> Result<Vec<FactorChunk>, GpuError> {
    let bytes = asset.factors.bytes_per_factor() as u64;
    chunks_of(&asset.probes, bytes, limit)
}

/// [`factor_chunks`] of `probes` over a table of `bytes` per factor.
fn chunks_of(probes: &[Probe], bytes: u64, limit: u64) -> Result<Vec<FactorChunk>, GpuError> {
    let mut chunks = Vec::new();
    let mut chunk = FactorChunk::default();
    let mut span: Option<(u32, u32)> = None;
    for (p, probe) in probes.iter().enumerate() {
        if probe.factor_count == 0 {
            continue;
        }
        let own = u64::from(probe.factor_count) * bytes;
        if own > limit {
            return Err(GpuError::Limit {
                what: "one probe's factor table",
                needed: own,
                limit,
            });
        }
        let (first, end) = (probe.first_factor, probe.first_factor + probe.factor_count);
        let grown = span.map_or((first, end), |(lo, hi)| (lo.min(first), hi.max(end)));
        if u64::from(grown.1 - grown.0) * bytes > limit {
            chunks.push(FactorChunk {
                probe_end: p as u32,
                ..chunk
            });
            chunk.probe_begin = p as u32;
            span = Some((first, end));
        } else {
            span = Some(grown);
        }
        chunk.first_factor = span.map_or(0, |s| s.0);
    }
    chunks.push(FactorChunk {
        probe_end: probes.len() as u32,
        ..chunk
    });
    Ok(chunks)
}

/// The factors chunk `c` holds: from its first factor to the end of the highest table its
/// probes read.
pub fn chunk_end(asset: &Asset, c: &FactorChunk) -> u32 {
    span_end(&asset.probes, c)
}

/// [`chunk_end`] of `probes`.
fn span_end(probes: &[Probe], c: &FactorChunk) -> u32 {
    (probes[c.probe_begin as usize..c.probe_end as usize].iter())
        .filter(|p| p.factor_count > 0)
        .map(|p| p.first_factor + p.factor_count)
        .max()
        .unwrap_or(c.first_factor)
}

/// Splits the bricks into runs whose surfels take at most `limit` bytes each (whole bricks,
/// since a brick's stage reads all its surfels).
pub fn surfel_chunks(asset: &Asset, limit: u64) -> Result<Vec<SurfelChunk>, GpuError> {
    let starts = run_starts(
        asset
            .bricks
            .iter()
            .map(|b| (b.first_surfel, b.surfel_count)),
        asset.header.settings.surfel_precision.bytes() as u64,
        limit,
        "one brick's surfels",
    )?;
    let ends = starts
        .iter()
        .skip(1)
        .copied()
        .chain([(asset.bricks.len(), asset.surfels.len() as u32)]);
    Ok(starts
        .iter()
        .zip(ends)
        .map(|(&(brick, first), (end, last))| SurfelChunk {
            brick_begin: brick as u32,
            brick_end: end as u32,
            surfel_begin: first,
            surfel_end: last,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Probes with runs `(first, count)`.
    fn probes(runs: &[(u32, u32)]) -> Vec<Probe> {
        runs.iter()
            .map(|&(first_factor, factor_count)| Probe {
                first_factor,
                factor_count,
                ..Probe::default()
            })
            .collect()
    }

    /// Every probe is in one chunk, in order, and the run it reads lies in its chunk's span,
    /// which fits the limit: with leading probes without factors, a dilated probe whose source
    /// is ahead and one whose source is behind, at a limit of two 8-byte tables of four and of
    /// all of them; a table past the limit is refused.
    #[test]
    fn chunks_hold_the_runs_their_probes_read() {
        let probes = probes(&[
            (0, 0),
            (0, 4),
            (4, 4),
            (12, 4), // dilated, its source ahead
            (8, 4),
            (12, 4),
            (0, 4), // dilated, its source behind
            (16, 4),
            (20, 0),
        ]);
        for (limit, count) in [(64u64, None), (1 << 20, Some(1))] {
            let chunks = chunks_of(&probes, 8, limit).unwrap();
            if let Some(count) = count {
                assert_eq!(chunks.len(), count);
            }
            assert_eq!(chunks[0].probe_begin, 0);
            assert_eq!(chunks.last().unwrap().probe_end, probes.len() as u32);
            for pair in chunks.windows(2) {
                assert_eq!(pair[0].probe_end, pair[1].probe_begin);
            }
            for c in &chunks {
                let end = span_end(&probes, c);
                assert!(u64::from(end - c.first_factor) * 8 <= limit, "{c:?}");
                for p in &probes[c.probe_begin as usize..c.probe_end as usize] {
                    if p.factor_count > 0 {
                        assert!(p.first_factor >= c.first_factor, "{p:?} in {c:?}");
                        assert!(p.first_factor + p.factor_count <= end, "{p:?} in {c:?}");
                    }
                }
            }
        }
        let err = chunks_of(&probes, 8, 24).unwrap_err();
        assert!(matches!(err, GpuError::Limit { needed: 32, .. }), "{err:?}");
    }
}
