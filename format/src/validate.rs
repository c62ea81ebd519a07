//! Structural validation of a decoded asset: every count, every index range, every float.
//!
//! A runtime uploads the arrays to the GPU as they are and indexes them without checks, so an
//! asset is only handed out once all of this holds.

use crate::asset::*;
use crate::error::FormatError;
use crate::factors::Factors;

mod coarse;
mod surface;

/// Largest ray count a bake may use (bit masks and tables are sized by it).
pub const MAX_RAYS: u32 = 1 << 20;
/// Largest traversal stack a BVH may need (its depth plus one): runtimes trace shadow rays with
/// a fixed-size stack of this many entries.
pub const MAX_BVH_STACK: usize = 64;

/// Fails when a value of `v` is not finite. Always inlined, its error built out of line: the
/// loops over the asset's millions of floats called it once per field, a third of the
/// validation's time ([`validate`]). With [`Factors::brick_and_rays`] inlined too, Sponza's
/// assets at 1.9 m and 1.0 m (56 and 219 MiB), best of 15 validations, three alternating runs:
/// 9.6-12.7 ms against 17.7-32.4 ms, and 34.5-47.5 ms against 61-101 ms.
#[inline(always)]
fn finite(section: &'static str, index: usize, what: &str, v: &[f32]) -> Result<(), FormatError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(not_finite(section, index, what, v))
    }
}

#[cold]
#[inline(never)]
fn not_finite(section: &'static str, index: usize, what: &str, v: &[f32]) -> FormatError {
    FormatError::invalid(section, index, format!("{what} {v:?} is not finite"))
}

fn count(section: &'static str, found: usize, expected: usize) -> Result<(), FormatError> {
    if found == expected {
        Ok(())
    } else {
        Err(FormatError::Count {
            section,
            found,
            expected,
        })
    }
}

/// Checks that `asset` is internally consistent, section by section; the first failing check
/// is the error.
pub fn validate(asset: &Asset) -> Result<(), FormatError> {
    header(&asset.header)?;
    probe_sections(asset)?;
    probe_records(asset)?;
    filled_points(asset)?;
    factor_table(asset)?;
    bricks(asset)?;
    coarse::coarse_bricks(asset)?;
    surfels(&asset.surfels)?;
    geometry(&asset.geometry)?;
    surface::surface_terms(asset)?;
    for (i, l) in asset.lights.iter().enumerate() {
        l.validate(i)
            .map_err(|e| FormatError::invalid("lights", i, e.to_string()))?;
    }
    Ok(())
}

/// The header: the grid's origin, spacing, steps and counts, and the ray count.
fn header(h: &Header) -> Result<(), FormatError> {
    let g = &h.grid;
    finite("header.grid", 0, "origin", &g.origin)?;
    if !(g.spacing.is_finite() && g.spacing > 0.0) {
        return Err(FormatError::invalid(
            "header.grid",
            0,
            format!("spacing {}", g.spacing),
        ));
    }
    if g.step
        .iter()
        .any(|&s| !(s.is_finite() && s > 0.0 && s <= g.spacing * 1.0001))
    {
        return Err(FormatError::invalid(
            "header.grid",
            0,
            format!(
                "step {:?} (expected 0 < step <= spacing {})",
                g.step, g.spacing
            ),
        ));
    }
    if g.counts.contains(&0) || g.probe_count() == u64::MAX {
        return Err(FormatError::invalid(
            "header.grid",
            0,
            format!("counts {:?}", g.counts),
        ));
    }
    // The runtime lights surfels with it (`prt_runtime::lights::surfel_spread_sq`).
    let cell = h.settings.cell_size;
    if !(cell >= 0.0 && (cell * cell).is_finite()) {
        return Err(FormatError::invalid(
            "header.settings",
            0,
            format!("cell_size {cell} (expected at least 0, its square finite)"),
        ));
    }
    if h.ray_count == 0 || h.ray_count > MAX_RAYS {
        return Err(FormatError::invalid(
            "header",
            0,
            format!("ray_count {} outside 1..={MAX_RAYS}", h.ray_count),
        ));
    }
    Ok(())
}

