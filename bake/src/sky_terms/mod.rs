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
//!   surfel moved [`SURFACE_BIAS`] spacings along its normal, a probe the surfel does not see
//!   weighted `BLOCKED_WEIGHT`, a filled grid point its coarse level's as the runtime fills
//!   it); `clamp(open . T, 0, A(n) . T)` is what the lookup's escaping near-field rays bring of
//!   that sky (the same clamp);
//! - `v`: the share of the surfel's cosine-weighted hemisphere that leaves the scene, from
//!   [`SKY_RAYS`] rays (the near field's spiral, turned per surfel; [`MORE_SKY_RAYS`] more
//!   where the term is uncertain, below) with the probes' sky as a
//!   control variate: `A(n) . T + mean over the rays of (V(w) - T . Y(w))`, `V` 1 for a ray
//!   that escapes. `T . Y` is the probes' visibility of the sky in SH; its cosine integral is
//!   `A(n) . T` exactly, so the estimate stays unbiased, and where the surfel sees the sky as
//!   its probes do only the difference is noisy;
//! - **pooled**: `v` less a baseline known exactly at each surfel (the probes' sky
//!   `clamp(...)`, the control variate's `A(n) . T`, or none: the one that leaves the group most
//!   uniform, [`pooled`]), averaged over the near group (the surfels of its brick that see the
//!   same probes), weighted by the surfels' hits, each surfel adding its own baseline back;
//! - **traced again where uncertain**: the surfels of a group whose pooled term the shrink
//!   would cut by a tenth or more of its sky ([`UNCERTAIN`]) get [`MORE_SKY_RAYS`] more rays
//!   (another spiral), their `v` the mean over both passes, and the groups are pooled anew;
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
//! - the uncertain groups traced again with 384 more rays (stop 65, the default:
//!   [`MORE_SKY_RAYS`], [`UNCERTAIN`]): 5.55 / 7.42% and 3.10 / 4.19% (cave_7 7.74% -> 6.71%,
//!   half 5.46% -> 4.19%; no tuning level worse by more than 0.02 point); on the sets not tuned
//!   on, median / worst level 5.12 / 7.31%, 4.73 / 6.52%, 5.27 / 12.18% (fresh interior_32 from
//!   12.90%), the blind sets of stops 64 and 65 4.32 / 12.99% and 5.54 / 15.64% (cave_139 from
//!   18.30%: a dark point that kept 55% of its probes' sky); Sponza under the sun 14.81% ->
//!   14.55%. 768 more rays measure alike on the tuning seeds at more time; tracing again the
//!   groups whose term is 1-4 times its shrinkage (768 more), 5.51 / 7.33% and 3.06 / 4.36%, traces a
//!   quarter to a half of every level's surfels; a darkening term shrunk by a quarter or no
//!   deviation instead, 8.25% and 8.99% on cave_7. It costs Sponza's bake 33% (a third of its
//!   surfels), the family's 5-30% (docs/results/surface_sky_uncertain.md);
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
//! Deterministic: each surfel's term depends only on the asset and fixed ray sets, which
//! surfels are traced again only on the first pass's terms, and groups are summed in surfel
//! order (`tests/tests/repeat.rs` bakes Cornell, where a few percent of the surfels are traced
//! again, with one thread and with two).

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_format::surface::{cosine_transfer, BLOCKED_WEIGHT, SURFACE_BIAS};
use prt_format::{f32_to_f16, tier, Asset};
use rayon::prelude::*;

use crate::accel::bvh::SceneBvh;
use crate::accel::bvh8::PACKET;
use crate::surface_terms::{cosine_spiral, surfel_origin};

mod pool;
use pool::{pooled, shrunk, uncertain_surfels, Traced};

/// Sky rays per surfel in the first pass.
pub const SKY_RAYS: u32 = 256;

/// Rays a surfel gets on top of [`SKY_RAYS`] where its group's first-pass term is uncertain
/// ([`UNCERTAIN`]): its view is then the mean over both passes' 640 rays. Module docs: what
/// chose it.
pub const MORE_SKY_RAYS: u32 = 384;

/// The most rays one pass traces at a surfel: its directions sit in a fixed array.
const MAX_RAYS: usize = if SKY_RAYS > MORE_SKY_RAYS {
    SKY_RAYS
} else {
    MORE_SKY_RAYS
} as usize;

/// A pooled term is uncertain where the shrink takes off at least this share of the sky its
/// surfel sees or its probes bring it (the larger), and leaves some of the term: the sky it
/// puts on the point could be a tenth or more wrong either way. A term the shrink takes off
/// whole is left as noise, and one it takes off a sliver of is already sure.
pub const UNCERTAIN: f32 = 0.1;

/// Standard deviations of its noise a sky term that brightens its surfel is shrunk by toward 0.
pub const SHRINK: f32 = 1.0;

