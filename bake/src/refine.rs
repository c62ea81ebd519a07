//! # Refinement by prediction: fine probes only where the coarser lattice would be wrong
//!
//! A probe between the points of level 1 of the grid (`prt_format::tier`, every other grid
//! point along each axis) is worth its data only where the trilinear interpolation of those
//! points would light the surfaces around it differently: beside a gallery whose ceiling hides
//! the sunlit court the coarse points see, at a wall's foot, in a niche. In the open field of a
//! flat wall the interpolation is as good as the probe. Unreal's volumetric lightmaps drop the
//! bricks "the coarser level already predicts" with the baked lighting; lights here are dynamic,
//! so the prediction is tested under fixed test lightings instead:
//!
//! - [`FIELDS`] stripes of radiance 0 and 1 (a lit and a dark band per period of [`PERIODS`]
//!   grid spacings) in three directions, laid from the grid's origin: sun patches and shadow
//!   edges at the scales a probe can resolve; every other one of them by index,
//!   under a sky of radiance 1, the others under a black sky;
//! - a point light at the probe's grid point, lighting every surface within a spacing with
//!   radiance 1 and farther ones with the inverse square of the distance (a hotspot the points
//!   around see from aside);
//! - per axis, the surfaces on one side of the probe's grid point lit and those on the other
//!   dark, then the reverse (a lit room behind a wall or door beside the probe; stop 63).
//!
//! A probe's SH under such a lighting is its factor table applied to it, as the runtime's
//! gather does, each factor's radiance the field's value at its mean hit point.
//!
//! The error of the prediction at a probe is the largest difference, over the lightings and the
//! six axis normals, between its irradiance and the level-1 interpolation's, in units of the
//! irradiance of radiance 1 from every direction (pi). The interpolation leaves out the corners
//! a ray from the probe does not reach ([`prt_format::FILL_HIDDEN_SHIFT`]) and renormalises
//! over the valid others, as `prt_runtime::fill` does. [`prune`] drops the probes whose error is
//! below a threshold and whose corners are all in sight (sparse bakes:
//! [`crate::BakeSettings::prune_error`]; a filled point has no visibility map for the lookups
//! without surface terms), then more until a budget of probes with data holds
//! ([`crate::BakeSettings::probe_budget`]): those that see all their corners in order of
//! error, then those with a hidden corner ([`drop_order`]). It keeps every probe that was
//! moved off a surface or out of a wall, and every dilation source (dilated probes read its table,
//! [`prt_format::PROBE_DILATED`]). The dropped ones are flagged filled from level 1
//! ([`prt_format::PROBE_FILLED`]): the runtime fills them
//! after every gather, so the lookup reads the coarse interpolation there, continuous where kept
//! and dropped probes meet (the argument of `prt_format::tier`). Only probes off level 1 are
//! dropped, so every probe a dropped one is filled from keeps its data.
//!
//! What it buys and costs (`docs/results/refine.md`): on the level family's tuning seeds 3-30%
//! fewer probes with data per level at an unchanged surface error; past that, under a budget,
//! a probe filled beside a surface reads the corners it sees, not those the surface sees, and
//! the error grows quickly (with the test's first version, Sponza at 1.2 m cut to 3,400
//! probes: 23.7%, against 21.1% for a 2.4 m grid).

use std::collections::{HashMap, HashSet};
use std::f32::consts::PI;
use std::ops::Range;

use glam::Vec3;
use prt_format::sh::{self, SH_COUNT};
use prt_format::{
    tier, Asset, Probe, DEPTH_WORDS, FILL_HIDDEN_SHIFT, FILL_LEVEL_SHIFT, NO_SLOT, PROBE_FILLED,
    PROBE_OFFSET,
};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;

/// Widths of the test stripes (one lit and one dark band), in grid spacings.
pub const PERIODS: [f32; 4] = [1.0, 2.0, 4.0, 8.0];

/// Stripe lightings: three stripe directions per period (the point and half-space lightings
/// are [`local_response`]'s).
pub const FIELDS: usize = 3 * PERIODS.len();

