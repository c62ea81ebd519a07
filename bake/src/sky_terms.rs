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
//! - **pooled**: the difference `v - clamp(...)`, not `v`, averaged over the near group (the
//!   surfels of its brick that see the same probes), weighted by the surfels' hits: the
//!   difference varies less across a group than the sky does;
//! - **shrunk** toward 0 by [`SHRINK`] standard deviations of its noise (soft threshold): a
//!   correction smaller than its noise is dropped. The variance is the rays' sample variance,
//!   and at least the binomial one of the larger of the two shares (and of one ray): a sky
//!   seen through a crack is missed by every ray as often as not, and the sample variance of
//!   no hits is zero.
//!
//! The lookup adds `pi * sky * L_sky` to the irradiance, `L_sky` the sky's mean radiance
//! (`prt_runtime::surface`): for a constant sky the surfel's own sky replaces its probes'; for
//! an image sky, band 0 of it (the directional rest stays the probes').
//!
//! What chose it (`prt-bench surface --case tuning`, the family's tuning seeds, open-point mean
//! of the median / worst level, default spacing and half; without sky terms 6.36 / 8.60% and
//! 3.63 / 4.81%, docs/results/surface_sky.md):
//!
//! - 64 rays, pooled difference, shrink 1, variance floor: 5.77 / 8.09% and 3.43 / 4.85%,
//!   every level better or within 0.04 point (the committed sets and Sponza:
//!   docs/results/surface_sky.md, surface_sky_bundled.md);
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
use prt_format::surface::{
    cosine_transfer, decode_normal, SurfaceTerms, BLOCKED_WEIGHT, TERMS_TRACED,
};
use prt_format::{f16_to_f32, f32_to_f16, tier, Asset};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::surface_terms::{cosine_spiral, ray_origin};

/// Sky rays per surfel.
pub const SKY_RAYS: u32 = 64;

