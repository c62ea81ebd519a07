//! # A reference lookup that traces rays through the asset's BVH (issue 31, item 3)
//!
//! The engine-side snippet weights each of the eight probes around a point by DDGI's Chebyshev
//! test against the probe's depth moments, and returns the probes' interpolated irradiance. On
//! levels no one tuned for (`fixtures/levels/`) that leaves two errors the moments cannot see:
//!
//! - **Light through occluders.** A probe the point cannot see (the far side of a thin cave
//!   shell, a wall between layers) still weighs when its moments are too coarse to reject it.
//!   [`RaySettings::visibility`] decides it exactly: a ray from the point (moved
//!   [`RAY_START`] spacings along its normal) to the probe, through the asset's BVH
//!   (`prt_runtime::shadow_rays::occluded`); a blocked probe keeps [`BLOCKED_WEIGHT`] of its
//!   weight, so a point that sees none of its eight still gets their trilinear mean.
//! - **Occluders nearer the point than its probes.** A facade under a balcony, a floor under a
//!   gallery, a gap behind a crate: the probes, a spacing away, see past the occluder and the
//!   point gets their (brighter) light. [`RaySettings::near_field`] traces [`NEAR_FIELD_RAYS`]
//!   cosine-distributed rays over the point's hemisphere, each no further than `near_field`
//!   spacings, and scales the irradiance by the share of the interpolated radiance
//!   `sum L(w)` that arrives along the rays that escape (an occluder within reach is taken as
//!   dark: a one-bounce occluder lit only from the far side is). This is a precomputed
//!   radiance transfer vector (Sloan et al., SIGGRAPH 2002) restricted to the near field,
//!   evaluated here per point and exactly, to measure what a baked one could reach.
//!
//! Both cost rays per lookup (8 and 256), which is why this is a benchmark reference and not the
//! runtime's lookup: `prt-bench surface --lookup rays` measures the upper bound of a baked
//! per-surface-cell visibility mask and transfer vector before either is built. Figures:
//! `docs/results/surface_candidates.md`.

use glam::Vec3;
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, Geometry, Grid, Probe};
use prt_runtime::shadow_rays::{occluded, ray_offset};
use prt_runtime::{LookupSettings, Sample, VolumeSampler};

/// Where the rays start: this many probe spacings off the surface along its normal (1 cm on a
/// 1 m grid), and never less than the shadow rays' own offset.
pub const RAY_START: f32 = 0.01;

/// Weight kept by a probe the point cannot see: small enough that any visible probe wins,
/// nonzero so that a point that sees none of its eight still gets their trilinear mean.
pub const BLOCKED_WEIGHT: f32 = 1e-4;

/// Hemisphere rays of the near-field term (a Fibonacci spiral, cosine-distributed).
pub const NEAR_FIELD_RAYS: u32 = 256;

/// What the ray lookup adds to the trilinear one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RaySettings {
    /// Weight each probe by whether a ray from the point reaches it.
    pub visibility: bool,
    /// Reach of the near-field occlusion term in probe spacings; `None` leaves it out.
    /// 0.75 was chosen on the family's tuning seeds (0.5 / 0.75 / 1.0 / 1.5, median and worst
    /// level of the open-point mean: `docs/results/surface_candidates.md`).
    pub near_field: Option<f32>,
}

impl Default for RaySettings {
    fn default() -> Self {
        RaySettings {
            visibility: true,
            near_field: Some(0.75),
        }
    }
}

/// The trilinear lookup (at the runtime's default normal bias, without depth moments) with
/// [`RaySettings`]' ray tests on top.
pub struct RayLookup<'a> {
    sampler: VolumeSampler<'a>,
    geometry: &'a Geometry,
    spacing: f32,
    settings: RaySettings,
}

impl<'a> RayLookup<'a> {
    /// The ray lookup of `asset` relit to `sh`.
    pub fn for_asset(asset: &'a Asset, sh: &'a [ShRgb], settings: RaySettings) -> Self {
        Self::new(
            &asset.header.grid,
            &asset.probes,
            &asset.geometry,
            sh,
            settings,
        )
    }