/// Standard deviations of its noise a sky term that darkens its surfel (it sees less sky than
/// its probes bring it) is shrunk by toward 0: less than a brightening one, because the errors
/// are not alike. A darkening term shrunk too far leaves the probes' sky on the point, the
/// over-lighting issue 31 counts as a leak (a ceiling under a gallery beside a sunlit court);
/// one shrunk too little darkens a point that sees a little sky under its noise (a cave's floor
/// under a small skylight). Module docs: what chose it.
pub const SHRINK_DARKER: f32 = 0.5;

/// The asset's sky terms, two halves a word (empty when it has no surface terms): every traced
/// surfel's view over [`SKY_RAYS`] rays, pooled; the surfels of groups whose term is then
/// uncertain traced again with [`MORE_SKY_RAYS`] more and pooled anew; shrunk.
pub fn sky_terms(asset: &Asset, bvh: &SceneBvh) -> Vec<u32> {
    let st = &asset.surface;
    if st.is_empty() || st.surfels.len() != asset.surfels.len() {
        return Vec::new();
    }
    let sampler = Sampler::new(asset, bvh);
    let first = spiral_order(SKY_RAYS);
    let mut views: Vec<Option<View>> = (0..st.surfels.len())
        .into_par_iter()
        .map(|s| sampler.view(s, &first))
        .collect();
    let mut terms = pooled(&st.group_surfels, &sampler.traced(&views));
    let shares: Vec<Option<f32>> = views.iter().map(|w| w.map(|w| w.share())).collect();
    let again = uncertain_surfels(&st.group_surfels, &shares, &terms);
    if !again.is_empty() {
        let more = spiral_order(MORE_SKY_RAYS);
        let second: Vec<Option<View>> = again.par_iter().map(|&s| sampler.view(s, &more)).collect();
        for (&s, b) in again.iter().zip(second) {
            views[s] = views[s].zip(b).map(|(a, b)| a.merged(&b));
        }
        terms = pooled(&st.group_surfels, &sampler.traced(&views));
    }
    let sky: Vec<f32> = (terms.iter().zip(&views))
        .map(|(&(d, variance), view)| match view {
            Some(_) => shrunk(d, variance),
            None => 0.0,
        })
        .collect();
    sky.chunks(2)
        .map(|p| {
            let h = |v: Option<&f32>| u32::from(f32_to_f16(v.copied().unwrap_or(0.0)));
            h(p.first()) | h(p.get(1)) << 16
        })
        .collect()
}

/// What a surfel's sky is traced against: the asset, its BVH, each grid point's sky transfer
/// ([`grid_transfer`]) and per brick its key's centre probe (which its surfels' masks are
/// stored from).
struct Sampler<'a> {
    asset: &'a Asset,
    bvh: &'a SceneBvh,
    transfer: Vec<[f32; SH_COUNT]>,
    centres: Vec<[i32; 3]>,
}

impl<'a> Sampler<'a> {
    fn new(asset: &'a Asset, bvh: &'a SceneBvh) -> Self {
        let grid = &asset.header.grid;
        let centres = (asset.bricks.iter())
            .map(|b| asset.surface.brick_centre(grid, b))
            .collect();
        Sampler {
            asset,
            bvh,
            transfer: grid_transfer(asset),
            centres,
        }
    }

    /// Surfel `s`'s view of the sky over the rays of `order` ([`spiral_order`]); `None` for a
    /// surfel without traced terms.
    fn view(&self, s: usize, order: &[u32]) -> Option<View> {
        let asset = self.asset;
        if !asset.surface.surfels[s].is_traced() {
            return None;
        }
        let key_centre = self.centres[asset.surfels[s].brick as usize];
        let t = interpolated_transfer(asset, &self.transfer, s, key_centre);
        let (v, variance, cosine) = sky_view(asset, self.bvh, order, &t, s);
        Some(View {
            v,
            variance,
            rays: order.len() as f32,
            cosine,
            probes: probes_sky(asset, &t, s),
        })
    }

    /// Per surfel, what [`pooled`] takes of its view (a default for a surfel without one).
    fn traced(&self, views: &[Option<View>]) -> Vec<Traced> {
        (views.iter().zip(&self.asset.surfels))
            .map(|(view, surfel)| view.map_or(Traced::default(), |w| w.traced(surfel.weight)))
            .collect()
    }
}

/// A surfel's traced view of the sky: `v` ([`sky_view`], not clamped) over `rays` rays and
/// the variance of that mean; the control variate's integral `A(n) . T` and the probes' sky
/// through its near field ([`probes_sky`]), its baselines.
#[derive(Clone, Copy, Debug)]
struct View {
    v: f32,
    variance: f32,
    rays: f32,
    cosine: f32,
    probes: f32,
}

impl View {
    /// Two independent views of one surfel as one: each mean weighted by its rays.
    fn merged(&self, other: &View) -> View {
        let rays = self.rays + other.rays;
        let (a, b) = (self.rays / rays, other.rays / rays);
        View {
            v: a * self.v + b * other.v,
            variance: a * a * self.variance + b * b * other.variance,
            rays,
            ..*self
        }
    }

