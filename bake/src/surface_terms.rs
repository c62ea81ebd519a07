//! # Surface terms: which probes each surfel sees, and its near field (issue 31)
//!
//! The lookup's leaks come from what probes a spacing away cannot know about the surface a
//! point lies on (`prt_format::surface` says what is stored and how the lookup uses it). This
//! stage traces it from every front-face surfel, after the bricks are final:
//!
//! 1. **The brick table**: each front-face brick under its key (lattice cell of its centroid,
//!    dominant axis) in an open-addressed hash table (of a brick split at a wall, the first
//!    part), and per brick the nearest surfel of each of its 4x4x4 cells, its own or a later
//!    part's.
//!    Where a wall crosses a cell (its hits were kept apart by side, `crate::merge::sides`),
//!    the cell's named surfel lists the wall's plane and the surfel beyond it
//!    ([`sides::sides_of`]).
//! 2. **Probe visibility**: a ray from the surfel to each of the 27 probes around its nearest
//!    one (to where the probe's rays started), through the scene's BVH. Every ray of this
//!    stage and of `crate::sky_terms` starts at [`surfel_origin`]: off the surfel along its
//!    normal, and past its surface where the surfel lies inside a solid.
//! 3. **Near field**: [`RAYS`] cosine-distributed rays (a Fibonacci spiral about the normal)
//!    no longer than [`REACH`] spacings. An escaping ray adds its SH9 basis values to the
//!    surfel's `open`; a ray that hits finds the brick of the surface it hits (its key, facing
//!    axis; else the nearest centroid of that axis among the 26 neighbouring keys) and adds one
//!    hit there to its near group's field (`group_surfels` says why groups).
//!
//! [`RAYS`] and [`REACH`] were chosen on the level family's tuning seeds with `prt-bench
//! surface` (`docs/results/surface_candidates.md`): 64 rays measure as 256 do (median level
//! 10.0% against 10.0%, worst 18.1% against 17.8%), 32 worse (10.3%, 18.4%, leaks 2.3% against
//! 1.7%) for a third less of this stage's time, and a reach of one spacing was the best of
//! 0.5 / 0.75 / 1.0 / 1.5 / 3.0 once hits bring their surface's light.
//!
//! Deterministic: bricks are processed in parallel but each one's terms depend only on the
//! asset and fixed ray sets, and are put together in brick order.

use std::collections::BTreeMap;

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_format::surface::{
    centre_probe, mask_bit, slot_hash, SurfaceSide, SurfaceSlot, SurfaceTerms, SurfelTerms,
    SurfelTermsHeader, CELL_WORDS, MAX_GROUPS, MAX_TABLE_BRICKS, NEAR_WEIGHT_BITS, NO_SURFEL,
    PROBE_BITS, SIDE_BIT, SLOT_AXIS_SHIFT,
};
use prt_format::surfel_terms::{centre_code, CENTRE_SHIFT};
use prt_format::{Brick, Grid, Surfel, BRICK_AXIS_MASK, BRICK_BACKFACE};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::merge::key::dominant_axis;
use crate::merge::sides;

/// Near-field rays per surfel.
pub const RAYS: u32 = 64;

/// Reach of the near-field rays, in probe spacings.
pub const REACH: f32 = 1.0;

/// A cell names its brick's nearest surfel only within this many cells of it: a point farther
/// from every surfel (a part of the surface no probe ray hit) gets the probe volume's lookup
/// rather than terms traced elsewhere. Tuning seeds: half spacing 6.6% -> 6.2% median, leaks
/// 1.0% -> 0.7% (default spacing unchanged); 0.5 cells raised the default spacing's median to
/// 11.1%.
const CELL_GAP: f32 = 1.0;

/// Where a surfel's rays start: this many spacings along its normal (1 cm on a 1 m grid), or
/// [`START_MAGNITUDE`] of its coordinates' magnitude if more (float steps far from the origin).
const START: f32 = 0.01;
const START_MAGNITUDE: f32 = 1e-6;

