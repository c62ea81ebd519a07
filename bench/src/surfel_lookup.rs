//! # The ray terms per surfel instead of per point: what a bake that stores them would give
//!
//! [`crate::ray_lookup`] traces from the shaded point itself, which no runtime can afford. A
//! bake can trace from its surfels instead (the merged surface samples, one per
//! 1/12-spacing cell and normal, grouped in normal-keyed bricks) and store per surfel which
//! probes it sees and its near-field transfer. This lookup computes exactly those per-surfel
//! values at lookup time, so that the design is measured before the asset format carries it:
//!
//! - the point's surfel: the nearest surfel of the nearest brick of its normal's dominant axis
//!   ([`NearLight::find`]); a point without one falls back to the runtime's default lookup
//!   (depth moments);
//! - a probe counts when a ray from the surfel reaches it ([`BLOCKED_WEIGHT`] otherwise); a
//!   surfel that sees none of the point's probes leaves them to the default lookup;
//! - the irradiance is scaled by `(T_open . L + near) / (T_all . L)` per channel: `T_open` and
//!   `T_all` are the SH9 sums of the surfel's [`NEAR_FIELD_RAYS`] cosine rays that escape
//!   within the reach and of all of them, `L` the point's interpolated radiance SH, `near` the
//!   summed relit radiance of the bricks the other rays hit. In a bake `T_open` and `T_all` are
//!   18 numbers per surfel and `near` a gather over the bricks within reach.
//!
//! Why per surfel and not per brick: a brick is 4x4x4 cells of one normal axis, so the floor
//! on both sides of a wall standing on it is one brick, and "any of its surfels sees the
//! probe" lets the far room's probes in (fixtures/two_rooms at half spacing: 14.6% with
//! per-brick values, 6.3% per surfel). One value per surfel, no blending between surfels: the
//! seams this leaves are part of what it measures.

use glam::Vec3;
use prt_bake::merge::key::dominant_axis;
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, Surfel};
use prt_runtime::shadow_rays::{occluded, ray_offset};
use prt_runtime::{LookupSettings, Sample, VolumeSampler};

use crate::ray_lookup::{
    closest_hit, cosine_spiral, NearLight, RaySettings, BLOCKED_WEIGHT, NEAR_FIELD_RAYS, RAY_START,
};

/// The ray terms of [`RaySettings::with_near_light`], decided per surfel.
pub struct SurfelLookup<'a> {
    asset: &'a Asset,
    trilinear: VolumeSampler<'a>,
    fallback: VolumeSampler<'a>,
    near: &'a NearLight,
    reach: f32,
}

impl<'a> SurfelLookup<'a> {
    /// The surfel lookup of `asset` relit to `sh`, its bricks' relit radiance in `near`.
    pub fn new(asset: &'a Asset, sh: &'a [ShRgb], near: &'a NearLight) -> Self {
        let trilinear = LookupSettings {
            depth_moments: false,
            ..LookupSettings::default()
        };
        let spacing = asset.header.grid.spacing;
        let reach = RaySettings::with_near_light().near_field.unwrap_or(0.0) * spacing;
        SurfelLookup {
            asset,
            trilinear: VolumeSampler::for_asset(asset, sh, &trilinear),
            fallback: VolumeSampler::for_asset(asset, sh, &LookupSettings::default()),
            near,
            reach,
        }
    }

    /// The sample at `position` for a surface with unit normal `normal`, and whether a surfel
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
        let p = Vec3::from(position);
        let nearest = surfels.iter().min_by(|a, b| {
            let d = |s: &Surfel| Vec3::from(s.position).distance_squared(p);
            d(a).total_cmp(&d(b))
        });
        let Some(surfel) = nearest else {
            return (self.fallback.sample(position, normal), false);
        };
        let surfels = std::slice::from_ref(surfel);
        let seen = std::cell::Cell::new(false);
        let mut s = self
            .trilinear
            .sample_weighted(position, normal, |_, probe| {
                let v = self.visibility(surfels, probe);
                seen.set(seen.get() || v == 1.0);
                v
            });
        if !seen.get() {
            // The brick sees none of the point's probes: the default lookup decides.
            s = self.fallback.sample(position, normal);
        }
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

    /// [`BLOCKED_WEIGHT`] unless a ray from one of `surfels` reaches `probe`.
    fn visibility(&self, surfels: &[Surfel], probe: Vec3) -> f32 {
        let sees = surfels.iter().any(|s| {
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

    /// The open and total SH sums and the near radiance sum (module docs) of [`NEAR_FIELD_RAYS`]
    /// rays taken in turn from `surfels`.
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
