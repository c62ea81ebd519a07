//! # The ray terms per brick instead of per point: what a bake that stores them would give
//!
//! [`crate::ray_lookup`] traces from the shaded point itself, which no runtime can afford. A
//! bake can trace from its bricks instead (the normal-keyed 4x4x4-cell surface patches the
//! probes' rays found) and store per brick: which probes its surfels see, and its near-field
//! transfer (the open share of the far field as SH, the near hits' bricks as a gather list).
//! This lookup computes exactly those per-brick values, from the brick's surfels, at lookup
//! time, so that the design is measured before the asset format carries it:
//!
//! - the point's brick is the nearest of its normal's dominant axis ([`NearLight::find`]); a
//!   point without one falls back to the runtime's default lookup (depth moments);
//! - a probe counts when a ray from any of the brick's first [`VISIBILITY_SURFELS`] surfels
//!   reaches it ([`BLOCKED_WEIGHT`] otherwise);
//! - the irradiance is scaled by `(T_open . L + near) / (T_all . L)` per channel: `T_open` and
//!   `T_all` are the SH9 sums of the brick's [`NEAR_FIELD_RAYS`] cosine rays (spread over its
//!   surfels) that escape within the reach and of all of them, `L` the point's interpolated
//!   radiance SH, `near` the summed relit radiance of the bricks the other rays hit.
//!
//! One value per brick, no blending between bricks: the seams this leaves are part of what it
//! measures.

use glam::Vec3;
use prt_bake::merge::key::dominant_axis;
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, Surfel};
use prt_runtime::shadow_rays::{occluded, ray_offset};
use prt_runtime::{LookupSettings, Sample, VolumeSampler};

use crate::ray_lookup::{
    closest_hit, cosine_spiral, NearLight, RaySettings, BLOCKED_WEIGHT, NEAR_FIELD_RAYS, RAY_START,
};

/// Surfels of a brick that test probe visibility (a probe counts if any of them sees it).
pub const VISIBILITY_SURFELS: usize = 8;

/// The ray terms of [`RaySettings::with_near_light`], decided per brick.
pub struct BrickLookup<'a> {
    asset: &'a Asset,
    trilinear: VolumeSampler<'a>,
    fallback: VolumeSampler<'a>,
    near: &'a NearLight,
    reach: f32,
}

impl<'a> BrickLookup<'a> {
    /// The brick lookup of `asset` relit to `sh`, its bricks' relit radiance in `near`.
    pub fn new(asset: &'a Asset, sh: &'a [ShRgb], near: &'a NearLight) -> Self {
        let trilinear = LookupSettings {
            depth_moments: false,
            ..LookupSettings::default()
        };
        let spacing = asset.header.grid.spacing;
        let reach = RaySettings::with_near_light().near_field.unwrap_or(0.0) * spacing;
        BrickLookup {
            asset,
            trilinear: VolumeSampler::for_asset(asset, sh, &trilinear),
            fallback: VolumeSampler::for_asset(asset, sh, &LookupSettings::default()),
            near,
            reach,
        }
    }

    /// The sample at `position` for a surface with unit normal `normal`, and whether a brick
    /// was found (false: the fallback's sample).
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> (Sample, bool) {
        let Some(brick) = self
            .near
            .find(Vec3::from(position), dominant_axis(normal.into()))
        else {
            return (self.fallback.sample(position, normal), false);
        };
        let b = &self.asset.bricks[brick as usize];
        let surfels = &self.asset.surfels
            [b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize];
        let mut s = self
            .trilinear
            .sample_weighted(position, normal, |_, probe| self.visibility(surfels, probe));
        let (open, all, near) = self.transfer(surfels);
        for (ch, (e, near)) in s.irradiance.iter_mut().zip(near).enumerate() {
            let dot = |t: &[f32; SH_COUNT]| (0..SH_COUNT).map(|i| s.sh[i][ch] * t[i]).sum::<f32>();
            let total = dot(&all);
            if total > 0.0 {
                *e *= ((dot(&open) + near) / total).max(0.0);
            }
        }
        (s, true)
    }

    /// [`BLOCKED_WEIGHT`] unless a ray from one of the first surfels reaches `probe`.
    fn visibility(&self, surfels: &[Surfel], probe: Vec3) -> f32 {
        let sees = surfels.iter().take(VISIBILITY_SURFELS).any(|s| {
            let o = self.start(s);
            let d = probe - o;
            let len = d.length();
            len <= 0.0 || !occluded(&self.asset.geometry, o, d / len, len)
        });
        if sees {
            1.0
        } else {
            BLOCKED_WEIGHT
        }
    }

    /// The brick's open and total SH sums and its near radiance sum (module docs), from
    /// [`NEAR_FIELD_RAYS`] rays taken in turn from its surfels.
    fn transfer(&self, surfels: &[Surfel]) -> ([f32; SH_COUNT], [f32; SH_COUNT], [f32; 3]) {
        let (mut open, mut all, mut near) = ([0.0; SH_COUNT], [0.0; SH_COUNT], [0.0f32; 3]);
        for k in 0..NEAR_FIELD_RAYS {
            let s = &surfels[k as usize % surfels.len()];
            let n = Vec3::from(s.normal);
            let (t, b) = n.any_orthonormal_pair();
            let d = cosine_spiral(k, t, b, n);
            let y = prt_format::sh::basis(d.to_array());
            let o = self.start(s);
            match closest_hit(&self.asset.geometry, o, d, self.reach) {
                Some((t, hit_normal)) => {
                    let facing = if hit_normal.dot(d) > 0.0 {
                        -hit_normal
                    } else {
                        hit_normal
                    };
                    let r = self.near_radiance(o + d * t, facing);
                    for ch in 0..3 {
                        near[ch] += r[ch];
                    }
                }
                None => (0..SH_COUNT).for_each(|i| open[i] += y[i]),
            }
            (0..SH_COUNT).for_each(|i| all[i] += y[i]);
        }
        (open, all, near)
    }

    fn near_radiance(&self, p: Vec3, facing: Vec3) -> [f32; 3] {
        self.near.radiance_at(p, dominant_axis(facing))
    }

    /// Where a surfel's rays start: [`RAY_START`] spacings along its normal.
    fn start(&self, s: &Surfel) -> Vec3 {
        let p = Vec3::from(s.position);
        let spacing = self.asset.header.grid.spacing;
        p + Vec3::from(s.normal) * (RAY_START * spacing).max(ray_offset(p, spacing))
    }
}
