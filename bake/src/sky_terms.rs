//! # Sky terms: the sky a surfel sees, against the sky its probes bring it (issue 31)
//!
//! Probes a spacing off a surface see more or less of the sky than the surface does: a wall
//! under an overhang, the ceiling of a gallery beside an open court, the floor of a cave under
//! its skylight. The near field (`crate::surface_terms`) reaches one spacing and does not see
//! what hides the sky farther out, so the lookup lit those points with the probes' view of the
//! sky. Swapping it for the point's own view, traced with 4,096 rays per point, met issue 31's
//! family targets on every committed set and took Sponza under the sun from 15.8% to 12.5%
//! (`prt-bench surface --lookup sky_point`, `docs/results/surface_sky_point.md`, stop 54).
//! This stage bakes that swap: after the probes are final (placement, refinement and fills
//! decided), per front-face surfel ([`prt_format::surface::sky_term`]),
//!
//! `sky = v - clamp(open . T, 0, A(n) . T)`, pooled over the surfel's near group and shrunk:
//!
//! - `T`: the probes' sky transfer (`Asset::sky_transfer`: what a sky of radiance 1 adds to a
//!   probe's SH), interpolated at the surfel with the lookup's weights (trilinear at the
//!   surfel moved [`NORMAL_BIAS`] spacings along its normal, a probe the surfel does not see
//!   weighted `BLOCKED_WEIGHT`, a filled grid point its coarse level's as the runtime fills
//!   it); `clamp(open . T, 0, A(n) . T)` is what the lookup's escaping near-field rays bring of
//!   that sky (the same clamp);
//! - `v`: the share of the surfel's cosine-weighted hemisphere that leaves the scene, from
//!   [`SKY_RAYS`] rays (the near field's spiral, turned per surfel) with the probes' sky as a
//!   control variate: `A(n) . T + mean over the rays of (V(w) - T . Y(w))`, `V` 1 for a ray
//!   that escapes. `T . Y` is the probes' visibility of the sky in SH; its cosine integral is
//!   `A(n) . T` exactly, so the estimate stays unbiased, and where the surfel sees the sky as
//!   its probes do only the difference is noisy;
//! - **pooled**: `v` less a baseline known exactly at each surfel (the probes' sky
//!   `clamp(...)`, the control variate's `A(n) . T`, or none: the one that leaves the group most
//!   uniform, [`pooled`]), averaged over the near group (the surfels of its brick that see the
//!   same probes), weighted by the surfels' hits, each surfel adding its own baseline back;
//! - **shrunk** toward 0 by [`SHRINK`] standard deviations of its noise (soft threshold), a
//!   darkening one by [`SHRINK_DARKER`]: a correction smaller than its noise is dropped. The
//!   variance is the rays' sample variance, and at least the binomial one of the larger of the
//!   two shares (and of one ray): a sky seen through a crack is missed by every ray as often
//!   as not, and the sample variance of no hits is zero.
//!
//! The lookup adds `pi * sky * L_sky` to the irradiance, `L_sky` the sky's mean radiance
//! (`prt_runtime::surface`): for a constant sky the surfel's own sky replaces its probes'; for
//! an image sky, band 0 of it (the directional rest stays the probes').
//!
//! What chose it (`prt-bench surface --case tuning`, the family's tuning seeds, open-point mean
//! of the median / worst level, default spacing and half; without sky terms 6.36 / 8.60% and
//! 3.63 / 4.81%, docs/results/surface_sky.md):
//!
//! - a darkening term (`d < 0`) shrunk by half a standard deviation, a brightening one by one
//!   (stop 59, the default: [`SHRINK_DARKER`]): 5.55 / 7.74% and 3.10 / 5.46%, every tuning
//!   level better but cave_7 (7.08% -> 7.74%, half 4.66% -> 5.46%: a cave floor under a small
//!   skylight read too dark); on the sets not tuned on 5.13 / 7.29%, 4.84 / 6.57%, 5.80 /
//!   12.82%, worst over-lit pixels 0.72% -> 0.47% (held-out) and 1.42% -> 0.99% (unseen);
//!   Sponza under the sun 4 -> 2 of 284 leaking (docs/results/sky_shrink_darker/). Both signs
//!   at half a deviation (stop 57): 5.54 / 7.50% and 3.12 / 5.75%, Sponza 4 leaking (two other
//!   points brightened over the line); 0.75 for a darkening term: Sponza 3 leaking;
//! - 256 rays, the baseline chosen per group, shrink 1, variance floor (stop 56):
//!   5.59 / 7.55% and 3.19 / 4.67%. On the other sets (held-out, unseen, fresh: median / worst
//!   level) 5.22 / 7.42%, 4.88 / 6.63%, 5.78 / 12.91%; unseen cave_31's over-lit pixels 2.65%
//!   -> 1.42% and Sponza under the sun 15.17% -> 14.74% against 64 rays with the same pooling
//!   (docs/results/surface_sky_256.md, surface_sky_256_bundled.md, surface_sky_pool*.md). Worse
//!   than that: cave_31's points 5.51% -> 5.78% (half 3.67% -> 3.93%), cave_7 at half spacing
//!   4.58% -> 4.67%, fresh street_38's over-lit pixels 1.19% -> 1.35%. It costs the stage four
//!   times its rays: Sponza's default bake about twice its time;
//! - 64 rays, the same: 5.79 / 8.03% and 3.41 / 4.82% (and atrium_13, held out, 4 leaking
//!   points of 297 -> 1 against always the probes' baseline); 128 rays 5.66 / 7.58% and 3.26 /
//!   5.22% (cave_7 at half spacing 4.58% -> 5.22%, cave_31's pixels 2.55%); 512 rays 5.53 /
//!   7.31% and 3.12 / 4.26%, Sponza under the sun 14.09%, at twice the 256 rays' cost
//!   (surface_sky_128.md, surface_sky_512.md: the tuning seeds, cave_31 and Sponza);
//! - 64 rays, the difference to the probes always pooled (stop 55): 5.77 / 8.09% and 3.43 /
//!   4.85% (docs/results/surface_sky.md, surface_sky_bundled.md); shrinking each surfel only
//!   part of the way to its group's mean by the group's spread over the noise (empirical
//!   Bayes) changed nothing at 256 rays: the floored noise covers the spread;
//! - 128 rays, `v` pooled instead of the difference, without the variance floor: a dark cave
//!   (cave_7) went from 4.48% to 7.29% at half the spacing; with the floor 5.53%; 128 rays
//!   with the difference pooled and shrink 2: 5.95% / 8.29% and 3.49% / 4.62%;
//! - without the control variate (plain share of escaping rays): cave_3 8.07% against 7.87%;
//!   with the probes' sky masks as control variate (nearest lattice direction): no better, at
//!   twice the stage's time;
//! - 1,024 rays per surfel, unpooled: cave_3 6.60% (the 4,096-ray reference 6.17%), at 6.6x
//!   that level's bake time.
//!
//! Deterministic: each surfel's term depends only on the asset and fixed ray sets, and groups
//! are summed in surfel order.

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_format::surface::{cosine_transfer, BLOCKED_WEIGHT};
use prt_format::{f32_to_f16, tier, Asset};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::surface_terms::{cosine_spiral, surfel_origin};