/// Lightings placed at the tested probe ([`local_response`]): the point light, then per axis
/// the surfaces below the probe lit, and those above.
const LOCAL: usize = 1 + 6;

/// Normals the irradiance is compared at.
const NORMALS: [[f32; 3]; 6] = sh::AXIS_NORMALS;

/// Stripe directions, none along an axis (a wall on a grid layer would sit on a stripe edge
/// at every period), fixed so that bakes are deterministic.
const DIRECTIONS: [[f32; 3]; 3] = [[0.80, 0.36, 0.48], [-0.28, 0.86, 0.43], [0.52, -0.31, 0.80]];

/// What [`prune`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Refined {
    /// The budget of probes with data, if any.
    pub budget: Option<usize>,
    /// Probes with data before and after.
    pub before: usize,
    pub after: usize,
    /// Probes off level 1 that could be dropped (valid, not dilated, no dilation source, their
    /// level-1 corners with data), and how many were.
    pub candidates: usize,
    pub dropped: usize,
    /// The largest prediction error among the dropped probes ([module docs](self)), 0 if none.
    pub worst_dropped: f32,
}

/// Test irradiance of one probe: per lighting, per normal.
type Response = [[f32; NORMALS.len()]; FIELDS];

/// Drops the probes of `asset` whose prediction error ([module docs](self)) is below
/// `threshold`, then, in order of error, more until at most `budget` carry data; `None` when
/// there was nothing to do.
pub fn prune(
    asset: &mut Asset,
    (threshold, budget): (f32, Option<usize>),
    bvh: &SceneBvh,
) -> Option<Refined> {
    let before = asset.probes.iter().filter(|p| p.has_data()).count();
    if before <= budget.unwrap_or(usize::MAX) && threshold <= 0.0 {
        return None;
    }
    let response: Vec<Option<Response>> = (0..asset.probes.len())
        .into_par_iter()
        .map(|p| asset.probes[p].is_valid().then(|| respond(asset, p)))
        .collect();
    // A dilation source keeps its table: dilated probes read it (format 12).
    let sources: HashSet<(u32, u32)> = (asset.probes.iter())
        .filter(|p| p.is_dilated() && p.factor_count > 0)
        .map(|p| (p.first_factor, p.factor_count))
        .collect();
    let scored: Vec<(f32, usize, u32)> = (0..asset.probes.len())
        .into_par_iter()
        .filter(|&p| {
            let probe = &asset.probes[p];
            !sources.contains(&(probe.first_factor, probe.factor_count))
        })
        .filter_map(|p| prediction_error(asset, &response, bvh, p).map(|(e, h)| (e, p, h)))
        .collect();
    let candidates = scored.len();
    let over = budget.map_or(0, |b| before.saturating_sub(b));
    let scored = drop_order(scored, threshold, over);
    let mut drop = vec![None; asset.probes.len()];
    for &(_, p, hidden) in &scored {
        drop[p] = Some(hidden);
    }
    rewrite(asset, &drop);
    Some(Refined {
        budget,
        before,
        after: before - scored.len(),
        candidates,
        dropped: scored.len(),
        worst_dropped: scored.iter().map(|s| s.0).fold(0.0, f32::max),
    })
}

/// The candidates to drop, of `scored` (prediction error, probe, hidden corners): those that
/// see all their corners, best predicted first, then those with a hidden corner, best predicted
/// first; as many as are below `threshold` among the first, or `over` (the probes past the
/// budget) if that is more.
///
/// The threshold drops only probes that see all their corners: a filled point has no
/// visibility map, so where a wall hides a corner the lookups without surface terms (points
/// with no surfel) would weigh it by its facing term alone, and a point filled beside a wall
/// reads the corners it sees, not those the surface sees. A budget drops those last (stop 63:
/// in one order of error, Sponza under its sun at 3,400 probes scored 15.04% with 5.50% of
/// pixels over-lit, seen-first 14.94% and 4.42% (before the half-space lightings); the 110 m
/// plaza at 1.5 m cut to 15,000 probes 0.71% -> 0.62%; `docs/results/refine.md`).
fn drop_order(
    mut scored: Vec<(f32, usize, u32)>,
    threshold: f32,
    over: usize,
) -> Vec<(f32, usize, u32)> {
    scored.sort_by(|a, b| {
        (a.2 != 0)
            .cmp(&(b.2 != 0))
            .then(a.0.total_cmp(&b.0))
            .then(a.1.cmp(&b.1))
    });
    let below = (scored.iter())
        .take_while(|&&(error, _, hidden)| hidden == 0 && error < threshold)
        .count();
    scored.truncate(below.max(over));
    scored
}

