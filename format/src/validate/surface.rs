//! Validation of the surface terms ([`crate::surface`]): the runtime indexes every table
//! unchecked, on the CPU and in WGSL, so an asset is refused unless every index, range and
//! search bound holds.

use crate::asset::Asset;
use crate::error::FormatError;
use crate::surface::{
    near_entry, slot_hash, SurfaceTerms, CELL_WORDS, NO_SURFEL, SIDE_BIT, SLOT_AXIS_SHIFT,
};
use crate::surfel_terms::{CENTRE_SHIFT, MAX_CENTRE_CODE};

fn bad(index: usize, what: String) -> Result<(), FormatError> {
    Err(FormatError::invalid("surface", index, what))
}

fn count(found: usize, expected: usize) -> Result<(), FormatError> {
    if found == expected {
        Ok(())
    } else {
        Err(FormatError::Count {
            section: "surface",
            found,
            expected,
        })
    }
}

/// None at all, or: a header of finite positive sizes; a power-of-two table naming bricks that
/// exist, whose longest search is what its slots need; a cell table per brick naming its own
/// surfels or those of the parts after it under its key (`surface_key_runs`, format 13);
/// per brick, near groups that tile its surfels in order; per surfel, terms whose centre code,
/// hit count and group (counted from its key's first brick) are in range and whose spare bits
/// are zero (format 16: every code decodes to a finite value) but [`SIDE_BIT`]; near fields in
/// range naming groups that exist; a sky term per surfel in [-2, 2]; sides (format 18) sorted
/// by surfel, one per surfel with [`SIDE_BIT`], naming a traced partner of the same key's run
/// with a finite plane. A slot's key is its brick's.
pub(super) fn surface_terms(asset: &Asset) -> Result<(), FormatError> {
    let st = &asset.surface;
    let empty = st.slots.is_empty()
        && st.cells.is_empty()
        && st.surfels.is_empty()
        && st.groups.is_empty()
        && st.group_surfels.is_empty()
        && st.near_ranges.is_empty()
        && st.near.is_empty()
        && st.sky.is_empty()
        && st.sides.is_empty();
    if st.header.brick_size == 0.0 && empty {
        return Ok(());
    }
    header_and_table(st, asset.bricks.len())?;
    let runs = crate::asset::surface_key_runs(st, &asset.bricks);
    // The lookup counts a surfel's group from the brick the table names: the first of its
    // key's run, as the cells and groups are checked below.
    let named = (st.slots.iter().enumerate()).filter_map(|(i, s)| Some((i, s.brick()? as usize)));
    for (i, brick) in named {
        // The lookup's key is the slot's; the centre probe it reads is the brick's key's.
        if st.key_of(asset.bricks[brick].centroid) != st.slots[i].key {
            return bad(
                i,
                format!("slot key {:?} is not its brick {brick}'s", st.slots[i].key),
            );
        }
        if runs[brick].0 as usize != brick {
            return bad(
                i,
                format!("slot names brick {brick}, not the first of its key's"),
            );
        }
    }
    cells(asset, &runs)?;
    groups(asset)?;
    surfels(asset, &runs)?;
    near(st)?;
    sky(st)?;
    sides(asset, &runs)
}

/// Sides ([`crate::surface::SurfaceSide`]): sorted by surfel without repeats, exactly the
/// surfels with [`SIDE_BIT`]; the partner another traced surfel of the same key's run (whose
/// group the lookup counts from the same first brick); the plane's offset finite.
fn sides(asset: &Asset, runs: &[(u32, u32)]) -> Result<(), FormatError> {
    let st = &asset.surface;
    let flagged = st
        .surfels
        .iter()
        .filter(|t| t.open_l2 & SIDE_BIT != 0)
        .count();
    count(st.sides.len(), flagged)?;
    let n = st.surfels.len();
    for (i, side) in st.sides.iter().enumerate() {
        let (s, p) = (side.surfel as usize, side.partner as usize);
        let why = if i > 0 && st.sides[i - 1].surfel >= side.surfel {
            "not after the side before it (sorted by surfel, one each)"
        } else if s >= n || p >= n || s == p {
            "a surfel or partner that does not exist, or the surfel itself"
        } else if st.surfels[s].open_l2 & SIDE_BIT == 0 {
            "a surfel without the side bit"
        } else if !st.surfels[p].is_traced() {
            "a partner whose terms were not traced"
        } else if runs[asset.surfels[s].brick as usize].0 != runs[asset.surfels[p].brick as usize].0
        {
            "a partner of another key's run (its group would count from another brick)"
        } else if !side.offset.is_finite() {
            "a plane offset that is not a number"
        } else {
            continue;
        };
        return bad(i, format!("side {side:?} of {n} surfels: {why}"));
    }
    Ok(())
}

/// Two halves a word, one per surfel, each in [-2, 2] (a share of the hemisphere less what the
/// probes' clamped sky brings: [-1, 1] but for L2's ringing).
fn sky(st: &SurfaceTerms) -> Result<(), FormatError> {
    count(st.sky.len(), st.surfels.len().div_ceil(2))?;
    for s in 0..st.surfels.len() {
        let v = crate::surface::sky_term(&st.sky, s);
        if !(-2.0..=2.0).contains(&v) {
            return bad(s, format!("sky term {v}"));
        }
    }
    Ok(())
}

