//! A summary of an asset: counts, grid, and the bytes each section takes. `prt inspect` prints
//! it; `--json` gives the object of docs/conventions.md section 6.

use serde::Serialize;

use crate::asset::*;
use crate::factors::TransferPrecision;
use crate::io::FORMAT_VERSION;
use crate::sh::SH_COUNT;

/// Counts and sizes of an asset.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub format_version: u32,
    pub source_name: String,
    pub source_hash: String,
    /// Grid points (the probes' records).
    pub probe_count: usize,
    /// Probes with data ([`Probe::slot`]): grid points the bake placed, less those inside
    /// geometry with no valid neighbour to copy; the "per probe" of the figures below.
    pub probes_with_data: usize,
    /// Probes outside geometry (dilated ones not counted).
    pub valid_probe_count: usize,
    /// Probes inside geometry whose table was copied from a valid neighbour.
    pub dilated_probe_count: usize,
    /// Grid points without data the runtime fills from a coarse level of a sparse bake
    /// ([`crate::tier`]).
    pub filled_probe_count: usize,
    /// Probes moved off a surface they lay on, or out of geometry by the virtual offset.
    pub offset_probe_count: usize,
    /// Valid probes in a gap narrower than a tenth of the spacing ([`probe_in_gap`]): they see
    /// little beyond the gap's two sides, and surfaces farther off are lit by their neighbours.
    pub probes_in_gaps: usize,
    pub ray_count: u32,
    pub surfel_count: usize,
    pub surfels_unmerged: u64,
    /// Surfels with surface terms (`crate::surface`; 0 without terms).
    pub surfels_with_terms: usize,
    /// Of those, the surfels that see none of the 27 probes around them: their points are
    /// sampled with the probe volume's weights (`SurfaceTerms::traced_and_blind`).
    pub surfels_seeing_no_probe: usize,
    /// Sides: surfels a cell table names whose cell a wall crosses, each with the surfel of
    /// the cell's other side (`crate::surface::SurfaceSide`; format 18).
    pub surfels_with_sides: usize,
    pub brick_count: usize,
    /// Coarse bricks over the bricks, for far hits (`crate::coarse`).
    pub coarse_brick_count: usize,
    /// Factors (a u8 table's lobe factors take one 8-byte slot, the others two).
    pub factor_count: usize,
    /// Of those, lobe factors (`crate::lobe`; 0 but in u8 tables).
    pub lobe_factor_count: usize,
    pub factors_per_probe: f64,
    /// Factors by what they read: `[0]` a brick, `[l]` a coarse brick of level `l`
    /// (`crate::coarse`), as many entries as the coarsest level used plus one. Transport per
    /// probe follows these counts: the far ratio sets the coarse ones (docs/results/cells.md).
    pub factors_by_level: Vec<usize>,
    /// Factors of a single ray: a grazing or partly seen brick, most of them coarse.
    pub single_ray_factors: usize,
    pub transfer_precision: TransferPrecision,
    pub triangle_count: usize,
    pub light_count: usize,
    pub file_bytes: u64,
    pub bytes_per_probe: f64,
    /// Per placed probe, the per-probe runtime data: probe records (the grid's, placed or not),
    /// sky mask, sky transfer, visibility map and factor table.
    pub transport_bytes_per_probe: f64,
    pub section_bytes: SectionBytes,
    pub grid: Grid,
}

/// Bytes of each array section as stored (in memory but for surfels, which are stored packed
/// unless in f32; the file adds a few bytes of lengths per section).
#[derive(Clone, Debug, Serialize)]
pub struct SectionBytes {
    pub probes: u64,
    pub sky_mask: u64,
    pub sky_transfer: u64,
    /// Visibility maps (octahedral depth moments).
    pub probe_depth: u64,
    pub factors: u64,
    pub bricks: u64,
    /// Coarse bricks, their children lists and the bricks' moments (`crate::coarse`).
    pub coarse: u64,
    pub surfels: u64,
    pub bvh_nodes: u64,
    pub triangles: u64,
    /// The surface lookup's tables and terms (`crate::surface`).
    pub surface: u64,
}

fn bytes<T>(v: &[T]) -> u64 {
    std::mem::size_of_val(v) as u64
}