/// The per-probe sections' lengths (the probes against the grid; sky masks, sky transfers and
/// visibility maps against the placed probes, [`Probe::slot`]), and the sky transfers' values.
fn probe_sections(asset: &Asset) -> Result<(), FormatError> {
    let h = &asset.header;
    let g = &h.grid;
    let probes = asset.probes.len();
    if g.probe_count() != probes as u64 {
        return Err(FormatError::Count {
            section: "probes",
            found: probes,
            expected: g.probe_count() as usize,
        });
    }
    let probes = asset.probes.iter().filter(|p| p.has_data()).count();
    crate::sky_mask::validate(&asset.sky_mask, probes, h.ray_count)?;
    count("sky_transfer", asset.sky_transfer.len(), probes)?;
    for (i, t) in asset.sky_transfer.iter().enumerate() {
        finite("sky_transfer", i, "transfer", t)?;
    }
    count(
        "probe_depth",
        asset.probe_depth.len(),
        probes * crate::asset::DEPTH_WORDS,
    )?;
    Ok(())
}

/// Each probe's record: a finite position, a sky ray count within the header's `ray_count`,
/// dilated only if valid, slots numbering the probes with data in grid order (a probe with
/// data is not filled; a probe without has no flags but `PROBE_OFFSET` and `PROBE_FILLED`
/// with its level, no factors and no sky rays), the factor runs of the probes that are not
/// dilated following one another and adding up to the factor table's length, and each dilated
/// probe's run one of theirs ([`dilated_tables`]).
fn probe_records(asset: &Asset) -> Result<(), FormatError> {
    let h = &asset.header;
    let factors = &asset.factors;
    let mut next_factor = 0u64;
    let mut next_slot = 0u32;
    for (i, p) in asset.probes.iter().enumerate() {
        finite("probes", i, "position", &p.position)?;
        if p.sky_rays > h.ray_count {
            return Err(FormatError::invalid(
                "probes",
                i,
                format!("sky_rays {} exceed ray_count {}", p.sky_rays, h.ray_count),
            ));
        }
        if p.has_data() {
            if p.is_filled() || p.fill_level() != 0 {
                return Err(FormatError::invalid(
                    "probes",
                    i,
                    format!(
                        "slot {} and flags {:#x}: filled, yet with data",
                        p.slot, p.flags
                    ),
                ));
            }
            if p.slot != next_slot {
                return Err(FormatError::invalid(
                    "probes",
                    i,
                    format!("slot {} (expected {next_slot})", p.slot),
                ));
            }
            next_slot += 1;
        } else if p.flags
            & !(PROBE_OFFSET
                | PROBE_FILLED
                | FILL_LEVEL_MASK << FILL_LEVEL_SHIFT
                | FILL_HIDDEN_MASK << FILL_HIDDEN_SHIFT)
            != 0
            || (p.is_filled() != (p.fill_level() != 0))
            || (!p.is_filled() && p.fill_hidden() != 0)
            || p.factor_count != 0
            || p.sky_rays != 0
        {
            return Err(FormatError::invalid(
                "probes",
                i,
                format!(
                    "no data (slot {NO_SLOT:#x}) but flags {:#x}, factor_count {}, sky_rays {}",
                    p.flags, p.factor_count, p.sky_rays
                ),
            ));
        }
        if p.is_dilated() && !p.is_valid() {
            return Err(FormatError::invalid(
                "probes",
                i,
                format!("flags {:#x}: dilated but not valid", p.flags),
            ));
        }
        if p.is_dilated() {
            continue;
        }
        if u64::from(p.first_factor) != next_factor {
            return Err(FormatError::invalid(
                "probes",
                i,
                format!("first_factor {} (expected {next_factor})", p.first_factor),
            ));
        }
        next_factor += u64::from(p.factor_count);
    }
    if next_factor != factors.len() as u64 {
        return Err(FormatError::Count {
            section: "factors",
            found: factors.len(),
            expected: next_factor as usize,
        });
    }
    dilated_tables(asset)
}