fn header_and_table(st: &SurfaceTerms, bricks: usize) -> Result<(), FormatError> {
    let h = &st.header;
    let sizes_ok = h.anchor.iter().all(|v| v.is_finite())
        && h.brick_size.is_finite()
        && h.brick_size > 0.0
        && h.reach.is_finite()
        && h.reach >= 0.0
        && (1..=u32::from(u8::MAX)).contains(&h.rays);
    if !sizes_ok {
        return bad(0, format!("header {h:?}"));
    }
    let len = st.slots.len();
    if !len.is_power_of_two() {
        return bad(0, format!("{len} slots: not a power of two"));
    }
    // The longest search the slots need: a larger bound lets every miss walk the table.
    let mut longest = 0u32;
    for (i, s) in st.slots.iter().enumerate() {
        if s.value == 0 {
            continue;
        }
        let axis = s.value >> SLOT_AXIS_SHIFT;
        if s.brick().is_none_or(|b| b as usize >= bricks) || axis >= 6 {
            return bad(i, format!("slot value {:#x} (bricks: {bricks})", s.value));
        }
        let home = slot_hash(s.key, axis) as usize & (len - 1);
        longest = longest.max(((i + len - home) & (len - 1)) as u32);
    }
    if h.max_probe != longest {
        return bad(
            0,
            format!("longest search {} (the slots need {longest})", h.max_probe),
        );
    }
    Ok(())
}

fn cells(asset: &Asset, runs: &[(u32, u32)]) -> Result<(), FormatError> {
    let st = &asset.surface;
    count(st.cells.len(), asset.bricks.len() * CELL_WORDS)?;
    for (b, brick) in asset.bricks.iter().enumerate() {
        let words = &st.cells[b * CELL_WORDS..(b + 1) * CELL_WORDS];
        let bytes = words.iter().flat_map(|w| w.to_le_bytes());
        let mut named = bytes.filter(|&s| s != NO_SURFEL);
        // Its own surfels and those of the parts after it under its key.
        let end = &asset.bricks[runs[b].1 as usize - 1];
        let surfels = u64::from(end.first_surfel) + u64::from(end.surfel_count)
            - u64::from(brick.first_surfel);
        if let Some(s) = named.find(|&s| u64::from(s) >= surfels) {
            return bad(b, format!("cell names surfel {s} of {surfels}"));
        }
    }
    Ok(())
}

/// Per brick, its groups `groups[b]..groups[b + 1]` (the last brick's up to the group count)
/// tile its surfels in order, each group non-empty.
fn groups(asset: &Asset) -> Result<(), FormatError> {
    let st = &asset.surface;
    let total = st.group_surfels.len();
    count(st.groups.len(), asset.bricks.len())?;
    count(st.near_ranges.len(), total)?;
    for (b, brick) in asset.bricks.iter().enumerate() {
        let first = st.groups[b] as usize;
        let next = st.groups.get(b + 1).map_or(total, |&g| g as usize);
        if (b == 0 && first != 0) || first >= next || next > total {
            return bad(b, format!("near groups {first}..{next} (groups: {total})"));
        }
        let mut at = u64::from(brick.first_surfel);
        for (g, &[start, n]) in st.group_surfels[first..next].iter().enumerate() {
            if u64::from(start) != at || n == 0 {
                return bad(
                    first + g,
                    format!("group surfels {start}+{n}, expected from {at}"),
                );
            }
            at += u64::from(n);
        }
        if at != u64::from(brick.first_surfel) + u64::from(brick.surfel_count) {
            return bad(b, format!("near groups end at surfel {at}"));
        }
    }
    Ok(())
}

fn surfels(asset: &Asset, runs: &[(u32, u32)]) -> Result<(), FormatError> {
    let st = &asset.surface;
    let h = &st.header;
    count(st.surfels.len(), asset.surfels.len())?;
    for (b, brick) in asset.bricks.iter().enumerate() {
        // A surfel's group counts from the first brick under its key's.
        let (run_first, run_end) = runs[b];
        let first = st.groups[run_first as usize] as usize;
        let next = st
            .groups
            .get(run_end as usize)
            .map_or(st.group_surfels.len(), |&g| g as usize);
        let range = brick.first_surfel as usize..(brick.first_surfel + brick.surfel_count) as usize;
        for (i, t) in st.surfels[range.clone()].iter().enumerate() {
            // Every code decodes to a finite value; the spare bit 30 stays zero (31 is SIDE_BIT).
            let ok = t.hits() <= h.rays
                && (t.group() as usize) < next - first
                && t.open_l2 >> 30 & 1 == 0
                && t.mask >> CENTRE_SHIFT <= MAX_CENTRE_CODE;
            if !ok {
                return bad(
                    range.start + i,
                    format!(
                        "surfel terms {t:?}: centre code {} (at most {MAX_CENTRE_CODE}), hits {} of {} rays, group {} of {}, spare bit 30 {}",
                        t.mask >> CENTRE_SHIFT,
                        t.hits(),
                        h.rays,
                        t.group(),
                        next - first,
                        t.open_l2 >> 30 & 1
                    ),
                );
            }
        }
    }
    Ok(())
}

fn near(st: &SurfaceTerms) -> Result<(), FormatError> {
    for (g, &[first, n]) in st.near_ranges.iter().enumerate() {
        if u64::from(first) + u64::from(n) > st.near.len() as u64 {
            return bad(
                g,
                format!("near field {first}+{n} (entries: {})", st.near.len()),
            );
        }
    }
    let groups = st.group_surfels.len() as u64;
    if let Some(i) = st
        .near
        .iter()
        .position(|&e| u64::from(near_entry(e).0) >= groups)
    {
        let g = near_entry(st.near[i]).0;
        return bad(i, format!("near entry names group {g} of {groups}"));
    }
    Ok(())
}