impl Summary {
    /// Summarises `asset`, whose file is `file_bytes` long.
    pub fn of(asset: &Asset, file_bytes: u64) -> Summary {
        let probes = asset.probes.iter().filter(|p| p.has_data()).count();
        let section_bytes = SectionBytes {
            probes: bytes(&asset.probes),
            sky_mask: bytes(&asset.sky_mask),
            sky_transfer: (asset.sky_transfer.len() * SH_COUNT * 4) as u64,
            probe_depth: bytes(&asset.probe_depth),
            factors: (asset.factors.len() * asset.factors.bytes_per_factor()) as u64,
            bricks: bytes(&asset.bricks),
            coarse: bytes(&asset.coarse.bricks)
                + bytes(&asset.coarse.children)
                + bytes(&asset.coarse.moments),
            surfels: (asset.surfels.len() * asset.header.settings.surfel_precision.bytes()) as u64,
            bvh_nodes: bytes(&asset.geometry.nodes),
            triangles: bytes(&asset.geometry.triangles),
            surface: surface_bytes(&asset.surface),
        };
        let per_probe = |b: u64| {
            if probes == 0 {
                0.0
            } else {
                b as f64 / probes as f64
            }
        };
        let (factor_count, lobe_factor_count) = asset.factors.factor_counts();
        let (factors_by_level, single_ray_factors) = factor_levels(asset);
        let s = &section_bytes;
        let (traced, blind) = asset.surface.traced_and_blind();
        let probes_in_gaps = (0..asset.probes.len())
            .filter(|&p| asset.probes[p].is_valid() && probe_in_gap(asset, p))
            .count();
        Summary {
            format_version: FORMAT_VERSION,
            source_name: asset.header.source_name.clone(),
            source_hash: format!("{:016x}", asset.header.source_hash),
            probe_count: asset.probes.len(),
            probes_with_data: probes,
            valid_probe_count: asset
                .probes
                .iter()
                .filter(|p| p.is_valid() && !p.is_dilated())
                .count(),
            dilated_probe_count: asset.probes.iter().filter(|p| p.is_dilated()).count(),
            filled_probe_count: asset.probes.iter().filter(|p| p.is_filled()).count(),
            offset_probe_count: asset
                .probes
                .iter()
                .filter(|p| p.flags & PROBE_OFFSET != 0)
                .count(),
            probes_in_gaps,
            ray_count: asset.header.ray_count,
            surfel_count: asset.surfels.len(),
            surfels_unmerged: asset.header.stats.surfels_unmerged,
            surfels_with_terms: traced,
            surfels_seeing_no_probe: blind,
            surfels_with_sides: asset.surface.sides.len(),
            brick_count: asset.bricks.len(),
            coarse_brick_count: asset.coarse.bricks.len(),
            factor_count,
            lobe_factor_count,
            factors_per_probe: per_probe(factor_count as u64),
            factors_by_level,
            single_ray_factors,
            transfer_precision: asset.factors.precision(),
            triangle_count: asset.geometry.triangles.len(),
            light_count: asset.lights.len(),
            file_bytes,
            bytes_per_probe: per_probe(file_bytes),
            transport_bytes_per_probe: per_probe(
                s.probes + s.sky_mask + s.sky_transfer + s.probe_depth + s.factors,
            ),
            section_bytes,
            grid: asset.header.grid,
        }
    }
}

/// Whether probe `p` sits in a gap narrower than a tenth of the spacing: the median over its
/// visibility map's texels of the mean hit distance is below [`GAP_DEPTH`] spacings (a probe
/// beside one wall sees the room over half its texels; one between two plates a centimetre
/// apart sees them everywhere but at grazing angles).
pub fn probe_in_gap(asset: &Asset, p: usize) -> bool {
    let Some(words) = asset.visibility_map(p) else {
        return false;
    };
    let mut means: Vec<f32> = (0..DEPTH_TEXELS)
        .map(|t| crate::depth::moments(words, t).0)
        .collect();
    let (_, median, _) = means.select_nth_unstable_by(DEPTH_TEXELS / 2, f32::total_cmp);
    *median < GAP_DEPTH
}

/// Median hit distance (probe spacings) under which [`probe_in_gap`] says a probe is in a gap.
/// With four-bit moments (`crate::depth`) the median reads below it at the levels 0, 0.018
/// and 0.071 spacings: true means under about 0.11 spacings.
pub const GAP_DEPTH: f32 = 0.1;

/// In-memory bytes of the surface terms' arrays.
fn surface_bytes(t: &crate::surface::SurfaceTerms) -> u64 {
    bytes(&t.slots)
        + bytes(&t.cells)
        + bytes(&t.surfels)
        + bytes(&t.groups)
        + bytes(&t.group_surfels)
        + bytes(&t.near_ranges)
        + bytes(&t.near)
        + bytes(&t.sky)
        + bytes(&t.sides)
}