/// What the stage reads.
pub struct Inputs<'a> {
    pub bricks: &'a [Brick],
    pub grid: &'a Grid,
    /// Per probe (grid order), where its rays started.
    pub probes: &'a [Vec3],
    pub bvh: &'a SceneBvh,
    /// The scene's triangles, by the BVH's triangle index (the normals of near hits).
    pub triangles: &'a [[Vec3; 3]],
    /// Edge of a surfel cell (the bake's merge distance); 0: merging off, no terms.
    pub cell_size: f32,
    /// The fold's normal agreement (`BakeSettings::merge_normal_cos`): which surfels of a cell
    /// a wall parted ([`sides::Pairing`]).
    pub merge_normal_cos: f32,
}

/// The surface terms of `input`'s bricks and `surfels` (empty when merging is off or the
/// bricks or groups overflow the tables). Reorders each brick's surfels so that its near
/// groups are consecutive.
pub fn surface_terms(input: &Inputs, surfels: &mut [Surfel]) -> SurfaceTerms {
    if input.cell_size <= 0.0 || input.bricks.len() > MAX_TABLE_BRICKS as usize {
        return SurfaceTerms::default();
    }
    let brick_size = 4.0 * input.cell_size;
    // The bake's brick lattice: half a cell off the origin (`merge::fold::BrickFolder::new`).
    let anchor = Vec3::splat(-0.5 * input.cell_size);
    let mut terms = SurfaceTerms {
        header: SurfelTermsHeader {
            anchor: anchor.to_array(),
            brick_size,
            max_probe: 0,
            rays: RAYS,
            reach: REACH,
        },
        ..SurfaceTerms::default()
    };
    table(&mut terms, input.bricks);
    let mut grouped = group_surfels(&mut terms, input, surfels);
    if terms.group_surfels.len() > MAX_GROUPS as usize {
        return SurfaceTerms::default();
    }
    let runs = prt_format::surface_key_runs(&terms, input.bricks);
    let nameable = from_first_parts(&terms, input.bricks, &runs, &mut grouped);
    // A side names a partner whose terms the lookup can read and whose group it can count.
    let eligible: Vec<bool> = (nameable.iter().zip(&grouped.traced))
        .map(|(&n, &(mask, _))| n && mask >> CENTRE_SHIFT != 0)
        .collect();
    let (cells, sides): (Vec<[u32; CELL_WORDS]>, Vec<Vec<SurfaceSide>>) =
        (input.bricks.par_iter().zip(&runs).enumerate())
            .map(|(i, (b, &(first, end)))| {
                let last = &input.bricks[end as usize - 1];
                let end = (last.first_surfel + last.surfel_count) as usize;
                let table = cells(&terms, b, &surfels[..end], &nameable);
                // Only the first brick of a key's run is looked up.
                let pairing = sides::Pairing {
                    bvh: input.bvh,
                    triangles: input.triangles,
                    surfels: &surfels[..end],
                    eligible: &eligible,
                    merge_normal_cos: input.merge_normal_cos,
                };
                let sides = match first as usize == i {
                    true => sides::sides_of(&terms, &pairing, b, &table),
                    false => Vec::new(),
                };
                (table, sides)
            })
            .unzip();
    terms.cells = cells.into_iter().flatten().collect();
    terms.sides = sides.into_iter().flatten().collect();
    // A surfel lies in one cell: one side at most, so the order is strict.
    terms.sides.sort_by_key(|s| s.surfel);
    debug_assert!(terms.sides.windows(2).all(|w| w[0].surfel < w[1].surfel));
    let surfels = &*surfels;
    let traced: Vec<(SurfelTerms, Vec<NearHit>)> = (0..surfels.len())
        .into_par_iter()
        .map(|i| near_field(input, &surfels[i], grouped.traced[i], grouped.group[i]))
        .collect();
    let fields: Vec<Vec<u32>> = terms
        .group_surfels
        .par_iter()
        .map(|&[first, n]| {
            let hits = traced[first as usize..(first + n) as usize].iter();
            field(&terms, input.bricks, &grouped.group, hits.map(|t| &t.1))
        })
        .collect();
    terms.surfels = traced.into_iter().map(|(t, _)| t).collect();
    for side in &terms.sides {
        terms.surfels[side.surfel as usize].open_l2 |= SIDE_BIT;
    }
    for field in fields {
        let first = terms.near.len() as u32;
        terms.near_ranges.push([first, field.len() as u32]);
        terms.near.extend(field);
    }
    terms
}