/// Sky rays per surfel.
pub const SKY_RAYS: u32 = 256;

/// Standard deviations of its noise a sky term that brightens its surfel is shrunk by toward 0.
pub const SHRINK: f32 = 1.0;

/// Standard deviations of its noise a sky term that darkens its surfel (it sees less sky than
/// its probes bring it) is shrunk by toward 0: less than a brightening one, because the errors
/// are not alike. A darkening term shrunk too far leaves the probes' sky on the point, the
/// over-lighting issue 31 counts as a leak (a ceiling under a gallery beside a sunlit court);
/// one shrunk too little darkens a point that sees a little sky under its noise (a cave's floor
/// under a small skylight). Module docs: what chose it.
pub const SHRINK_DARKER: f32 = 0.5;

/// The runtime lookup's default normal bias in spacings (`prt_runtime::LookupSettings`;
/// `tests/tests/surface_terms.rs` checks that they agree): where the sky transfer is
/// interpolated.
pub const NORMAL_BIAS: f32 = 0.2;

/// The asset's sky terms, two halves a word (empty when it has no surface terms).
pub fn sky_terms(asset: &Asset, bvh: &SceneBvh) -> Vec<u32> {
    let st = &asset.surface;
    if st.is_empty() || st.surfels.len() != asset.surfels.len() {
        return Vec::new();
    }
    let transfer = grid_transfer(asset);
    let order = spiral_order(SKY_RAYS);
    // Per brick, its key's centre probe, which its surfels' centres are stored from.
    let grid = &asset.header.grid;
    let centres: Vec<[i32; 3]> = (asset.bricks.iter())
        .map(|b| st.brick_centre(grid, b))
        .collect();
    // Per surfel, its view of the sky, the baselines it may be pooled against, and the view's
    // variance.
    let traced: Vec<Traced> = (0..st.surfels.len())
        .into_par_iter()
        .map(|s| {
            if !st.surfels[s].is_traced() {
                return Traced::default();
            }
            let key_centre = centres[asset.surfels[s].brick as usize];
            let t = interpolated_transfer(asset, &transfer, s, key_centre);
            let (v, variance, cosine) = sky_view(asset, bvh, &order, &t, s);
            let probes = probes_sky(asset, &t, s);
            let n = SKY_RAYS as f32;
            let q = v.max(probes).clamp(1.0 / n, 1.0);
            Traced {
                view: v,
                baselines: [probes, cosine, 0.0],
                variance: variance.max(q * (1.0 - q) / n),
                weight: asset.surfels[s].weight,
            }
        })
        .collect();
    let pooled = pooled(&st.group_surfels, &traced);
    let terms: Vec<f32> = (pooled.iter().zip(&st.surfels))
        .map(|(&(d, variance), t)| {
            if t.is_traced() {
                shrunk(d, variance)
            } else {
                0.0
            }
        })
        .collect();
    terms
        .chunks(2)
        .map(|p| {
            let h = |v: Option<&f32>| u32::from(f32_to_f16(v.copied().unwrap_or(0.0)));
            h(p.first()) | h(p.get(1)) << 16
        })
        .collect()
}