/// A dilated probe carries no table of its own (format 12): its run is its source's, the
/// run of a probe with data that is not dilated (or empty), and in u8 tables holds no lobe
/// factor, since a lobe is decoded from the position of the probe that reads it and a
/// dilated probe reads its source's from elsewhere (`prt_format::FactorSlot`).
fn dilated_tables(asset: &Asset) -> Result<(), FormatError> {
    let own: std::collections::HashSet<(u32, u32)> = (asset.probes.iter())
        .filter(|p| p.has_data() && !p.is_dilated() && p.factor_count > 0)
        .map(|p| (p.first_factor, p.factor_count))
        .collect();
    for (i, p) in asset.probes.iter().enumerate() {
        if !p.is_dilated() {
            continue;
        }
        if p.factor_count == 0 {
            // An empty run (a source that saw only sky) starts anywhere in the table.
            if p.first_factor as usize > asset.factors.len() {
                return Err(FormatError::invalid(
                    "probes",
                    i,
                    format!(
                        "dilated, with first_factor {} past the table",
                        p.first_factor
                    ),
                ));
            }
            continue;
        }
        if !own.contains(&(p.first_factor, p.factor_count)) {
            return Err(FormatError::invalid(
                "probes",
                i,
                format!(
                    "dilated, with factors {}..{} that are no other probe's table",
                    p.first_factor,
                    u64::from(p.first_factor) + u64::from(p.factor_count)
                ),
            ));
        }
        if let Factors::U8 { factors, .. } = &asset.factors {
            let run = p.first_factor as usize..p.first_factor as usize + p.factor_count as usize;
            if let Some(f) = run
                .clone()
                .find(|&f| factors[f].rays() != 0 && !factors[f].is_full())
            {
                return Err(FormatError::invalid(
                    "probes",
                    i,
                    format!("dilated, with a lobe factor (slot {f}) in its source's table"),
                ));
            }
        }
    }
    Ok(())
}

/// Each filled grid point ([`PROBE_FILLED`], no data by [`probe_records`]): its level is one of
/// the tiers', among the points of that level it is interpolated from with a positive weight
/// ([`crate::tier::used_corners`]) one is valid, and none is filled itself (the runtime fills
/// every point in one pass, reading only gathered probes).
fn filled_points(asset: &Asset) -> Result<(), FormatError> {
    let grid = &asset.header.grid;
    for (index, p) in asset
        .probes
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_filled())
    {
        let level = p.fill_level();
        if !(1..=crate::tier::LEVELS).contains(&level) {
            return Err(FormatError::invalid(
                "probes",
                index,
                format!(
                    "filled from level {level} (flags {:#x}); levels run 1 to {}",
                    p.flags,
                    crate::tier::LEVELS
                ),
            ));
        }
        let ijk = grid.ijk(index);
        let used: Vec<(usize, Probe)> = crate::tier::used_corners(grid, ijk, level)
            .map(|(c, _)| (c, asset.probes[c]))
            .collect();
        let corners: Vec<String> = used.iter().map(|(c, _)| c.to_string()).collect();
        for &(c, corner) in &used {
            if corner.is_filled() {
                return Err(FormatError::invalid(
                    "probes",
                    index,
                    format!(
                        "filled from level {level} and probe {c}, which is filled itself (flags {:#x})",
                        corner.flags
                    ),
                ));
            }
        }
        if crate::tier::filled_from(grid, &asset.probes, index)
            .next()
            .is_none()
        {
            return Err(FormatError::invalid(
                "probes",
                index,
                format!(
                    "filled from level {level}, but none of the level's probes around it ({}) is valid among those it sees (hidden corners {:#x})",
                    corners.join(", "),
                    p.fill_hidden()
                ),
            ));
        }
    }
    Ok(())
}