/// A near hit: where, and the dominant axis of the side of the surface that faces the ray.
type NearHit = (Vec3, u32);

/// Per surfel (in their new order), its probe mask and ray origin ([`origin`]; a back-face
/// surfel's mask is 0 and its origin unused), and its group: counted from its key's first
/// brick's groups (within its brick until [`from_first_parts`]), and absolute.
struct Grouped {
    traced: Vec<Traced>,
    group: Vec<(u8, u32)>,
}

/// A surfel's probe mask and ray origin.
type Traced = (u32, Vec3);

/// Traces each surfel's probe mask, groups each brick's surfels by mask and reorders them
/// group by group. Surfels that see the same probes are on the same side of whatever stands
/// on their brick: the floor on both sides of a thin wall is one brick, and one near field per
/// brick brought the lit side's light to the dark side (fixtures/two_rooms at half spacing:
/// 9.0% against 6.3% per surfel). Groups in order of first appearance, at most 256 per brick
/// (further masks join the last). Fills `groups` and `group_surfels`.
fn group_surfels(terms: &mut SurfaceTerms, input: &Inputs, surfels: &mut [Surfel]) -> Grouped {
    // Per brick: masks, origins and group (within the brick) of its surfels, in their old
    // order.
    let view = &*terms;
    let per_brick: Vec<(Vec<Traced>, Vec<u8>)> = input
        .bricks
        .par_iter()
        .map(|b| {
            let range = b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize;
            if b.flags & BRICK_BACKFACE != 0 {
                return (vec![(0, Vec3::ZERO); range.len()], vec![0; range.len()]);
            }
            let key_centre = view.brick_centre(input.grid, b);
            let traced: Vec<Traced> = surfels[range]
                .iter()
                .map(|s| {
                    let o = origin(input, s);
                    (probe_mask(input, s, o, key_centre), o)
                })
                .collect();
            // Grouped by the bits alone, whatever probe they are about (as in format 15).
            let mut distinct: Vec<u32> = Vec::new();
            let group = traced
                .iter()
                .map(|(m, _)| m & PROBE_BITS)
                .map(|m| match distinct.iter().position(|&d| d == m) {
                    Some(g) => g as u8,
                    None if distinct.len() < 256 => {
                        distinct.push(m);
                        (distinct.len() - 1) as u8
                    }
                    None => 255,
                })
                .collect();
            (traced, group)
        })
        .collect();
    let mut out = Grouped {
        traced: Vec::with_capacity(surfels.len()),
        group: Vec::with_capacity(surfels.len()),
    };
    for (b, (traced, group)) in input.bricks.iter().zip(per_brick) {
        let first = b.first_surfel as usize;
        let mut order: Vec<usize> = (0..traced.len()).collect();
        order.sort_by_key(|&i| group[i]);
        let moved: Vec<Surfel> = order.iter().map(|&i| surfels[first + i]).collect();
        surfels[first..first + moved.len()].copy_from_slice(&moved);
        let first_group = terms.group_surfels.len() as u32;
        terms.groups.push(first_group);
        for (k, &i) in order.iter().enumerate() {
            let g = group[i];
            if k == 0 || group[order[k - 1]] != g {
                terms.group_surfels.push([(first + k) as u32, 0]);
            }
            terms.group_surfels.last_mut().expect("pushed")[1] += 1;
            out.traced.push(traced[i]);
            out.group.push((g, terms.group_surfels.len() as u32 - 1));
        }
        debug_assert!(first_group < terms.group_surfels.len() as u32);
    }
    out
}

