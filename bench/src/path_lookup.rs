//! `path` (`prt-bench surface --lookup path [--path-rays N]`): the one-bounce irradiance at a
//! surface point by path tracing, with no probe taking part. N cosine-distributed rays
//! ([`PATH_RAYS`] by default; the spiral of the other ray lookups' near field) leave the point
//! through the asset's BVH. A ray that
//! hits brings the radiance leaving what it hits under docs/conventions.md section 5 (emission
//! plus albedo / pi times each light's irradiance there, behind a shadow ray, as the CPU relight
//! lights a surfel); one that escapes brings the sky's. The irradiance is pi / N times their sum.
//! The albedo and emission are those of the surfel nearest the hit in the brick of the side the
//! ray hits ([`NearLight::find_side`]; a back face of a single-sided surface is black).
//!
//! What it is for: it checks the benchmark against the oracle with nothing of the probes
//! involved, and it shows what the probes cost a lookup. Its error is the Monte Carlo noise of
//! its rays and whatever the benchmark gets wrong (the merged surfels' materials, the rig's
//! units, and the L2 truncation of the reference it is scored against); with enough rays
//! (4,096 on Sponza: 5.15% against the default lookup's 15.84%), what a lookup that reads the
//! probes loses beyond it is the radiance they carry, L2 and a spacing from the point, not
//! the lookup's visibility (docs/results/surface_candidates.md, stops 42-43). At the default
//! 256 rays its noise is as large as the probes' error on Sponza: use it with more rays.

use glam::Vec3;
use prt_bake::merge::key::dominant_axis;
use prt_format::Asset;
use prt_runtime::lights::PreparedLight;
use prt_runtime::shadow_rays::{closest_hit, lit};
use prt_runtime::{Sample, SkyModel};

use crate::ray_lookup::{facing_normal, nearest_surfel, ray_start, NearLight, NEAR_FIELD_RAYS};

/// Rays per point by default (`--path-rays`): the other ray lookups' near-field count, which
/// keeps a run over the family to minutes.
pub const PATH_RAYS: u32 = NEAR_FIELD_RAYS;

/// The path tracer over one bake and one rig.
pub struct PathLookup<'a> {
    asset: &'a Asset,
    bricks: &'a NearLight,
    lights: Vec<PreparedLight>,
    sky: &'a SkyModel,
    rays: u32,
}

impl<'a> PathLookup<'a> {
    /// The lookup of `asset` lit by `lights` and `sky` with `rays` rays per point; `bricks`
    /// finds what a ray hits.
    pub fn new(
        asset: &'a Asset,
        bricks: &'a NearLight,
        (lights, sky): (&prt_format::LightRig, &'a SkyModel),
        rays: u32,
    ) -> Self {
        PathLookup {
            asset,
            bricks,
            lights: lights.lights.iter().map(PreparedLight::new).collect(),
            sky,
            rays,
        }
    }

    /// The irradiance at `position` on a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let n = Vec3::from(normal);
        let start = ray_start(Vec3::from(position), n, self.asset.header.grid.spacing);
        let (t, b) = n.any_orthonormal_pair();
        let mut sum = Vec3::ZERO;
        for k in 0..self.rays {
            let d = prt_bake::surface_terms::cosine_spiral(k, self.rays, t, b, n);
            // Without end (f32::MAX, as a directional light's shadow ray): whatever the level
            // holds along the ray is nearer.
            sum += match closest_hit(&self.asset.geometry, start, d, f32::MAX) {
                Some((t, tri)) => {
                    let facing = facing_normal(&self.asset.geometry, tri, d);
                    self.leaving(start + d * t, facing)
                }
                None => Vec3::from(self.sky.radiance(d.to_array())),
            };
        }
        Sample {
            irradiance: (sum * std::f32::consts::PI / self.rays as f32).to_array(),
            validity: 1.0,
            ..Sample::default()
        }
    }

    /// One-bounce radiance leaving `h` on the side with unit normal `n`.
    fn leaving(&self, h: Vec3, n: Vec3) -> Vec3 {
        let Some((brick, false)) = self.bricks.find_side(h, dominant_axis(n)) else {
            return Vec3::ZERO;
        };
        let Some(s) = nearest_surfel(self.asset, brick, h) else {
            return Vec3::ZERO;
        };
        let spacing = self.asset.header.grid.spacing;
        let mut e = Vec3::ZERO;
        for light in &self.lights {
            let (el, l, dist) = light.irradiance(h, n);
            if el.max_element() <= 0.0 {
                continue;
            }
            // As the CPU relight lights a surfel.
            let at = dist.is_finite().then_some(light.position);
            if lit(&self.asset.geometry, h, n, spacing, l, at) {
                e += el;
            }
        }
        Vec3::from(s.emission) + Vec3::from(s.albedo) * std::f32::consts::FRAC_1_PI * e
    }
}