/// Pooled term `d` of noise `variance` shrunk toward 0 (soft threshold) by [`SHRINK`] standard
/// deviations, by [`SHRINK_DARKER`] where it darkens its surfel.
fn shrunk(d: f32, variance: f32) -> f32 {
    let k = if d < 0.0 { SHRINK_DARKER } else { SHRINK };
    d.signum() * (d.abs() - k * variance.sqrt()).max(0.0)
}

/// The probes' sky transfer interpolated at surfel `s` with the lookup's weights: trilinear at
/// the surfel moved [`NORMAL_BIAS`] spacings along its normal, times each probe's sample
/// weight, a probe the surfel does not see times `BLOCKED_WEIGHT`; plain trilinear when it
/// sees none of them (the lookup's fallback, less its depth moments). Zero where no probe has
/// weight.
fn interpolated_transfer(
    asset: &Asset,
    transfer: &[[f32; SH_COUNT]],
    s: usize,
    key_centre: [i32; 3],
) -> [f32; SH_COUNT] {
    let terms = &asset.surface.surfels[s];
    let grid = &asset.header.grid;
    let n = terms.normal();
    let at = Vec3::from(asset.surfels[s].position) + Vec3::from(n) * NORMAL_BIAS * grid.spacing;
    let mut seen = false;
    // Per corner: grid point, plain weight, masked weight.
    let mut corners: Vec<(usize, f32, f32)> = Vec::with_capacity(8);
    for (i, tri) in grid.corners(at.to_array()) {
        let w = tri * asset.probes[i].sample_weight();
        if w <= 0.0 {
            continue;
        }
        let visible = terms.sees(key_centre, grid, i);
        seen |= visible;
        corners.push((i, w, if visible { w } else { w * BLOCKED_WEIGHT }));
    }
    let (mut t, mut total) = ([0.0f32; SH_COUNT], 0.0f32);
    for (i, plain, masked) in corners {
        let w = if seen { masked } else { plain };
        (0..SH_COUNT).for_each(|k| t[k] += w * transfer[i][k]);
        total += w;
    }
    if total > 0.0 {
        t.map(|v| v / total)
    } else {
        t
    }
}