/// Factors by the level of what they read, and those of one ray ([`Summary::factors_by_level`]).
/// A continuation slot is no factor; a brick index past the coarse bricks (an asset not
/// validated) counts as level 0.
fn factor_levels(asset: &Asset) -> (Vec<usize>, usize) {
    let bricks = asset.bricks.len();
    let (mut by_level, mut single) = (vec![0usize], 0);
    for f in 0..asset.factors.len() {
        let (brick, rays) = asset.factors.brick_and_rays(f);
        if rays == 0 {
            continue;
        }
        let level = (brick as usize)
            .checked_sub(bricks)
            .and_then(|c| asset.coarse.bricks.get(c))
            .map_or(0, |c| c.level as usize);
        if by_level.len() <= level {
            by_level.resize(level + 1, 0);
        }
        by_level[level] += 1;
        single += usize::from(rays == 1);
    }
    (by_level, single)
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.grid;
        writeln!(f, "format version   {}", self.format_version)?;
        writeln!(
            f,
            "source           {} (xxh3 {})",
            self.source_name, self.source_hash
        )?;
        writeln!(
            f,
            "grid             {} x {} x {}, step {:?} m (spacing {} m), origin {:?}",
            g.counts[0], g.counts[1], g.counts[2], g.step, g.spacing, g.origin
        )?;
        writeln!(
            f,
            "probes           {} with data of {} grid points ({} valid, {} inside geometry with a neighbour's data; the other {} left out by the placement or inside geometry: no data, {} of them filled from a coarse level), {} moved off a surface or out of geometry, {} rays each",
            self.probes_with_data,
            self.probe_count,
            self.valid_probe_count,
            self.dilated_probe_count,
            self.probe_count - self.probes_with_data,
            self.filled_probe_count,
            self.offset_probe_count,
            self.ray_count
        )?;
        writeln!(
            f,
            "probes in gaps   {} (median hit distance over their visibility map under a tenth of the spacing)",
            self.probes_in_gaps
        )?;
        writeln!(
            f,
            "surfels          {} ({} ray hits before merging)",
            self.surfel_count, self.surfels_unmerged
        )?;
        writeln!(
            f,
            "bricks           {} (and {} coarse bricks for far hits)",
            self.brick_count, self.coarse_brick_count
        )?;
        writeln!(
            f,
            "surface terms    {} surfels, {} of them see none of their probes (sampled from the volume); {} sides (a surfel whose cell a wall crosses, and the surfel beyond it)",
            self.surfels_with_terms, self.surfels_seeing_no_probe, self.surfels_with_sides
        )?;
        writeln!(
            f,
            "factors          {} ({:.1} per probe, {:?} transfer{})",
            self.factor_count,
            self.factors_per_probe,
            self.transfer_precision,
            match self.transfer_precision {
                TransferPrecision::U8 => format!(
                    ": {} lobes of one 8-byte slot, {} of two",
                    self.lobe_factor_count,
                    self.factor_count - self.lobe_factor_count
                ),
                _ => String::new(),
            }
        )?;
        if self.probes_with_data > 0 && self.factor_count > 0 {
            let per = |n: usize| n as f64 / self.probes_with_data as f64;
            let coarse: Vec<String> = (self.factors_by_level.iter().enumerate().skip(1))
                .map(|(l, &n)| format!("{l}: {:.1}", per(n)))
                .collect();
            writeln!(
                f,
                "factor levels    per probe: {:.1} read bricks{}; {:.1} have one ray",
                per(self.factors_by_level[0]),
                match coarse.is_empty() {
                    true => String::new(),
                    false => format!(", coarse bricks of level {}", coarse.join(", ")),
                },
                per(self.single_ray_factors)
            )?;
        }
        writeln!(
            f,
            "geometry         {} triangles, {} lights",
            self.triangle_count, self.light_count
        )?;
        let s = &self.section_bytes;
        writeln!(
            f,
            "section bytes    probes {} | sky mask {} | sky transfer {} | visibility {} | factors {} | bricks {} | coarse {} | surfels {} | bvh {} | triangles {} | surface {}",
            s.probes, s.sky_mask, s.sky_transfer, s.probe_depth, s.factors, s.bricks, s.coarse, s.surfels, s.bvh_nodes, s.triangles, s.surface
        )?;
        write!(
            f,
            "file             {} bytes, {:.0} bytes per probe ({:.0} of per-probe transport data)",
            self.file_bytes, self.bytes_per_probe, self.transport_bytes_per_probe
        )
    }
}