/// Counts each surfel's group from the first brick under its key (`runs`,
/// `prt_format::surface_key_runs`): the lookup finds the first part of a split brick in the
/// table and reads its groups from there. Returns per surfel whether a cell of the first part
/// may name it: not when its group lies more than 255 past the first part's.
fn from_first_parts(
    terms: &SurfaceTerms,
    bricks: &[Brick],
    runs: &[(u32, u32)],
    grouped: &mut Grouped,
) -> Vec<bool> {
    let mut nameable = vec![true; grouped.group.len()];
    for (b, (brick, &(first, _))) in bricks.iter().zip(runs).enumerate() {
        if first as usize == b {
            continue;
        }
        let base = terms.groups[first as usize];
        let range = brick.first_surfel as usize..(brick.first_surfel + brick.surfel_count) as usize;
        for i in range {
            let relative = grouped.group[i].1 - base;
            grouped.group[i].0 = relative.min(255) as u8;
            nameable[i] = relative <= 255;
        }
    }
    nameable
}

/// A group's near field from its surfels' near hits: per group hit, its share of all the
/// hits (those that find no brick bring nothing) in 255ths, rounded so that the shares keep
/// their sum (largest remainders); groups whose share rounds to nothing are left out.
fn field<'a>(
    terms: &SurfaceTerms,
    bricks: &[Brick],
    group: &[(u8, u32)],
    hits: impl Iterator<Item = &'a Vec<NearHit>>,
) -> Vec<u32> {
    let mut counts: BTreeMap<u32, u32> = BTreeMap::new();
    let mut total = 0u32;
    for &(h, axis) in hits.flatten() {
        total += 1;
        let Some(j) = brick_at(terms, bricks, h, axis) else {
            continue;
        };
        let b = &bricks[j as usize];
        let key = terms.key_of(b.centroid);
        if let Some(within) = terms.surfel_in(j, key, h.to_array()) {
            // The surfel of the hit's side of a wall in its cell, as the lookup finds it.
            let named = b.first_surfel + within;
            let s = terms.side_beyond(named, key, h.to_array()).unwrap_or(named);
            *counts.entry(group[s as usize].1).or_default() += 1;
        }
    }
    let unit = ((1u32 << NEAR_WEIGHT_BITS) - 1) as f64;
    let resolved: u32 = counts.values().sum();
    let target = (unit * f64::from(resolved) / f64::from(total.max(1))).round() as u32;
    let quota = |n: u32| unit * f64::from(n) / f64::from(total);
    let mut shares: Vec<(u32, u32, f64)> = counts
        .iter()
        .map(|(&g, &n)| (g, quota(n).floor() as u32, quota(n).fract()))
        .collect();
    let given: u32 = shares.iter().map(|s| s.1).sum();
    let mut by_remainder: Vec<usize> = (0..shares.len()).collect();
    by_remainder.sort_by(|&a, &b| shares[b].2.total_cmp(&shares[a].2).then(a.cmp(&b)));
    for &i in by_remainder
        .iter()
        .take(target.saturating_sub(given) as usize)
    {
        shares[i].1 += 1;
    }
    shares
        .into_iter()
        .filter(|s| s.1 > 0)
        .map(|(g, w, _)| g << NEAR_WEIGHT_BITS | w)
        .collect()
}

