//! `sky_point` (`prt-bench surface --lookup sky_point [--path-rays N]`): the runtime's lookup
//! with the sky's direct share replaced by the point's own (issue 31, stop 54; a reference,
//! not in the runtime). The probes' direct view of the sky is sampled through the same lookup
//! from SH relit with the sky alone over black surfels (`surface::sky_view`) and subtracted;
//! the point's own sky light is added back: `rays` cosine-distributed rays from the point, pi /
//! `rays` times the sky's radiance along those that leave the scene (any sky, as the `path`
//! lookup reads it). The subtraction goes through the lookup's clamps (the near field's
//! `clamp(open . L, 0, A(n) . L)`, irradiance at least 0, and since stop 70 the floor under
//! L2's ringing), so it is exact only where they do not bind.
//!
//! What it is for: probes a spacing from a point see more or less of a bright sky than the
//! point does (a wall under an overhang, a cave's skylight, a gallery's ceiling beside an open
//! court), and the near field, one spacing long, does not reach the occluder. This measures
//! what a baked per-surfel sky term would bring, with the point's visibility exact. At 256 rays
//! its own noise is larger than the gain (a skylight seen through a small solid angle).

use glam::Vec3;
use prt_format::Asset;
use prt_runtime::shadow_rays::closest_hit;
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{Sample, SkyModel};

use crate::ray_lookup::ray_start;

/// Rays per point by default (`--path-rays`): at 256 the share of a small skylight is too
/// noisy to compare (cave_31 5.9% -> 8.6% against 4.9% at 4,096).
pub const SKY_RAYS: u32 = 4096;

/// The lookup over one bake and its rig's sky.
pub struct SkyPointLookup<'a> {
    asset: &'a Asset,
    default: SurfaceSampler<'a>,
    sky_only: SurfaceSampler<'a>,
    sky: &'a SkyModel,
    rays: u32,
}

impl<'a> SkyPointLookup<'a> {
    /// `default` samples the relit probes, `sky_only` their direct view of the sky (the same
    /// lookup settings, over black surfels), `sky` the rig's sky.
    pub fn new(
        asset: &'a Asset,
        (default, sky_only): (SurfaceSampler<'a>, SurfaceSampler<'a>),
        sky: &'a SkyModel,
        rays: u32,
    ) -> Self {
        SkyPointLookup {
            asset,
            default,
            sky_only,
            sky,
            rays,
        }
    }

    /// The irradiance at `position` on a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let mut out = self.default.sample(position, normal);
        let probes = self.sky_only.sample(position, normal);
        let n = Vec3::from(normal).normalize_or_zero();
        let x = ray_start(Vec3::from(position), n, self.asset.header.grid.spacing);
        let (t, b) = n.any_orthonormal_pair();
        let mut own = Vec3::ZERO;
        for k in 0..self.rays {
            let d = prt_bake::surface_terms::cosine_spiral(k, self.rays, t, b, n);
            if closest_hit(&self.asset.geometry, x, d, f32::MAX).is_none() {
                own += Vec3::from(self.sky.radiance(d.to_array()));
            }
        }
        let own = own * std::f32::consts::PI / self.rays as f32;
        for ch in 0..3 {
            out.irradiance[ch] = (out.irradiance[ch] - probes.irradiance[ch] + own[ch]).max(0.0);
        }
        out
    }
}