/// The warning for a budget the refine stage could not meet: only probes between the points of
/// level 1 can be dropped.
pub fn budget_warning(r: &Refined) -> Option<String> {
    let budget = r.budget.filter(|&b| r.after > b)?;
    Some(format!(
        "probe budget {budget} not met: {} probes with data remain, of which only the {} \
         between every other grid point (and read by no dilated probe) could be dropped (and \
         were); a larger --spacing places fewer",
        r.after, r.candidates
    ))
}

/// The largest difference between probe `p`'s test irradiance and its level-1 interpolation's,
/// in units of pi, and the corners it leaves out ([`prt_format::Probe::fill_hidden`]: those a
/// ray from the probe through `bvh` does not reach); `None` unless `p` may be dropped (valid and
/// not dilated, off level 1, no level-1 corner with a weight filled, one it sees valid).
fn prediction_error(
    asset: &Asset,
    response: &[Option<Response>],
    bvh: &SceneBvh,
    p: usize,
) -> Option<(f32, u32)> {
    let probe = &asset.probes[p];
    let own = response[p].as_ref()?;
    let grid = &asset.header.grid;
    let ijk = grid.ijk(p);
    // A probe moved off a surface or out of a wall stands where its grid point would see
    // through it: kept.
    let moved = probe.flags & PROBE_OFFSET != 0;
    if moved || probe.is_dilated() || !probe.has_data() || tier::on_level_point(grid, ijk, 1) {
        return None;
    }
    if tier::used_corners(grid, ijk, 1).any(|(c, _)| asset.probes[c].is_filled()) {
        return None;
    }
    let hidden = hidden_corners(asset, bvh, p);
    // The point light of the test sits at the probe's grid point: a hotspot the points around
    // it see from aside.
    let [i, j, k] = ijk;
    let at = Vec3::from(grid.position(i, j, k));
    let mut mean = [[0.0f32; NORMALS.len()]; FIELDS];
    let mut local = [[0.0f32; NORMALS.len()]; LOCAL];
    let mut total = 0.0;
    for (c, w) in tier::fill_corners(grid, ijk, 1, hidden) {
        let Some(r) = response[c].as_ref() else {
            continue;
        };
        total += w;
        let r_local = local_response(asset, c, at);
        for (m, r) in (mean.iter_mut().zip(r)).chain(local.iter_mut().zip(&r_local)) {
            for (m, r) in m.iter_mut().zip(r) {
                *m += w * r;
            }
        }
    }
    if total <= 0.0 {
        return None;
    }
    let own_local = local_response(asset, p, at);
    let worst = (own.iter().chain(&own_local).flatten())
        .zip(mean.iter().chain(&local).flatten())
        .map(|(e, m)| (e - m / total).abs())
        .fold(0.0f32, f32::max);
    Some((worst / PI, hidden))
}