/// Fills the hash table with the front-face bricks (a second brick under a key already
/// taken is left out: a later part of a brick split at a wall, or a brick whose centroid
/// float rounding put on a lattice plane).
fn table(terms: &mut SurfaceTerms, bricks: &[Brick]) {
    let front = bricks.iter().filter(|b| b.flags & BRICK_BACKFACE == 0);
    let len = (2 * front.count()).next_power_of_two().max(1);
    let mut slots = vec![SurfaceSlot::default(); len];
    let mask = len as u32 - 1;
    let mut max_probe = 0;
    for (i, b) in bricks.iter().enumerate() {
        if b.flags & BRICK_BACKFACE != 0 {
            continue;
        }
        let key = terms.key_of(b.centroid);
        let axis = b.flags & BRICK_AXIS_MASK;
        let start = slot_hash(key, axis);
        for probe in 0..len as u32 {
            let s = &mut slots[(start.wrapping_add(probe) & mask) as usize];
            if s.value == 0 {
                *s = SurfaceSlot {
                    key,
                    value: axis << SLOT_AXIS_SHIFT | (i as u32 + 1),
                };
                max_probe = max_probe.max(probe);
                break;
            }
            if s.key == key && s.value >> SLOT_AXIS_SHIFT == axis {
                break;
            }
        }
    }
    terms.slots = slots;
    terms.header.max_probe = max_probe;
}

/// The [`CELL_WORDS`] words of brick `b`: per cell, the surfel nearest the cell's centre
/// (among the first 255 from its first, its own and those of the parts after it under its key:
/// `surfels` ends with the last of them) within [`CELL_GAP`] cells of the cell, or
/// [`NO_SURFEL`]. A part's surfel whose group the first part cannot count to is not named.
fn cells(
    terms: &SurfaceTerms,
    b: &Brick,
    surfels: &[Surfel],
    nameable: &[bool],
) -> [u32; CELL_WORDS] {
    let mut words = [0u32; CELL_WORDS];
    let key = terms.key_of(b.centroid);
    let cell = terms.header.brick_size / 4.0;
    let first = b.first_surfel as usize;
    let own = &surfels[first..surfels.len().min(first + 255)];
    for c in 0..64u32 {
        let centre = Vec3::from(terms.cell_centre(key, c as usize));
        let lo = centre - Vec3::splat(0.5 * cell);
        let hi = centre + Vec3::splat(0.5 * cell);
        let nearest = own
            .iter()
            .enumerate()
            .filter(|&(i, _)| nameable[first + i])
            .filter(|(_, s)| {
                let p = Vec3::from(s.position);
                (p.clamp(lo, hi) - p).length() <= CELL_GAP * cell
            })
            .min_by(|(_, a), (_, b)| {
                let d = |s: &Surfel| Vec3::from(s.position).distance_squared(centre);
                d(a).total_cmp(&d(b))
            })
            .map_or(NO_SURFEL, |(i, _)| i as u8);
        words[c as usize / 4] |= u32::from(nearest) << (8 * (c % 4));
    }
    words
}

/// A surfel's terms (with its `mask` and ray origin `o`, and its `group`, [`Grouped`]) and its
/// near hits.
fn near_field(
    input: &Inputs,
    s: &Surfel,
    (mask, o): Traced,
    group: (u8, u32),
) -> (SurfelTerms, Vec<NearHit>) {
    if mask >> CENTRE_SHIFT == 0 {
        let untraced = SurfelTerms {
            mask,
            group_open: u32::from(group.0),
            ..SurfelTerms::default()
        };
        return (untraced, Vec::new());
    }
    let n = Vec3::from(s.normal);
    let reach = REACH * input.grid.spacing;
    let (tx, ty) = n.any_orthonormal_pair();
    let dirs: [Vec3; RAYS as usize] =
        std::array::from_fn(|k| cosine_spiral(k as u32, RAYS, tx, ty, n));
    let mut open = [0.0f32; SH_COUNT];
    let mut hits = Vec::new();
    for packet in dirs.chunks(PACKET) {
        let traced = input.bvh.closest_hits(o, packet, reach);
        for (&d, hit) in packet.iter().zip(traced) {
            let Some(hit) = hit else {
                let y = prt_format::sh::basis(d.to_array());
                (0..SH_COUNT).for_each(|i| open[i] += y[i]);
                continue;
            };
            let [v0, v1, v2] = input.triangles[hit.triangle as usize];
            let normal = (v1 - v0).cross(v2 - v0);
            let facing = if normal.dot(d) > 0.0 { -normal } else { normal };
            hits.push((o + d * hit.t, dominant_axis(facing)));
        }
    }
    let open = open.map(|v| v / RAYS as f32);
    let t = SurfelTerms::new(mask, group.0, s.normal, hits.len() as u8, &open, RAYS);
    (t, hits)
}