    /// The ray lookup over probes `probes` of `grid` with SH `sh`, tracing through `geometry`.
    pub fn new(
        grid: &Grid,
        probes: &[Probe],
        geometry: &'a Geometry,
        sh: &'a [ShRgb],
        settings: RaySettings,
    ) -> Self {
        let bias = LookupSettings::default().normal_bias * grid.spacing;
        RayLookup {
            sampler: VolumeSampler::new(grid, probes, sh, bias),
            geometry,
            spacing: grid.spacing,
            settings,
        }
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let n = Vec3::from(normal);
        let p = Vec3::from(position);
        let start = p + n * (RAY_START * self.spacing).max(ray_offset(p, self.spacing));
        let mut s = if self.settings.visibility {
            self.sampler.sample_weighted(position, normal, |_, probe| {
                let d = probe - start;
                let len = d.length();
                if len > 0.0 && occluded(self.geometry, start, d / len, len) {
                    BLOCKED_WEIGHT
                } else {
                    1.0
                }
            })
        } else {
            self.sampler.sample(position, normal)
        };
        if let Some(reach) = self.settings.near_field {
            let open = self.open_share(&s.sh, start, n, reach * self.spacing);
            for (e, o) in s.irradiance.iter_mut().zip(open) {
                *e *= o;
            }
        }
        s
    }

    /// Per channel, the share of the cosine-weighted radiance `sh` over the hemisphere around
    /// `n` that arrives along rays from `start` no occluder within `reach` blocks (1 when the
    /// hemisphere is dark).
    fn open_share(&self, sh: &ShRgb, start: Vec3, n: Vec3, reach: f32) -> [f32; 3] {
        let (t, b) = n.any_orthonormal_pair();
        let (mut open, mut all) = ([0.0f32; 3], [0.0f32; 3]);
        for k in 0..NEAR_FIELD_RAYS {
            let d = cosine_spiral(k, t, b, n);
            let y = prt_format::sh::basis(d.to_array());
            let blocked = occluded(self.geometry, start, d, reach);
            for ch in 0..3 {
                let l = (0..SH_COUNT)
                    .map(|i| sh[i][ch] * y[i])
                    .sum::<f32>()
                    .max(0.0);
                all[ch] += l;
                if !blocked {
                    open[ch] += l;
                }
            }
        }
        std::array::from_fn(|ch| {
            if all[ch] > 0.0 {
                open[ch] / all[ch]
            } else {
                1.0
            }
        })
    }
}

/// Direction `k` of [`NEAR_FIELD_RAYS`] on a golden-angle spiral, cosine-distributed over the
/// hemisphere around `n` (tangents `t`, `b`): equal-area rings in the unit disk lifted to it.
fn cosine_spiral(k: u32, t: Vec3, b: Vec3, n: Vec3) -> Vec3 {
    const GOLDEN_ANGLE: f32 = 2.399_963;
    let u = (k as f32 + 0.5) / NEAR_FIELD_RAYS as f32;
    let phi = k as f32 * GOLDEN_ANGLE;
    let (sin_t, cos_t) = (u.sqrt(), (1.0 - u).sqrt());
    t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + n * cos_t
}

#[cfg(test)]
mod tests {
    use super::*;
    use prt_format::{BvhNode, Triangle, PROBE_VALID};