/// Probe `q`'s irradiance at the six axis normals under the lightings placed at `at`, its
/// grid point when `q` is the tested probe ([`LOCAL`]):
///
/// - a point light at `at`: every surface within a grid spacing of radiance 1, farther ones
///   falling off with the inverse square of the distance;
/// - per axis, the surfaces below `at` along it of radiance 1 (the others 0), then those above
///   it. Each puts a light's edge through the tested probe, as a door does between a lit room
///   and a dark one: the stripes, laid from the grid's origin, light both rooms alike, so a
///   probe in a doorway, which its level-1 corners in either room see through the door, passed
///   the test and was filled half from the lit room (stop 63: interior_112, a level of the
///   then-blind set 112-119, 33.3% -> 11.7% open mean; `docs/results/refine.md`).
fn local_response(asset: &Asset, q: usize, at: Vec3) -> [[f32; NORMALS.len()]; LOCAL] {
    let spacing_sq = asset.header.grid.spacing * asset.header.grid.spacing;
    let mut sh = [[0.0f32; SH_COUNT]; LOCAL];
    for (x, t) in factors(asset, q) {
        let radiance = (spacing_sq / x.distance_squared(at).max(spacing_sq)).min(1.0);
        for (s, t) in sh[0].iter_mut().zip(&t) {
            *s += radiance * t;
        }
        for a in 0..3 {
            let k = 1 + 2 * a + usize::from(x[a] > at[a]);
            for (s, t) in sh[k].iter_mut().zip(&t) {
                *s += t;
            }
        }
    }
    sh.map(axis_irradiance)
}

/// Probe `q`'s factors: each one's mean hit point and SH transfer, continuation slots
/// (`prt_format::FactorSlot`) left out.
fn factors(asset: &Asset, q: usize) -> impl Iterator<Item = (Vec3, [f32; SH_COUNT])> + '_ {
    let probe = &asset.probes[q];
    let first = probe.first_factor as usize;
    (first..first + probe.factor_count as usize)
        .filter(|&f| asset.factors.brick_and_rays(f).1 != 0)
        .map(move |f| {
            (
                Vec3::from(asset.factor_point(f)),
                asset.factor_transfer(probe, f),
            )
        })
}

/// The irradiance of one channel's SH `c` at the six axis normals.
fn axis_irradiance(c: [f32; SH_COUNT]) -> [f32; NORMALS.len()] {
    let rgb = c.map(|v| [v, 0.0, 0.0]);
    NORMALS.map(|n| sh::irradiance(&rgb, n)[0])
}

/// The corners of probe `p`'s level-1 cell ([`tier::corners`]' order) that a ray from where
/// its rays started does not reach through `bvh`.
fn hidden_corners(asset: &Asset, bvh: &SceneBvh, p: usize) -> u32 {
    let grid = &asset.header.grid;
    let from = Vec3::from(asset.probes[p].position);
    let corners = tier::corners(grid, grid.ijk(p), 1);
    let to: Vec<(usize, Vec3)> = (corners.iter().enumerate())
        .filter(|(_, &(_, w))| w > 0.0)
        .map(|(c, &(q, _))| (c, Vec3::from(asset.probes[q].position) - from))
        .filter(|(_, d)| d.length_squared() > 0.0)
        .collect();
    let dirs: Vec<Vec3> = to.iter().map(|&(_, d)| d).collect();
    // Rays of their corner's length: a hit before `t = 1` stands between.
    let blocked = bvh.occluded(from, &dirs, 1.0);
    (to.iter().enumerate())
        .filter(|&(j, _)| blocked >> j & 1 == 1)
        .fold(0, |mask, (_, &(c, _))| mask | 1 << c)
}

/// Probe `p`'s irradiance at the six axis normals under each test lighting.
fn respond(asset: &Asset, p: usize) -> Response {
    let probe = &asset.probes[p];
    let grid = &asset.header.grid;
    let mut sh = [[0.0f32; SH_COUNT]; FIELDS];
    for (at, t) in factors(asset, p) {
        for (k, sh) in sh.iter_mut().enumerate() {
            if field(k, at, grid) {
                for (s, t) in sh.iter_mut().zip(&t) {
                    *s += t;
                }
            }
        }
    }
    if let Some(sky) = asset.sky_transfer.get(probe.slot as usize) {
        // Half the lightings have a sky of radiance 1.
        for sh in sh.iter_mut().skip(1).step_by(2) {
            for (s, t) in sh.iter_mut().zip(sky) {
                *s += t;
            }
        }
    }
    sh.map(axis_irradiance)
}