/// `v` of surfel `s` (module docs: the share of its cosine-weighted hemisphere that sees the
/// sky, with the probes' sky `t` as control variate), clamped to [0, 1], the variance of its
/// mean over the rays, and the control variate's integral `A(n) . t`. The rays are traced in
/// packets of neighbouring directions (`order`, [`spiral_order`]) and summed in spiral order,
/// so the packets change the time, not the bits.
fn sky_view(
    asset: &Asset,
    bvh: &SceneBvh,
    order: &[u32],
    t: &[f32; SH_COUNT],
    s: usize,
) -> (f32, f32, f32) {
    let surfel = &asset.surfels[s];
    let (p, n) = (
        Vec3::from(surfel.position),
        Vec3::from(surfel.normal).normalize_or_zero(),
    );
    let cells = (asset.header.grid.spacing, asset.header.settings.cell_size);
    let o = surfel_origin(bvh, p, n, cells);
    let (tx, ty) = n.any_orthonormal_pair();
    // Turned about the normal by a golden-ratio step per surfel: the surfels of a group pool
    // different directions, not the same spiral.
    // In f64: an f32 product keeps few fractional bits at large surfel indices.
    let turn = (s as f64 * 0.618_033_988_749_895).fract() as f32 * std::f32::consts::TAU;
    let (sin, cos) = turn.sin_cos();
    let (tx, ty) = (tx * cos + ty * sin, ty * cos - tx * sin);
    let dirs: [Vec3; SKY_RAYS as usize] =
        std::array::from_fn(|k| cosine_spiral(k as u32, SKY_RAYS, tx, ty, n));
    debug_assert_eq!(order.len(), SKY_RAYS as usize, "a permutation of the rays");
    let mut escaped = [false; SKY_RAYS as usize];
    for packet in order.chunks(PACKET) {
        let mut ray = [Vec3::ZERO; PACKET];
        for (r, &k) in ray.iter_mut().zip(packet) {
            *r = dirs[k as usize];
        }
        let blocked = bvh.occluded(o, &ray[..packet.len()], f32::INFINITY);
        for (j, &k) in packet.iter().enumerate() {
            escaped[k as usize] = blocked >> j & 1 == 0;
        }
    }
    let (mut sum, mut square) = (0.0f32, 0.0f32);
    for (d, &open) in dirs.iter().zip(&escaped) {
        let y = prt_format::sh::basis(d.to_array());
        let probes: f32 = (0..SH_COUNT).map(|k| y[k] * t[k]).sum();
        let x = f32::from(u8::from(open)) - probes;
        sum += x;
        square += x * x;
    }
    let rays = SKY_RAYS as f32;
    let mean = sum / rays;
    let all = cosine_transfer(n.to_array());
    let integral: f32 = (0..SH_COUNT).map(|k| all[k] * t[k]).sum();
    let variance = (square / rays - mean * mean).max(0.0) / rays;
    ((integral + mean).clamp(0.0, 1.0), variance, integral)
}

