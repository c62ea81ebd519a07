//! # The ray terms per surfel instead of per point: what a bake that stores them would give
//!
//! [`crate::ray_lookup`] traces from the shaded point itself, which no runtime can afford. A
//! bake can trace from its surfels instead (the merged surface samples, one per
//! surfel cell and normal, grouped in normal-keyed bricks) and store per surfel which
//! probes it sees and its near-field transfer. This lookup computes exactly those per-surfel
//! values at lookup time, so that the design is measured before the asset format carries it:
//!
//! - the point's surfel: the nearest surfel of the brick of its normal's dominant axis whose
//!   centroid is nearest ([`NearLight::find`]); a point without one falls back to the runtime's
//!   default lookup (depth moments). A runtime would find it by key instead (the brick's cell
//!   and axis, then the point's cell inside the brick), which can pick a different surfel near
//!   brick borders: the bound is for the stored values, not for that search;
//! - a probe counts when a ray from the surfel reaches it ([`BLOCKED_WEIGHT`] otherwise); a
//!   surfel that sees none of the point's probes leaves them to the default lookup;
//! - the irradiance is scaled by `(clamp(T_open . L, 0, T_all . L) + near) / (T_all . L)` per
//!   channel (the runtime's `scale_by_near_field`, whose clamp since stop 52 this reference
//!   shares: its rows in docs/results/surface.md predate it): `T_open` and `T_all` are the SH9
//!   sums of the surfel's [`NEAR_FIELD_RAYS`] cosine rays that escape
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
use prt_runtime::surface::scale_by_near_field;
use prt_runtime::{LookupSettings, Sample, VolumeSampler};

use crate::ray_lookup::{
    cosine_spiral, nearest_surfel, ray_start, sees, NearLight, RaySettings, BLOCKED_WEIGHT,
    NEAR_FIELD_RAYS,
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
    /// The surfel lookup of `asset` relit to `sh`, its bricks' relit radiance in `near`; the
    /// trilinear weights take `lookup`'s surface bias (as the runtime's surface lookup) and the
    /// fallback its normal bias.
    pub fn new(
        asset: &'a Asset,
        sh: &'a [ShRgb],
        near: &'a NearLight,
        lookup: &LookupSettings,
    ) -> Self {
        let trilinear = LookupSettings {
            depth_moments: false,
            normal_bias: lookup.surface_bias,
            ..*lookup
        };
        let fallback = LookupSettings {
            depth_moments: true,
            ..*lookup
        };
        let spacing = asset.header.grid.spacing;
        let reach = RaySettings::with_near_light().near_field.unwrap_or(0.0) * spacing;
        SurfelLookup {
            asset,
            trilinear: VolumeSampler::for_asset(asset, sh, &trilinear),
            fallback: VolumeSampler::for_asset(asset, sh, &fallback),
            near,
            reach,
        }
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let p = Vec3::from(position);
        let surfel = self
            .near
            .find(p, dominant_axis(normal.into()))
            .and_then(|b| nearest_surfel(self.asset, b, p));
        let Some(surfel) = surfel else {
            return self.fallback.sample(position, normal);
        };
        let start = self.start(surfel);
        let geo = &self.asset.geometry;
        let seen = std::cell::Cell::new(false);
        let mut s = self
            .trilinear
            .sample_weighted(position, normal, |_, probe| {
                let sees = sees(geo, start, probe);
                seen.set(seen.get() || sees);
                if sees {
                    1.0
                } else {
                    BLOCKED_WEIGHT
                }
            });
        if !seen.get() {
            // The surfel sees none of the point's probes: the default lookup decides.
            s = self.fallback.sample(position, normal);
        }
        let (open, all, near) = self.transfer(surfel);
        scale_by_near_field(&mut s, &open, &all, near);
        s
    }

    /// The open and total SH sums and the near radiance sum (module docs) of the surfel's
    /// [`NEAR_FIELD_RAYS`] cosine rays.
    fn transfer(&self, surfel: &Surfel) -> ([f32; SH_COUNT], [f32; SH_COUNT], [f32; 3]) {
        let geo = &self.asset.geometry;
        let (mut open, mut all, mut near) = ([0.0; SH_COUNT], [0.0; SH_COUNT], [0.0f32; 3]);
        let n = Vec3::from(surfel.normal);
        let (t, b) = n.any_orthonormal_pair();
        let o = self.start(surfel);
        for k in 0..NEAR_FIELD_RAYS {
            let d = cosine_spiral(k, t, b, n);
            let y = prt_format::sh::basis(d.to_array());
            match self.near.trace(geo, o, d, self.reach) {
                Some(r) => (0..3).for_each(|ch| near[ch] += r[ch]),
                None => (0..SH_COUNT).for_each(|i| open[i] += y[i]),
            }
            (0..SH_COUNT).for_each(|i| all[i] += y[i]);
        }
        (open, all, near)
    }

    /// Where a surfel's rays start ([`ray_start`]).
    fn start(&self, s: &Surfel) -> Vec3 {
        let spacing = self.asset.header.grid.spacing;
        ray_start(s.position.into(), s.normal.into(), spacing)
    }
}