/// Where a surfel's rays start ([`surfel_origin`]), traced once for its probe mask and its
/// near field.
fn origin(input: &Inputs, s: &Surfel) -> Vec3 {
    let (p, n) = (Vec3::from(s.position), Vec3::from(s.normal));
    surfel_origin(input.bvh, p, n, (input.grid.spacing, input.cell_size))
}

/// Rays of [`surfel_origin`]'s enclosure test (one packet).
const ENCLOSURE_RAYS: u32 = 16;

/// A surfel's ray origin is enclosed when every ray of [`surfel_origin`]'s test hits within
/// this many surfel cells of it.
const ENCLOSED: f32 = 0.5;

// The test is one packet and its hits one mask word.
const _: () = assert!(ENCLOSURE_RAYS as usize <= PACKET && ENCLOSURE_RAYS < 32);

/// Where the rays of the surfel at `p` with unit normal `n` start, on a grid of `spacing` with
/// surfel cells of `cell` (0: unmerged, [`ray_origin`] as it is): [`ray_origin`], unless every
/// one of [`ENCLOSURE_RAYS`] cosine-distributed rays from there hits a surface within
/// [`ENCLOSED`] cells and no surface lies just behind it (the surfel's own, where it stands
/// on one), when the origin is taken past the first surface along the normal.
///
/// Why: a merged surfel sits at the mean of its hits, which on a curved surface lies behind it;
/// `crate::merge::snap` puts it back on a surface about parallel to it, but across an arch or
/// a column's bevel the surface ahead may be turned by more than the snap's 45 degrees. From
/// inside the solid every near-field ray then hits within a few centimetres, on faces no light
/// reaches, and the lookup turned the points it serves black: Sponza under its sun, baked at
/// 1.55 m with its bounds' minimum 0.78 m lower along z (`docs/results/surface_enclosed.md`), had two
/// open points at 0 whose surfels sat 2 cm inside an arch, rays hitting within 3-41 mm. A gap
/// between two walls is not enclosed: its rays along the walls run on.
pub(crate) fn surfel_origin(bvh: &SceneBvh, p: Vec3, n: Vec3, (spacing, cell): (f32, f32)) -> Vec3 {
    let o = ray_origin(p, n, spacing);
    if cell <= 0.0 {
        return o;
    }
    let (tx, ty) = n.any_orthonormal_pair();
    let dirs: [Vec3; ENCLOSURE_RAYS as usize] =
        std::array::from_fn(|k| cosine_spiral(k as u32, ENCLOSURE_RAYS, tx, ty, n));
    let reach = ENCLOSED * cell;
    if bvh.occluded(o, &dirs, reach) != (1 << ENCLOSURE_RAYS) - 1 {
        return o;
    }
    let Some(ahead) = bvh.closest_hit(o, n, reach) else {
        return o;
    };
    // A surface behind the origin within twice its offset is the surfel's own: it stands on
    // it, in a pocket (a floor under a crate 2 cm above), not inside a solid. Whichever way
    // the faces are wound: a double-sided bake's windings may be anything.
    if bvh.closest_hit(o, -n, 2.0 * o.distance(p)).is_some() {
        return o;
    }
    ray_origin(o + n * ahead.t, n, spacing)
}