    /// A 2x1x1 grid (spacing 2, probes at x = 0 and 2) and, with `wall`, a wall at x = 1 over
    /// y, z in [-5, 5].
    fn two_probes(wall: bool) -> (Grid, Vec<Probe>, Geometry) {
        let grid = Grid::cubic([0.0, 0.0, 0.0], 2.0, [2, 1, 1]);
        let probes = (0..2)
            .map(|i| Probe {
                position: grid.position(i, 0, 0),
                flags: PROBE_VALID,
                ..Probe::default()
            })
            .collect();
        let mut geometry = Geometry::default();
        if wall {
            let (a, b, c, d) = (
                [1.0, -5.0, -5.0],
                [1.0, 5.0, -5.0],
                [1.0, 5.0, 5.0],
                [1.0, -5.0, 5.0],
            );
            let tri = |v0, v1, v2| Triangle {
                v0,
                v1,
                v2,
                ..Triangle::default()
            };
            geometry.triangles = vec![tri(a, b, c), tri(a, c, d)];
            geometry.nodes = vec![BvhNode {
                min: [0.9, -5.0, -5.0],
                max: [1.1, 5.0, 5.0],
                first: 0,
                count: 2,
            }];
        }
        (grid, probes, geometry)
    }

    fn lookup<'a>(
        parts: &'a (Grid, Vec<Probe>, Geometry),
        sh: &'a [ShRgb],
        settings: RaySettings,
    ) -> RayLookup<'a> {
        RayLookup::new(&parts.0, &parts.1, &parts.2, sh, settings)
    }

    fn lit_and_dark() -> Vec<ShRgb> {
        let mut lit = [[0.0f32; 3]; SH_COUNT];
        lit[0] = [1.0; 3];
        vec![lit, [[0.0; 3]; SH_COUNT]]
    }

    const UP: [f32; 3] = [0.0, 1.0, 0.0];

    /// Without a wall the ray lookup is the trilinear one; a wall between the probes hides the
    /// lit one from a point on the dark side.
    #[test]
    fn visibility_hides_the_probe_behind_a_wall() {
        let sh = lit_and_dark();
        let settings = RaySettings {
            visibility: true,
            near_field: None,
        };
        let open = two_probes(false);
        let at = [1.5, 0.0, 0.0];
        let trilinear = VolumeSampler::new(&open.0, &open.1, &sh, 0.4);
        assert_eq!(
            lookup(&open, &sh, settings).sample(at, UP),
            trilinear.sample(at, UP)
        );
        let walled = two_probes(true);
        let dark_side = lookup(&walled, &sh, settings).sample(at, UP);
        let lit_side = lookup(&walled, &sh, settings).sample([0.5, 0.0, 0.0], UP);
        assert!(dark_side.irradiance[0] < 1e-3 * lit_side.irradiance[0]);
        assert!(
            dark_side.irradiance[0] > 0.0,
            "blocked probes keep a little weight"
        );
    }

    /// A point facing the wall 0.1 spacing away loses most of its light with a reach past the
    /// wall, and none with a reach short of it.
    #[test]
    fn the_near_field_term_darkens_only_within_its_reach() {
        let sh = lit_and_dark();
        let walled = two_probes(true);
        let facing_wall = [1.0, 0.0, 0.0];
        let at = [0.8, 0.0, 0.0];
        let sample = |reach| {
            let settings = RaySettings {
                visibility: false,
                near_field: Some(reach),
            };
            lookup(&walled, &sh, settings).sample(at, facing_wall)
        };
        let plain = VolumeSampler::new(&walled.0, &walled.1, &sh, 0.4).sample(at, facing_wall);
        assert_eq!(sample(0.05).irradiance, plain.irradiance);
        assert!(sample(0.75).irradiance[0] < 0.05 * plain.irradiance[0]);
    }

    /// The spiral's directions are unit vectors in the hemisphere with a mean cosine of 2/3,
    /// the cosine distribution's.
    #[test]
    fn the_spiral_is_cosine_distributed() {
        let n = Vec3::new(0.3, 0.8, -0.52).normalize();
        let (t, b) = n.any_orthonormal_pair();
        let mut mean = 0.0;
        for k in 0..NEAR_FIELD_RAYS {
            let d = cosine_spiral(k, t, b, n);
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.dot(n) > 0.0);
            mean += d.dot(n) / NEAR_FIELD_RAYS as f32;
        }
        assert!((mean - 2.0 / 3.0).abs() < 0.01, "{mean}");
    }
}