/// The factor table: its offset scale, and each factor's brick, ray count and values.
fn factor_table(asset: &Asset) -> Result<(), FormatError> {
    let (h, factors) = (&asset.header, &asset.factors);
    if let Factors::U8 { offset_scale, .. } = factors {
        if !(offset_scale.is_finite() && *offset_scale > 0.0) {
            return Err(FormatError::invalid(
                "factors",
                0,
                format!("offset_scale {offset_scale}"),
            ));
        }
    }
    // Bricks, then coarse bricks (`crate::coarse`).
    let bricks = asset.bricks.len() + asset.coarse.bricks.len();
    // Packed factors decode to finite values whatever their bits (signed fields times a finite
    // scale, checked above, a DC term of at most 255 rays, and lobes about a direction that is
    // zero when it is not finite): only f32 and f16 can hold an infinity or a NaN. Decoding
    // every u8 factor to check it took 0.1 s of a 5-million-factor bake's serial assembly.
    let may_be_infinite = !matches!(factors, Factors::U8 { .. });
    if let Factors::U8 { factors: slots, .. } = factors {
        slot_pairs(asset, slots)?;
    }
    for f in 0..factors.len() {
        let (b, rays) = factors.brick_and_rays(f);
        if rays == 0 && matches!(factors, Factors::U8 { .. }) {
            // A continuation, paired with its head by `slot_pairs`.
            continue;
        }
        if b as usize >= bricks {
            return Err(FormatError::invalid(
                "factors",
                f,
                format!("brick {b} out of range (bricks and coarse bricks: {bricks})"),
            ));
        }
        if rays == 0 || rays > h.ray_count {
            return Err(FormatError::invalid(
                "factors",
                f,
                format!("ray count {rays} outside 1..={}", h.ray_count),
            ));
        }
        if may_be_infinite {
            finite(
                "factors",
                f,
                "transfer",
                &factors.transfer(f, h.ray_count, [0.0; 3]),
            )?;
            finite("factors", f, "offset", &factors.offset(f))?;
        }
    }
    Ok(())
}

/// The slots of a u8 table ([`crate::FactorSlot`]): every full head followed by a continuation
/// of its probe's table and every continuation after a full head, and no bits set beyond the
/// fields (a lobe head's fill its word).
fn slot_pairs(asset: &Asset, slots: &[crate::FactorSlot]) -> Result<(), FormatError> {
    let bad = |f: usize, what: String| Err(FormatError::invalid("factors", f, what));
    for (f, s) in slots.iter().enumerate() {
        let follows_full = f.checked_sub(1).is_some_and(|h| slots[h].is_full());
        if s.rays() == 0 {
            if !follows_full {
                return bad(
                    f,
                    format!("continuation slot {:#x} without a full head", s.bits),
                );
            }
            let v = u64::from(s.brick_rays) | u64::from(s.bits) << 32;
            if v >> (crate::TERMS_AT[7] + crate::SH_BITS[7]) != 0 {
                return bad(
                    f,
                    format!("continuation slot {v:#x}: bits beyond the terms"),
                );
            }
        } else {
            // A lobe head's fields fill its bits; a full head has no lobe codes.
            if s.is_full() && s.bits & !(crate::SLOT_FULL | ((1 << crate::R_AT) - 1)) != 0 {
                return bad(f, format!("full factor with lobe bits {:#x}", s.bits));
            }
            if s.is_full() && slots.get(f + 1).is_none_or(|c| c.rays() != 0) {
                return bad(f, "full factor without its continuation slot".to_string());
            }
        }
    }
    // Pairs inside one probe's table: none starts with a continuation or ends with a head.
    for (p, probe) in asset.probes.iter().enumerate() {
        let (first, count) = (probe.first_factor as usize, probe.factor_count as usize);
        if count == 0 {
            continue;
        }
        let last = &slots[first + count - 1];
        if slots[first].rays() == 0 || last.is_full() {
            return Err(FormatError::invalid(
                "probes",
                p,
                format!(
                    "factor table {first}..{} splits a full factor's slots",
                    first + count
                ),
            ));
        }
    }
    Ok(())
}

/// The bricks: finite bounds, flags, surfel runs that follow one another, and each surfel of a
/// brick inside its bounds and naming it.
fn bricks(asset: &Asset) -> Result<(), FormatError> {
    let mut next_surfel = 0u64;
    for (i, b) in asset.bricks.iter().enumerate() {
        finite("bricks", i, "min", &b.min)?;
        finite("bricks", i, "max", &b.max)?;
        // A packed surfel decodes its position from the extent: it must be finite too.
        let extent: [f32; 3] = std::array::from_fn(|a| b.max[a] - b.min[a]);
        finite("bricks", i, "max - min", &extent)?;
        finite("bricks", i, "centroid", &b.centroid)?;
        if b.surfel_count == 0 {
            return Err(FormatError::invalid("bricks", i, "no surfels"));
        }
        if b.flags & BRICK_AXIS_MASK >= 6 {
            return Err(FormatError::invalid(
                "bricks",
                i,
                format!("flags {:#x}", b.flags),
            ));
        }
        if u64::from(b.first_surfel) != next_surfel {
            return Err(FormatError::invalid(
                "bricks",
                i,
                format!("first_surfel {} (expected {next_surfel})", b.first_surfel),
            ));
        }
        next_surfel += u64::from(b.surfel_count);
        if next_surfel > asset.surfels.len() as u64 {
            return Err(FormatError::invalid(
                "bricks",
                i,
                format!(
                    "surfels end at {next_surfel} (surfels: {})",
                    asset.surfels.len()
                ),
            ));
        }
        let range = b.first_surfel as usize..next_surfel as usize;
        for (s, surfel) in asset.surfels[range.clone()].iter().enumerate() {
            let inside =
                (0..3).all(|a| surfel.position[a] >= b.min[a] && surfel.position[a] <= b.max[a]);
            if !inside {
                return Err(FormatError::invalid(
                    "surfels",
                    range.start + s,
                    format!(
                        "position {:?} outside its brick's bounds {:?}..{:?}",
                        surfel.position, b.min, b.max
                    ),
                ));
            }
            if surfel.brick as usize != i {
                return Err(FormatError::invalid(
                    "surfels",
                    range.start + s,
                    format!("brick {} but listed in brick {i}", surfel.brick),
                ));
            }
        }
    }
    count("surfels", asset.surfels.len(), next_surfel as usize)?;
    Ok(())
}