/// Where rays from a surfel at `p` with unit normal `n` start on a grid of `spacing`: [`START`]
/// spacings along the normal, or [`START_MAGNITUDE`] of the coordinates' magnitude if more
/// ([`surfel_origin`] starts from it).
fn ray_origin(p: Vec3, n: Vec3, spacing: f32) -> Vec3 {
    p + n * (START * spacing).max(START_MAGNITUDE * p.abs().max_element())
}

/// A front-face surfel's [`SurfelTerms::mask`]: the probes around its nearest probe that it
/// sees from its ray origin `o`, and that probe's code from `key_centre`, its brick key's
/// (`SurfaceTerms::brick_centre`; where the probe grid is too fine for its bricks for the code
/// to reach the surfel's nearest probe, the nearest probe the code names).
fn probe_mask(input: &Inputs, s: &Surfel, o: Vec3, key_centre: [i32; 3]) -> u32 {
    let g = input.grid;
    let nearest = centre_probe(g.origin, g.step, g.counts, s.position);
    let offset: [i32; 3] = std::array::from_fn(|a| (nearest[a] - key_centre[a]).clamp(-1, 1));
    let centre = std::array::from_fn(|a| key_centre[a] + offset[a]);
    centre_code(offset) | visible_probes(input, o, centre)
}

/// Mask bits of the 27 probes around grid position `centre` that a ray from `o` reaches
/// (probes outside the grid, or at `o`, count as seen: no lookup reads the former). One
/// packet: the rays run to the probes themselves (directions of their length, `tmax` 1).
fn visible_probes(input: &Inputs, o: Vec3, centre: [i32; 3]) -> u32 {
    let g = input.grid;
    let mut mask = 0;
    let (mut bits, mut dirs) = (Vec::with_capacity(27), Vec::with_capacity(27));
    for bit in 0..27 {
        let d = [bit % 3, bit / 3 % 3, bit / 9].map(|v| v as i32 - 1);
        let ijk: [i32; 3] = std::array::from_fn(|a| centre[a] + d[a]);
        debug_assert_eq!(mask_bit(centre, ijk), Some(bit));
        let inside = (0..3).all(|a| ijk[a] >= 0 && (ijk[a] as u32) < g.counts[a]);
        let to = match inside {
            true => input.probes[g.index(ijk[0] as u32, ijk[1] as u32, ijk[2] as u32)] - o,
            false => Vec3::ZERO,
        };
        if to.length_squared() > 0.0 {
            bits.push(bit);
            dirs.push(to);
        } else {
            mask |= 1 << bit;
        }
    }
    let blocked = input.bvh.occluded(o, &dirs, 1.0);
    for (j, bit) in bits.into_iter().enumerate() {
        if blocked >> j & 1 == 0 {
            mask |= 1 << bit;
        }
    }
    mask
}

/// The front-face brick of axis `axis` at `h`: the one under `h`'s key, else the one of that
/// axis with the nearest centroid among the 26 neighbouring keys.
fn brick_at(terms: &SurfaceTerms, bricks: &[Brick], h: Vec3, axis: u32) -> Option<u32> {
    let key = terms.key_of(h.to_array());
    if let Some(b) = terms.find(key, axis) {
        return Some(b);
    }
    let mut best: Option<(f32, u32)> = None;
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let Some(b) = terms.find([key[0] + dx, key[1] + dy, key[2] + dz], axis) else {
                    continue;
                };
                let d = Vec3::from(bricks[b as usize].centroid).distance_squared(h);
                if best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, b));
                }
            }
        }
    }
    best.map(|(_, b)| b)
}