/// Standard deviations of its noise a sky term is shrunk by toward 0.
pub const SHRINK: f32 = 1.0;

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
    // Per surfel, the unpooled term and its variance.
    let traced: Vec<(f32, f32)> = (0..st.surfels.len())
        .into_par_iter()
        .map(|s| {
            if st.surfels[s].mask & TERMS_TRACED == 0 {
                return (0.0, 0.0);
            }
            let t = interpolated_transfer(asset, &transfer, s);
            let (v, variance) = sky_view(asset, bvh, &t, s);
            let probes = probes_sky(asset, &t, s);
            let n = SKY_RAYS as f32;
            let q = v.max(probes).clamp(1.0 / n, 1.0);
            (v - probes, variance.max(q * (1.0 - q) / n))
        })
        .collect();
    let pooled = pooled(st, asset, &traced);
    let terms: Vec<f32> = (pooled.iter().zip(&st.surfels))
        .map(|(&(d, variance), t)| match t.mask & TERMS_TRACED {
            0 => 0.0,
            _ => d.signum() * (d.abs() - SHRINK * variance.sqrt()).max(0.0),
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

/// The probes' sky transfer interpolated at surfel `s` with the lookup's weights: trilinear at
/// the surfel moved [`NORMAL_BIAS`] spacings along its normal, times each probe's sample
/// weight, a probe the surfel does not see times `BLOCKED_WEIGHT`; plain trilinear when it
/// sees none of them (the lookup's fallback, less its depth moments). Zero where no probe has
/// weight.
fn interpolated_transfer(asset: &Asset, transfer: &[[f32; SH_COUNT]], s: usize) -> [f32; SH_COUNT] {
    let terms = &asset.surface.surfels[s];
    let grid = &asset.header.grid;
    let n = decode_normal(terms.normal);
    let at = Vec3::from(asset.surfels[s].position) + Vec3::from(n) * NORMAL_BIAS * grid.spacing;
    let mut seen = false;
    // Per corner: grid point, plain weight, masked weight.
    let mut corners: Vec<(usize, f32, f32)> = Vec::with_capacity(8);
    for (i, tri) in grid.corners(at.to_array()) {
        let w = tri * asset.probes[i].sample_weight();
        if w <= 0.0 {
            continue;
        }
        let visible = terms.sees(grid, i);
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
/// sky, with the probes' sky `t` as control variate), clamped to [0, 1], and the variance of
/// its mean over the rays.
fn sky_view(asset: &Asset, bvh: &SceneBvh, t: &[f32; SH_COUNT], s: usize) -> (f32, f32) {
    let surfel = &asset.surfels[s];
    let (p, n) = (
        Vec3::from(surfel.position),
        Vec3::from(surfel.normal).normalize_or_zero(),
    );
    let o = ray_origin(p, n, asset.header.grid.spacing);
    let (tx, ty) = n.any_orthonormal_pair();
    // Turned about the normal by a golden-ratio step per surfel: the surfels of a group pool
    // different directions, not the same spiral.
    // In f64: an f32 product keeps few fractional bits at large surfel indices.
    let turn = (s as f64 * 0.618_033_988_749_895).fract() as f32 * std::f32::consts::TAU;
    let (sin, cos) = turn.sin_cos();
    let (tx, ty) = (tx * cos + ty * sin, ty * cos - tx * sin);
    let dirs: Vec<Vec3> = (0..SKY_RAYS)
        .map(|k| cosine_spiral(k, SKY_RAYS, tx, ty, n))
        .collect();
    let (mut sum, mut square) = (0.0f32, 0.0f32);
    for packet in dirs.chunks(PACKET) {
        let hits = bvh.closest_hits(o, packet, f32::INFINITY);
        for (d, hit) in packet.iter().zip(&hits) {
            let y = prt_format::sh::basis(d.to_array());
            let probes: f32 = (0..SH_COUNT).map(|k| y[k] * t[k]).sum();
            let x = f32::from(u8::from(hit.is_none())) - probes;
            sum += x;
            square += x * x;
        }
    }
    let rays = SKY_RAYS as f32;
    let mean = sum / rays;
    let all = cosine_transfer(n.to_array());
    let integral: f32 = (0..SH_COUNT).map(|k| all[k] * t[k]).sum();
    let variance = (square / rays - mean * mean).max(0.0) / rays;
    ((integral + mean).clamp(0.0, 1.0), variance)
}

/// `clamp(open . t, 0, A(n) . t)` of surfel `s`: what its near field's escaping rays bring of
/// the probes' sky `t` (in units of pi).
fn probes_sky(asset: &Asset, t: &[f32; SH_COUNT], s: usize) -> f32 {
    let terms = &asset.surface.surfels[s];
    let open = terms.open.map(f16_to_f32);
    let all = cosine_transfer(decode_normal(terms.normal));
    let dot = |a: &[f32; SH_COUNT]| (0..SH_COUNT).map(|k| a[k] * t[k]).sum::<f32>();
    dot(&open).max(0.0).min(dot(&all).max(0.0))
}

/// Per surfel, the mean of `terms` (value, variance) over the traced surfels of its near
/// group, weighted by the surfels' hits, and the variance of that mean.
fn pooled(st: &SurfaceTerms, asset: &Asset, terms: &[(f32, f32)]) -> Vec<(f32, f32)> {
    let mut out = terms.to_vec();
    for &[first, count] in &st.group_surfels {
        let range = first as usize..(first + count) as usize;
        let traced = (range.clone()).filter(|&s| st.surfels[s].mask & TERMS_TRACED != 0);
        let (sum, variance, weight) = traced.fold((0.0f64, 0.0f64, 0.0f64), |(v, q, w), s| {
            let ws = f64::from(asset.surfels[s].weight);
            let (d, var) = terms[s];
            (v + ws * f64::from(d), q + ws * ws * f64::from(var), w + ws)
        });
        if weight > 0.0 {
            let mean = ((sum / weight) as f32, (variance / (weight * weight)) as f32);
            out[range].fill(mean);
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