/// Each surfel's values: finite, with a positive weight.
fn surfels(surfels: &[Surfel]) -> Result<(), FormatError> {
    for (i, s) in surfels.iter().enumerate() {
        finite("surfels", i, "position", &s.position)?;
        finite("surfels", i, "normal", &s.normal)?;
        finite("surfels", i, "albedo", &s.albedo)?;
        finite("surfels", i, "emission", &s.emission)?;
        finite("surfels", i, "gradient", &s.gradient)?;
        if !(s.weight.is_finite() && s.weight > 0.0) {
            return Err(FormatError::invalid(
                "surfels",
                i,
                format!("weight {}", s.weight),
            ));
        }
    }
    Ok(())
}

/// The BVH: nodes and triangles together or neither, finite boxes, children after their
/// parent and in range, a tree (no shared children), a stack runtimes can hold, and finite
/// triangles.
fn geometry(geo: &Geometry) -> Result<(), FormatError> {
    let nodes = geo.nodes.len();
    let tris = geo.triangles.len();
    if (nodes == 0) != (tris == 0) {
        return Err(FormatError::invalid(
            "geometry",
            0,
            format!("{nodes} BVH nodes for {tris} triangles"),
        ));
    }
    for (i, n) in geo.nodes.iter().enumerate() {
        finite("geometry.nodes", i, "min", &n.min)?;
        finite("geometry.nodes", i, "max", &n.max)?;
        let ok = if n.count > 0 {
            u64::from(n.first) + u64::from(n.count) <= tris as u64
        } else {
            // Children come after their parent: traversal can never loop.
            (n.first as usize) > i && (n.first as usize) + 1 < nodes
        };
        if !ok {
            return Err(FormatError::invalid(
                "geometry.nodes",
                i,
                format!("first {} count {} out of range", n.first, n.count),
            ));
        }
    }
    // A tree: every node but the root is the child of exactly one node. Children after their
    // parent rule out loops, not sharing: a crafted BVH whose nodes share children (a DAG) would
    // make traversal exponential.
    let mut parents = vec![0u8; nodes];
    for n in geo.nodes.iter().filter(|n| n.count == 0) {
        for c in [n.first as usize, n.first as usize + 1] {
            parents[c] = parents[c].saturating_add(1);
        }
    }
    if let Some((i, &p)) = parents.iter().enumerate().skip(1).find(|(_, &p)| p != 1) {
        return Err(FormatError::invalid(
            "geometry.nodes",
            i,
            format!("the child of {p} nodes (a BVH must be a tree)"),
        ));
    }
    let stack = geo.stack_needed();
    if stack > MAX_BVH_STACK {
        return Err(FormatError::invalid(
            "geometry.nodes",
            0,
            format!("the BVH needs a traversal stack of {stack}, more than {MAX_BVH_STACK}"),
        ));
    }
    for (i, t) in geo.triangles.iter().enumerate() {
        finite("geometry.triangles", i, "v0", &t.v0)?;
        finite("geometry.triangles", i, "v1", &t.v1)?;
        finite("geometry.triangles", i, "v2", &t.v2)?;
    }
    Ok(())
}