/// The indices `0..count` of `cosine_spiral`'s directions in an order where consecutive ones
/// are neighbours: Morton order of their projection on the disc about the normal (the spiral's
/// own lattice, in a fixed frame: turning the spiral about its normal keeps neighbours
/// neighbours). The spiral's own order steps by the golden angle, so that a packet of
/// consecutive directions would span the hemisphere and visit most of the BVH.
pub(crate) fn spiral_order(count: u32) -> Vec<u32> {
    crate::trace::morton_order(count, |k| {
        let d = cosine_spiral(k, count, Vec3::X, Vec3::Y, Vec3::Z);
        [d.x, d.y]
    })
}

/// `clamp(open . t, 0, A(n) . t)` of surfel `s`: what its near field's escaping rays bring of
/// the probes' sky `t` (in units of pi).
fn probes_sky(asset: &Asset, t: &[f32; SH_COUNT], s: usize) -> f32 {
    let terms = &asset.surface.surfels[s];
    let (open, all) = terms.open_and_cosine(asset.surface.header.rays);
    let dot = |a: &[f32; SH_COUNT]| (0..SH_COUNT).map(|k| a[k] * t[k]).sum::<f32>();
    dot(&open).max(0.0).min(dot(&all).max(0.0))
}

/// What [`sky_terms`] traced at a surfel: its view of the sky `v`, the baselines its group
/// may be pooled against ([`pooled`]: the probes' sky through its near field, the control
/// variate's integral `A(n) . T`, and none), the variance of `v` (floored), and its weight in
/// the group (its hits; 0 for a surfel not traced).
#[derive(Clone, Copy, Debug, Default)]
struct Traced {
    view: f32,
    baselines: [f32; 3],
    variance: f32,
    weight: f32,
}

/// Per surfel, its term before shrinking (`v - probes`, `v` pooled over the traced surfels of
/// its near group, weighted by their hits) and the variance of the pooled mean.
///
/// What is pooled is `v` less a baseline known exactly at each surfel, the one that leaves the
/// group most uniform: `v - baseline` is averaged and each surfel adds its own baseline back.
/// The rays' noise is the same whichever baseline is taken off, so the one whose differences
/// spread least across the group is the one the sky varies least against. Where the probes'
/// sky falls off across a gallery wall that sees none (atrium_13: 0.2% to 2.5% within one
/// group of 16), `v` itself is uniform and the difference to the probes is not: pooling the
/// difference gave each surfel the group's mean correction, about half its own, and left 3 of
/// its 4 leaking points (1 at 64 rays with the baseline chosen, 8.31% -> 7.99%,
/// docs/results/surface_sky_pool.md). Where a skylight's edge crosses the group the probes
/// follow it and the difference is the uniform one (cave_7, module docs). The choice is made
/// on the same noisy `v` it pools, clamped to [0, 1]: in a group that sees no sky, or all of
/// it, the clamp makes `v` look uniform and "none" tends to win, which is the right baseline
/// there.
fn pooled(groups: &[[u32; 2]], traced: &[Traced]) -> Vec<(f32, f32)> {
    let mut out: Vec<(f32, f32)> = traced
        .iter()
        .map(|t| (t.view - t.baselines[0], t.variance))
        .collect();
    for &[first, count] in groups {
        let range = first as usize..(first + count) as usize;
        let members: Vec<(usize, f64)> = (range.clone())
            .map(|s| (s, f64::from(traced[s].weight)))
            .filter(|m| m.1 > 0.0)
            .collect();
        let weight: f64 = members.iter().map(|m| m.1).sum();
        if weight <= 0.0 {
            continue;
        }
        let x = |s: usize, b: usize| f64::from(traced[s].view - traced[s].baselines[b]);
        let means =
            [0, 1, 2].map(|b| members.iter().map(|&(s, w)| w * x(s, b)).sum::<f64>() / weight);
        let spreads = [0, 1, 2].map(|b| {
            (members.iter())
                .map(|&(s, w)| w * (x(s, b) - means[b]).powi(2))
                .sum::<f64>()
        });
        // The first of the least spread: the probes' baseline where they tie.
        let best = (1..3).fold(
            0,
            |best, b| if spreads[b] < spreads[best] { b } else { best },
        );
        let m = means[best];
        let variance = members
            .iter()
            .map(|&(s, w)| w * w * f64::from(traced[s].variance))
            .sum::<f64>()
            / (weight * weight);
        for s in range {
            let t = &traced[s];
            let own = f64::from(t.baselines[best]) + m - f64::from(t.baselines[0]);
            out[s] = (own as f32, variance as f32);
        }
    }
    out
}