    /// The larger of the sky the surfel sees (its view clamped to [0, 1]) and the sky its
    /// probes bring it.
    fn share(&self) -> f32 {
        self.v.clamp(0.0, 1.0).max(self.probes)
    }

    /// What [`pooled`] takes of it, for a surfel of `weight` hits: its view clamped to [0, 1],
    /// and a variance at least the binomial one of its [`View::share`] and of one ray (a sky
    /// seen through a crack is missed by every ray as often as not, and the sample variance of
    /// no hits is zero).
    fn traced(&self, weight: f32) -> Traced {
        let q = self.share().clamp(1.0 / self.rays, 1.0);
        Traced {
            view: self.v.clamp(0.0, 1.0),
            baselines: [self.probes, self.cosine, 0.0],
            variance: self.variance.max(q * (1.0 - q) / self.rays),
            weight,
        }
    }
}

/// The probes' sky transfer interpolated at surfel `s` with the lookup's weights: trilinear at
/// the surfel moved [`SURFACE_BIAS`] spacings along its normal, times each probe's sample
/// weight, a probe the surfel does not see times `BLOCKED_WEIGHT`; plain trilinear at the
/// same point when it sees none of them (the lookup falls back to the volume's lookup there,
/// which adds depth moments and weighs the corners of the point moved by the volume's normal
/// bias, 0.2 spacings: the two can read different corners for such a surfel). Zero where no
/// probe has weight.
fn interpolated_transfer(
    asset: &Asset,
    transfer: &[[f32; SH_COUNT]],
    s: usize,
    key_centre: [i32; 3],
) -> [f32; SH_COUNT] {
    let terms = &asset.surface.surfels[s];
    let grid = &asset.header.grid;
    let n = terms.normal();
    let at = Vec3::from(asset.surfels[s].position) + Vec3::from(n) * SURFACE_BIAS * grid.spacing;
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

/// `v` of surfel `s` over the rays of `order` (module docs: the share of its cosine-weighted
/// hemisphere that sees the sky, with the probes' sky `t` as control variate), not yet clamped
/// to [0, 1] (two passes are averaged first), the variance of its mean over the rays, and the
/// control variate's integral `A(n) . t`. The rays are traced in
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
    assert!(order.len() <= MAX_RAYS, "{} sky rays", order.len());
    let count = order.len() as u32;
    let mut dirs = [Vec3::ZERO; MAX_RAYS];
    for (k, d) in (0..count).zip(&mut dirs) {
        *d = cosine_spiral(k, count, tx, ty, n);
    }
    let dirs = &dirs[..order.len()];
    let mut escaped = [false; MAX_RAYS];
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
    let rays = count as f32;
    let mean = sum / rays;
    let all = cosine_transfer(n.to_array());
    let integral: f32 = (0..SH_COUNT).map(|k| all[k] * t[k]).sum();
    let variance = (square / rays - mean * mean).max(0.0) / rays;
    (integral + mean, variance, integral)
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

    /// Two passes' views are one mean over all their rays: weighted by rays, and the
    /// variance of that mean; the first pass's baselines are kept (both passes' are the
    /// surfel's own, the same up to rounding).
    #[test]
    fn merged_views_weigh_each_pass_by_its_rays() {
        let view = |v, variance, rays| View {
            v,
            variance,
            rays,
            cosine: 0.3,
            probes: 0.2,
        };
        let merged = view(0.1, 4e-4, 256.0).merged(&view(0.2, 1e-4, 768.0));
        assert!((merged.v - 0.175).abs() < 1e-7, "{merged:?}");
        assert!((merged.variance - 8.125e-5).abs() < 1e-10, "{merged:?}");
        assert_eq!(merged.rays, 1024.0);
        assert_eq!((merged.cosine, merged.probes), (0.3, 0.2));
        // The floor of one ray falls with the rays: a view of no sky whose probes bring none.
        let dark = View {
            probes: 0.0,
            ..view(0.0, 0.0, 256.0)
        };
        let floor = |w: View| w.traced(1.0).variance;
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b;
        assert!(
            close(floor(dark), 255.0 / 256f32.powi(3)),
            "{}",
            floor(dark)
        );
        let both = dark.merged(&view(0.0, 0.0, 768.0));
        assert_eq!(both.probes, 0.0, "the first pass's baselines");
        assert!(
            close(floor(both), 1023.0 / 1024f32.powi(3)),
            "{}",
            floor(both)
        );
        // A dark surfel's two passes are averaged before the clamp: a first pass below 0
        // pulls a second above it down.
        let merged = view(-0.004, 0.0, 256.0).merged(&view(0.002, 0.0, 768.0));
        assert!(close(merged.traced(1.0).view, 0.0005), "{merged:?}");
    }
}