/// Whether test lighting `k` lights the point `at` of `grid`: stripes of the period
/// `PERIODS[k / 3]` along direction `k % 3`. The stripes are laid from the
/// grid's origin, so that a level moved far from the world's origin is pruned as it is there.
fn field(k: usize, at: Vec3, grid: &prt_format::Grid) -> bool {
    let period = PERIODS[k / DIRECTIONS.len()] * grid.spacing;
    let d = Vec3::from(DIRECTIONS[k % DIRECTIONS.len()]);
    (d.dot(at - Vec3::from(grid.origin)) / period).rem_euclid(1.0) < 0.5
}

/// Rewrites `asset` without the data of the probes marked in `drop`, which become filled from
/// level 1 at their grid positions; slots and factor ranges of the others follow in grid order.
fn rewrite(asset: &mut Asset, drop: &[Option<u32>]) {
    let grid = asset.header.grid;
    let mut ranges: Vec<Range<usize>> = Vec::new();
    // The kept probes' old slots, in their new order.
    let (mut kept, mut sky_transfer, mut depth) = (Vec::new(), Vec::new(), Vec::new());
    let (mut first_factor, mut slot) = (0u32, 0u32);
    // Where each kept table of a probe that is not dilated starts, by where it started.
    let mut moved_to: HashMap<u32, u32> = HashMap::new();
    for (p, probe) in asset.probes.iter_mut().enumerate() {
        if let Some(hidden) = drop[p] {
            let [i, j, k] = grid.ijk(p);
            *probe = Probe {
                position: grid.position(i, j, k),
                flags: PROBE_FILLED | 1 << FILL_LEVEL_SHIFT | hidden << FILL_HIDDEN_SHIFT,
                slot: NO_SLOT,
                first_factor,
                ..Probe::default()
            };
            continue;
        }
        if !probe.is_dilated() {
            let start = probe.first_factor as usize;
            ranges.push(start..start + probe.factor_count as usize);
            moved_to.insert(probe.first_factor, first_factor);
            probe.first_factor = first_factor;
            first_factor += probe.factor_count;
        }
        if probe.has_data() {
            let s = probe.slot as usize;
            kept.push(s);
            sky_transfer.push(asset.sky_transfer[s]);
            depth.extend_from_slice(&asset.probe_depth[s * DEPTH_WORDS..(s + 1) * DEPTH_WORDS]);
            probe.slot = slot;
            slot += 1;
        }
    }
    // A dilated probe reads its source's table where it now is (sources are never dropped).
    for probe in asset.probes.iter_mut().filter(|p| p.is_dilated()) {
        probe.first_factor = match probe.factor_count {
            0 => first_factor,
            _ => *(moved_to.get(&probe.first_factor)).expect("a dilation source is kept"),
        };
    }
    asset.factors = asset.factors.select(&ranges);
    let sky_mask = prt_format::sky_mask::with_index(kept.iter().map(|&s| asset.sky_record(s)));
    (asset.sky_mask, asset.sky_transfer, asset.probe_depth) = (sky_mask, sky_transfer, depth);
}

#[cfg(test)]
mod tests {
    use super::drop_order;

    fn probes(order: Vec<(f32, usize, u32)>) -> Vec<usize> {
        order.iter().map(|s| s.1).collect()
    }

    /// The threshold drops the probes that see all their corners below it; a budget then drops
    /// the rest of those, best predicted first, before any probe with a hidden corner, however
    /// well predicted.
    #[test]
    fn a_budget_drops_probes_that_see_their_corners_first() {
        // (prediction error, probe, hidden corners)
        let scored = vec![
            (0.05, 1, 0),
            (0.02, 2, 0b1),
            (0.3, 3, 0),
            (0.1, 4, 0),
            (0.5, 5, 0b10),
        ];
        let order = |threshold, over| probes(drop_order(scored.clone(), threshold, over));
        assert_eq!(order(0.15, 0), [1, 4]);
        assert_eq!(order(0.15, 1), [1, 4]);
        assert_eq!(order(0.15, 3), [1, 4, 3]);
        assert_eq!(order(0.15, 4), [1, 4, 3, 2]);
        assert_eq!(order(0.0, 9), [1, 4, 3, 2, 5]);
        assert_eq!(order(1.0, 0), [1, 4, 3]);
    }
}