/// Per grid point, the sky transfer the runtime's relight gives it under a sky of radiance 1:
/// its own for a valid probe with data, its coarse level's interpolation for a filled point
/// (as `prt_runtime::fill`), none otherwise.
fn grid_transfer(asset: &Asset) -> Vec<[f32; SH_COUNT]> {
    let grid = &asset.header.grid;
    let own = |p: &prt_format::Probe| {
        (p.has_data() && p.is_valid())
            .then(|| asset.sky_transfer.get(p.slot as usize).copied())
            .flatten()
            .unwrap_or([0.0; SH_COUNT])
    };
    let mut t: Vec<[f32; SH_COUNT]> = asset.probes.iter().map(own).collect();
    for (index, probe) in asset.probes.iter().enumerate() {
        if !probe.is_filled() {
            continue;
        }
        let (mut acc, mut total) = ([0.0f32; SH_COUNT], 0.0f32);
        for (c, w) in tier::filled_from(grid, &asset.probes, index) {
            total += w;
            let tc = own(&asset.probes[c]);
            (0..SH_COUNT).for_each(|k| acc[k] += w * tc[k]);
        }
        if total > 0.0 {
            t[index] = acc.map(|v| v / total);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `spiral_order` is a permutation whose packets are narrow cones: on average a ray is less
    /// than half as far from its packet's mean direction as in the spiral's own order, whose 32
    /// consecutive directions span the hemisphere.
    #[test]
    fn the_spiral_order_packs_neighbouring_directions() {
        let spread = |dirs: &[Vec3]| {
            let mean = dirs.iter().copied().sum::<Vec3>().normalize();
            dirs.iter().map(|d| d.angle_between(mean)).sum::<f32>()
        };
        let order = spiral_order(SKY_RAYS);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..SKY_RAYS).collect::<Vec<_>>());
        let dir = |k: u32| cosine_spiral(k, SKY_RAYS, Vec3::X, Vec3::Y, Vec3::Z);
        let spiral: Vec<Vec3> = (0..SKY_RAYS).map(dir).collect();
        let packed: Vec<Vec3> = order.iter().map(|&k| dir(k)).collect();
        let mean = |d: &[Vec3]| d.chunks(PACKET).map(spread).sum::<f32>() / d.len() as f32;
        assert!(
            mean(&packed) < 0.5 * mean(&spiral),
            "a ray {} rad from its packet's mean against {}",
            mean(&packed),
            mean(&spiral)
        );
    }

    /// A term that darkens its surfel loses half a standard deviation, one that brightens a
    /// whole one, and either is dropped under that.
    #[test]
    fn a_darkening_term_is_shrunk_less() {
        let variance = 0.01f32 * 0.01;
        let cases = [
            (-0.03, -0.025),
            (0.03, 0.02),
            (-0.004, 0.0),
            (0.008, 0.0),
            (0.0, 0.0),
        ];
        for (d, want) in cases {
            assert!(
                (shrunk(d, variance) - want).abs() < 1e-7,
                "{d}: {}",
                shrunk(d, variance)
            );
        }
    }

    /// A traced surfel of weight 1 that sees `view` of the sky, its probes `probes`, its
    /// control variate's integral `cosine`, and no noise.
    fn surfel(view: f32, probes: f32, cosine: f32) -> Traced {
        Traced {
            view,
            baselines: [probes, cosine, 0.0],
            variance: 0.0,
            weight: 1.0,
        }
    }

    #[test]
    fn a_group_that_sees_no_sky_takes_off_each_surfels_own_probes() {
        // A gallery wall under probes whose sky falls off across it: the difference to the
        // probes varies, the view does not. Each surfel's term is minus its own probes' sky,
        // not the group's mean difference.
        let traced: Vec<Traced> = [0.025, 0.017, 0.009, 0.002]
            .iter()
            .map(|&p| surfel(0.0, p, p))
            .collect();
        let terms = pooled(&[[0, 4]], &traced);
        for (t, s) in terms.iter().zip(&traced) {
            assert!((t.0 + s.baselines[0]).abs() < 1e-7, "{t:?} for {s:?}");
        }
    }

    #[test]
    fn a_view_that_follows_the_probes_pools_the_difference() {
        // A skylight's edge across the group: the view falls off as the probes' sky does,
        // 0.1 under it. Every surfel gets the group's difference, and the untraced one
        // (weight 0) takes no part.
        let mut traced: Vec<Traced> = [0.5, 0.3, 0.2, 0.1]
            .iter()
            .map(|&p| surfel(p - 0.1, p, 0.4))
            .collect();
        traced.push(Traced {
            view: 1.0,
            ..Traced::default()
        });
        let terms = pooled(&[[0, 5]], &traced);
        for t in &terms[..4] {
            assert!((t.0 + 0.1).abs() < 1e-6, "{t:?}");
        }
    }

    #[test]
    fn a_view_that_follows_the_cosine_integral_pools_against_it() {
        // The view tracks the control variate's integral while the probes' sky (through the
        // near field) does not: each surfel keeps its own integral less a common 0.05.
        let traced: Vec<Traced> = [(0.4, 0.1), (0.3, 0.3), (0.2, 0.0), (0.1, 0.2)]
            .iter()
            .map(|&(cosine, probes)| surfel(cosine - 0.05, probes, cosine))
            .collect();
        let terms = pooled(&[[0, 4]], &traced);
        for (t, s) in terms.iter().zip(&traced) {
            let want = s.view - s.baselines[0];
            assert!((t.0 - want).abs() < 1e-6, "{t:?} for {s:?}");
        }
    }

    #[test]
    fn an_untraced_surfel_takes_no_part_and_a_group_of_none_stays_zero() {
        let mut traced = vec![surfel(0.0, 0.1, 0.1), surfel(0.2, 0.1, 0.1)];
        // Untraced (weight 0) with a view that would pull the mean.
        traced.push(Traced {
            view: 1.0,
            ..Traced::default()
        });
        let terms = pooled(&[[0, 3]], &traced);
        assert!((terms[0].0 - 0.0).abs() < 1e-6, "{:?}", terms[0]);
        let none = pooled(&[[0, 2]], &[Traced::default(); 2]);
        assert_eq!(none, vec![(0.0, 0.0); 2]);
    }

    #[test]
    fn the_pooled_variance_is_that_of_the_weighted_mean() {
        let mut traced = vec![surfel(0.0, 0.1, 0.1), surfel(0.0, 0.1, 0.1)];
        traced[0].variance = 4e-4;
        traced[1].variance = 4e-4;
        traced[1].weight = 3.0;
        let terms = pooled(&[[0, 2]], &traced);
        // (1 * 4e-4 + 9 * 4e-4) / 16
        assert!((terms[0].1 - 2.5e-4).abs() < 1e-9, "{:?}", terms[0]);
        assert_eq!(terms[0].1, terms[1].1);
    }
}