/// Direction `k` of `count` cosine-distributed ones about `n` (tangents `t`, `b`): a golden-angle
/// (Fibonacci) spiral, equal-area rings in the unit disc lifted to the hemisphere.
pub fn cosine_spiral(k: u32, count: u32, t: Vec3, b: Vec3, n: Vec3) -> Vec3 {
    const GOLDEN_ANGLE: f32 = 2.399_963;
    let u = (k as f32 + 0.5) / count as f32;
    let phi = k as f32 * GOLDEN_ANGLE;
    let (sin_t, cos_t) = (u.sqrt(), (1.0 - u).sqrt());
    t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + n * cos_t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spiral's mean `Y_k` is the cosine transfer (what `open` is when nothing is near).
    #[test]
    fn the_spiral_is_cosine_distributed() {
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let (t, b) = n.any_orthonormal_pair();
        let mut mean = [0.0f32; SH_COUNT];
        for k in 0..RAYS {
            let y = prt_format::sh::basis(cosine_spiral(k, RAYS, t, b, n).to_array());
            (0..SH_COUNT).for_each(|i| mean[i] += y[i] / RAYS as f32);
        }
        let want = prt_format::surface::cosine_transfer(n.to_array());
        for i in 0..SH_COUNT {
            assert!(
                (mean[i] - want[i]).abs() < 0.01,
                "{i}: {} vs {}",
                mean[i],
                want[i]
            );
        }
    }

    /// The two triangles of the square `[-r, r]^2` at `z` along axis `axis`, facing +axis,
    /// or -axis with `down`.
    fn square(axis: usize, z: f32, r: f32, down: bool) -> [[Vec3; 3]; 2] {
        let v = |x: f32, y: f32| {
            let mut p = [x, y, z];
            p.swap(axis, 2);
            Vec3::from(p)
        };
        let (a, b, c, d) = (v(-r, -r), v(r, -r), v(r, r), v(-r, r));
        // Swapping two axes (x or y with z) mirrors the square, and turns its winding with it.
        match down != (axis != 2) {
            false => [[a, b, c], [a, c, d]],
            true => [[a, c, b], [a, d, c]],
        }
    }

    /// A surfel 2 cm inside a closed 10 cm box (the mean of hits on a bevel) starts its rays
    /// outside the box's face. These start where [`ray_origin`] puts them: a surfel on an
    /// open floor; one on a floor 2 cm under a plate, whichever way the plate is wound (a
    /// pocket: its own surface is behind it); one in the air 2 cm under a 4 cm plate, whose
    /// widest rays pass the plate (not enclosed); and, unmerged, the one in the box.
    #[test]
    fn an_enclosed_surfel_starts_its_rays_past_its_surface() {
        let (spacing, cell) = (1.0, 0.2);
        let up = Vec3::Z;
        // Faces facing out.
        let boxed: Vec<[Vec3; 3]> = (0..3)
            .flat_map(|axis| {
                [
                    square(axis, -0.05, 0.05, true),
                    square(axis, 0.05, 0.05, false),
                ]
            })
            .flatten()
            .collect();
        let origin = |triangles: &[[Vec3; 3]], p: Vec3, cell: f32| {
            let bvh = SceneBvh::build(triangles, 1.0);
            surfel_origin(&bvh, p, up, (spacing, cell))
        };
        let inside = Vec3::new(0.0, 0.0, 0.03);
        let o = origin(&boxed, inside, cell);
        assert!(o.z > 0.05 && o.z < 0.05 + 0.02, "{o}");
        let unmerged = origin(&boxed, inside, 0.0);
        assert_eq!(
            unmerged,
            ray_origin(inside, up, spacing),
            "unmerged: as it is"
        );
        let on = Vec3::new(0.1, 0.2, 0.0);
        let floor = square(2, 0.0, 1.0, false);
        assert_eq!(origin(&floor, on, cell), ray_origin(on, up, spacing));
        for down in [true, false] {
            let gap = [floor, square(2, 0.02, 1.0, down)].concat();
            let o = origin(&gap, on, cell);
            assert_eq!(o, ray_origin(on, up, spacing), "plate facing down: {down}");
        }
        let plate = square(2, 0.02, 0.02, true);
        let air = Vec3::ZERO;
        assert_eq!(origin(&plate, air, cell), ray_origin(air, up, spacing));
    }
}
