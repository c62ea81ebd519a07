//! The asset's arrays larger than one storage binding, split into chunks of whole items that
//! each fit one: factor tables by probe, surfel arrays by brick (a stage dispatches once per
//! chunk). An item that alone passes the limit is refused with [`GpuError::Limit`].

use prt_format::{Asset, Factors};

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
            let end = asset.probes[c.probe_begin as usize..c.probe_end as usize]
                .last()
                .map_or(first, |p| (p.first_factor + p.factor_count) as usize);
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
                        .stored(&asset.surfels[range]),
                    none,
                )?,
                alloc.zeroed("prt surfel radiance", 16 * n, none)?,
                alloc.zeroed(
                    "prt surfel bounce",
                    if feeds_back { 16 * n } else { 0 },
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
pub fn factor_chunks(asset: &Asset, limit: u64) -> Result<Vec<FactorChunk>, GpuError> {
    let starts = run_starts(
        asset
            .probes
            .iter()
            .map(|p| (p.first_factor, p.factor_count)),
        asset.factors.bytes_per_factor() as u64,
        limit,
        "one probe's factor table",
    )?;
    let ends = starts
        .iter()
        .skip(1)
        .map(|s| s.0)
        .chain([asset.probes.len()]);
    Ok(starts
        .iter()
        .zip(ends)
        .map(|(&(probe, first), end)| FactorChunk {
            first_factor: first,
            probe_begin: probe as u32,
            probe_end: end as u32,
            ..FactorChunk::default()
        })
        .collect())
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
