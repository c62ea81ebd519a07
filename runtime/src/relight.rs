//! The CPU relight: the straightforward, parallel reference every GPU kernel is checked against.
//!
//! 1. **Direct light at surfels.** Per brick: cull each light by range, cone and facing
//!    ([`PreparedLight::cull`]); for the lights left, every surfel gets the irradiance of
//!    docs/conventions.md section 3, with a shadow ray through the asset's BVH
//!    ([`crate::shadow_rays`]). Back-face bricks are black and skipped.
//! 2. **Surfel radiance** `L = emission + albedo / pi * E`, kept as the GPU keeps it
//!    ([`crate::radiance_word`]: a word for packed surfels, f32 for the exact preset's).
//! 3. **Brick radiance**: the weighted mean of its surfels'.
//! 4. **Gather**: probe SH9 = sum over its factors of transfer x brick radiance, plus the sky
//!    term. Invalid probes are skipped (zero, flagged invalid); then the grid points a sparse
//!    bake left to the coarse levels are filled from it ([`crate::fill`]).
//! 5. **Bounces** (optional, `bounces > 1`): surfels also receive the irradiance of the probe
//!    volume from the previous iteration, sampled at the surfel with its normal through the
//!    engine's lookup (`sample_irradiance`: the surface lookup at its surface bias where the
//!    surfel has terms, else the normal bias, validity and depth-moment weights), and
//!    steps 2-4 repeat. `bounces = 1` is the one-bounce contract of
//!    docs/conventions.md section 5, exactly when the bake did not merge surfels and kept them
//!    in f32 (the exact preset).

use glam::Vec3;
use prt_format::coarse::{symmetric_times, CoarseBrick};
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, BRICK_BACKFACE};
use rayon::prelude::*;

use crate::contract::MAX_STACK;
use crate::lights::{
    brick_normal_bounds, surfel_spread_sq, CullReason, NormalBounds, PreparedLight,
};
use crate::radiance_word::kept_radiance;
use crate::rig::Lighting;
use crate::settings::{LookupSettings, MAX_BOUNCES};
use crate::shadow_rays::lit;
use crate::surface::SurfaceSampler;

/// Why an asset cannot be relit.
#[derive(Debug, thiserror::Error)]
pub enum RelightError {
    #[error("the asset's BVH needs a traversal stack of {needed} entries, more than {max}")]
    BvhTooDeep { needed: usize, max: usize },
    #[error("bounces must be in 1..={MAX_BOUNCES}, got {0}")]
    Bounces(u32),
    #[error("{count} lights: the CPU relight takes at most {MAX_CPU_LIGHTS} (its cost is lights x surfels)")]
    TooManyLights { count: usize },
    #[error("the relit SH of probe {probe} is not finite: the light intensities (up to {max_intensity:e}) overflow f32")]
    NonFinite { probe: usize, max_intensity: f32 },
}

/// Fails on the first probe whose relit SH is not finite (intensities that overflow f32), for
/// every backend's result before it is written anywhere.
pub fn check_finite(sh: &[ShRgb], lighting: &Lighting) -> Result<(), RelightError> {
    match sh
        .iter()
        .position(|c| c.iter().flatten().any(|v| !v.is_finite()))
    {
        Some(probe) => Err(RelightError::NonFinite {
            probe,
            max_intensity: lighting
                .rig
                .lights
                .iter()
                .map(|l| l.intensity)
                .fold(0.0, f32::max),
        }),
        None => Ok(()),
    }
}

/// Most lights the CPU relight takes (the renderer's own limit): beyond it a relight takes
/// minutes per update on a real level, which is not what a reference is for.
pub const MAX_CPU_LIGHTS: usize = 4096;

/// What a relight did and skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RelightStats {
    pub bricks: u64,
    pub bricks_skipped_backface: u64,
    pub light_brick_pairs: u64,
    pub culled_dark: u64,
    pub culled_range: u64,
    pub culled_cone: u64,
    pub culled_facing: u64,
    pub shadow_rays: u64,
    pub probes_gathered: u64,
    pub probes_skipped_invalid: u64,
}

impl std::ops::Add for RelightStats {
    type Output = RelightStats;
    fn add(self, o: RelightStats) -> RelightStats {
        RelightStats {
            bricks: self.bricks + o.bricks,
            bricks_skipped_backface: self.bricks_skipped_backface + o.bricks_skipped_backface,
            light_brick_pairs: self.light_brick_pairs + o.light_brick_pairs,
            culled_dark: self.culled_dark + o.culled_dark,
            culled_range: self.culled_range + o.culled_range,
            culled_cone: self.culled_cone + o.culled_cone,
            culled_facing: self.culled_facing + o.culled_facing,
            shadow_rays: self.shadow_rays + o.shadow_rays,
            probes_gathered: self.probes_gathered + o.probes_gathered,
            probes_skipped_invalid: self.probes_skipped_invalid + o.probes_skipped_invalid,
        }
    }
}

impl std::fmt::Display for RelightStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "bricks {} ({} back-face skipped) | light-brick pairs {} (culled: dark {}, range {}, cone {}, facing {}) | shadow rays {} | probes gathered {} ({} invalid skipped)",
            self.bricks,
            self.bricks_skipped_backface,
            self.light_brick_pairs,
            self.culled_dark,
            self.culled_range,
            self.culled_cone,
            self.culled_facing,
            self.shadow_rays,
            self.probes_gathered,
            self.probes_skipped_invalid
        )
    }
}

/// A relit probe volume.
#[derive(Clone, Debug)]
pub struct Relit {
    /// SH9 of incident radiance per probe (zero for invalid probes).
    pub sh: Vec<ShRgb>,
    /// Per surfel, the irradiance of the last bounce (direct, plus the volume's beyond the
    /// first).
    pub surfel_irradiance: Vec<[f32; 3]>,
    /// Per surfel, the radiance of the last bounce as the runtime keeps it
    /// ([`CpuRelighter::surfel_radiance`]): what the bricks and the surface lookup's near field
    /// are lit by (`crate::surface`).
    pub surfel_radiance: Vec<[f32; 3]>,
    /// The sky's mean radiance ([`crate::SkyModel::mean_radiance`]): what the surface
    /// lookup's sky term scales.
    pub sky: [f32; 3],
    pub stats: RelightStats,
}

/// CPU relighting of one asset; holds the per-brick data derived once at load.
pub struct CpuRelighter<'a> {
    asset: &'a Asset,
    normal_bounds: Vec<NormalBounds>,
}

impl<'a> CpuRelighter<'a> {
    pub fn new(asset: &'a Asset) -> Result<Self, RelightError> {
        let needed = asset.geometry.stack_needed();
        if needed > MAX_STACK {
            return Err(RelightError::BvhTooDeep {
                needed,
                max: MAX_STACK,
            });
        }
        Ok(CpuRelighter {
            asset,
            normal_bounds: brick_normal_bounds(asset),
        })
    }

    /// Relights with `lighting`; `bounces` >= 1. Bounces beyond the first sample the volume as
    /// the GPU runtime does by default ([`LookupSettings::default`]).
    pub fn relight(&self, lighting: &Lighting, bounces: u32) -> Result<Relit, RelightError> {
        self.relight_with(lighting, bounces, &LookupSettings::default())
    }

    /// [`CpuRelighter::relight`], with bounces beyond the first sampling the volume through
    /// the engine's lookup with `lookup` (`sample_irradiance`, twin
    /// [`SurfaceSampler`]), as the GPU runtime does with the same settings.
    pub fn relight_with(
        &self,
        lighting: &Lighting,
        bounces: u32,
        lookup: &LookupSettings,
    ) -> Result<Relit, RelightError> {
        if bounces == 0 || bounces > MAX_BOUNCES {
            return Err(RelightError::Bounces(bounces));
        }
        if lighting.rig.lights.len() > MAX_CPU_LIGHTS {
            return Err(RelightError::TooManyLights {
                count: lighting.rig.lights.len(),
            });
        }
        let lights: Vec<PreparedLight> =
            lighting.rig.lights.iter().map(PreparedLight::new).collect();
        let (direct, mut stats) = self.direct_irradiance(&lights);
        let lattice = lighting.sky.lattice(self.asset.header.ray_count);
        let sky_mean = lighting.sky.mean_radiance(&lattice);
        let sky: Vec<ShRgb> = (0..self.asset.probes.len())
            .into_par_iter()
            .map(|p| lighting.sky.probe_sky(self.asset, p, &lattice))
            .collect();
        let (mut sh, mut surfel_irradiance) = (Vec::new(), Vec::new());
        let mut surfel_radiance = Vec::new();
        for bounce in 0..bounces {
            let (irradiance, radiance) = if bounce == 0 {
                (direct.clone(), self.surfel_radiance(&direct, None))
            } else {
                // The previous bounce's light at the surfel, through the engine's lookup.
                let volume =
                    SurfaceSampler::new(self.asset, &sh, &surfel_radiance, sky_mean, lookup);
                let volume: Vec<[f32; 3]> = (self.asset.surfels.par_iter())
                    .map(|s| volume.sample(s.position, s.normal).irradiance)
                    .collect();
                let total = direct.iter().zip(&volume);
                (
                    total
                        .map(|(e, v)| std::array::from_fn(|c| e[c] + v[c]))
                        .collect(),
                    self.surfel_radiance(&direct, Some(&volume)),
                )
            };
            let (g, gather_stats) = self.gather(&self.brick_radiance(&radiance), &sky);
            sh = g;
            (surfel_irradiance, surfel_radiance) = (irradiance, radiance);
            if bounce + 1 == bounces {
                stats = stats + gather_stats;
            }
        }
        check_finite(&sh, lighting)?;
        Ok(Relit {
            sh,
            surfel_irradiance,
            surfel_radiance,
            sky: sky_mean,
            stats,
        })
    }

    /// Step 1: direct irradiance at every surfel (zero on back-face bricks).
    pub fn direct_irradiance(&self, lights: &[PreparedLight]) -> (Vec<[f32; 3]>, RelightStats) {
        let asset = self.asset;
        let spread_sq = surfel_spread_sq(asset.header.settings.cell_size);
        let spacing = asset.header.grid.spacing;
        let per_brick: Vec<(Vec<[f32; 3]>, RelightStats)> = asset
            .bricks
            .par_iter()
            .zip(&self.normal_bounds)
            .map(|(brick, nb)| {
                let surfels = &asset.surfels[brick.first_surfel as usize
                    ..(brick.first_surfel + brick.surfel_count) as usize];
                let mut e = vec![[0.0f32; 3]; surfels.len()];
                let mut st = RelightStats {
                    bricks: 1,
                    ..RelightStats::default()
                };
                if brick.flags & BRICK_BACKFACE != 0 {
                    st.bricks_skipped_backface = 1;
                    return (e, st);
                }
                for light in lights {
                    st.light_brick_pairs += 1;
                    match light.cull(brick, nb) {
                        Some(CullReason::Dark) => st.culled_dark += 1,
                        Some(CullReason::Range) => st.culled_range += 1,
                        Some(CullReason::Cone) => st.culled_cone += 1,
                        Some(CullReason::Facing) => st.culled_facing += 1,
                        None => {
                            for (s, out) in surfels.iter().zip(e.iter_mut()) {
                                let p = Vec3::from(s.position);
                                let n = Vec3::from(s.normal);
                                let (el, l, dist) = light.irradiance_over(p, n, spread_sq);
                                if el.max_element() <= 0.0 {
                                    continue;
                                }
                                st.shadow_rays += 1;
                                let at = dist.is_finite().then_some(light.position);
                                if lit(&asset.geometry, p, n, spacing, l, at) {
                                    for c in 0..3 {
                                        out[c] += el[c];
                                    }
                                }
                            }
                        }
                    }
                }
                (e, st)
            })
            .collect();
        let mut stats = RelightStats::default();
        let mut out = Vec::with_capacity(asset.surfels.len());
        for (e, st) in per_brick {
            out.extend(e);
            stats = stats + st;
        }
        (out, stats)
    }

    /// Step 2: per surfel, its radiance as the GPU runtime keeps it: the direct radiance
    /// `emission + albedo / pi * E` from the direct irradiance `direct`, plus with bounces the
    /// bounce radiance `albedo / pi * E` from the volume's irradiance `bounce`, each kept as the
    /// asset's surfel precision says ([`crate::radiance_word`]: a radiance word for packed
    /// surfels) and summed as stage 4 does.
    pub fn surfel_radiance(
        &self,
        direct: &[[f32; 3]],
        bounce: Option<&[[f32; 3]]>,
    ) -> Vec<[f32; 3]> {
        let surfels = &self.asset.surfels;
        let precision = self.asset.header.settings.surfel_precision;
        (surfels.par_iter().enumerate())
            .map(|(i, s)| {
                let e = direct[i];
                let mut l = kept_radiance(
                    std::array::from_fn(|c| {
                        s.emission[c] + s.albedo[c] * std::f32::consts::FRAC_1_PI * e[c]
                    }),
                    precision,
                );
                if let Some(b) = bounce {
                    let more = kept_radiance(
                        std::array::from_fn(|c| {
                            s.albedo[c] * std::f32::consts::FRAC_1_PI * b[i][c]
                        }),
                        precision,
                    );
                    l = std::array::from_fn(|c| l[c] + more[c]);
                }
                l
            })
            .collect()
    }

    /// Step 3: brick radiance (mean and gradient) from surfel radiance `radiance`
    /// ([`Self::surfel_radiance`]), then the coarse bricks' from their bricks'
    /// ([`coarse_radiance`]), after them.
    pub fn brick_radiance(&self, radiance: &[[f32; 3]]) -> Vec<BrickRadiance> {
        let mut radiance = self.fine_radiance(radiance);
        let coarse = &self.asset.coarse;
        let fine = &radiance[..];
        let far: Vec<BrickRadiance> = (coarse.bricks.par_iter())
            .map(|c| coarse_radiance(self.asset, c, fine))
            .collect();
        radiance.extend(far);
        radiance
    }

    /// Step 3 for the bricks.
    fn fine_radiance(&self, radiance: &[[f32; 3]]) -> Vec<BrickRadiance> {
        let asset = self.asset;
        asset
            .bricks
            .par_iter()
            .map(|b| {
                let mut out = BrickRadiance::default();
                if b.flags & BRICK_BACKFACE != 0 {
                    return out;
                }
                let range = b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize;
                let mut weight = 0.0f32;
                for (s, l) in asset.surfels[range.clone()].iter().zip(&radiance[range]) {
                    for c in 0..3 {
                        out.mean[c] += s.weight * l[c];
                        for a in 0..3 {
                            out.gradient[c][a] += s.gradient[a] * l[c];
                        }
                    }
                    weight += s.weight;
                }
                out.mean = out.mean.map(|v| v / weight);
                out
            })
            .collect()
    }

    /// Step 4: probe SH from brick radiance and the probes' sky terms.
    pub fn gather(
        &self,
        brick_radiance: &[BrickRadiance],
        sky: &[ShRgb],
    ) -> (Vec<ShRgb>, RelightStats) {
        let asset = self.asset;
        let mut sh: Vec<ShRgb> = asset
            .probes
            .par_iter()
            .enumerate()
            .map(|(p, probe)| {
                if !probe.is_valid() {
                    return [[0.0; 3]; SH_COUNT];
                }
                // Accumulated in f64: the reference every GPU gather is measured against must not
                // drift itself over 100,000 factors (`tests/tests/sums.rs`).
                let mut acc = sky[p].map(|c| c.map(f64::from));
                for f in probe.first_factor..probe.first_factor + probe.factor_count {
                    let (brick, rays) = asset.factors.brick_and_rays(f as usize);
                    if rays == 0 {
                        // A continuation slot (`prt_format::FactorSlot`): its head read it.
                        continue;
                    }
                    let t = asset.factor_transfer(probe, f as usize);
                    let l = brick_radiance[brick as usize].at(asset.factors.offset(f as usize));
                    for k in 0..SH_COUNT {
                        for c in 0..3 {
                            acc[k][c] += f64::from(t[k]) * f64::from(l[c]);
                        }
                    }
                }
                acc.map(|c| c.map(|v| v as f32))
            })
            .collect();
        crate::fill::fill(asset, &mut sh);
        let valid = asset.probes.iter().filter(|p| p.is_valid()).count() as u64;
        let stats = RelightStats {
            probes_gathered: valid,
            probes_skipped_invalid: asset.probes.len() as u64 - valid,
            ..RelightStats::default()
        };
        (sh, stats)
    }
}

/// A coarse brick's linear model from its bricks' (`prt_format::coarse`): their weighted mean,
/// and the gradient `M^-1 sum_c (M_c G_c + W_c (mu_c - mu) m_c)` (the stored inverse carries
/// the `2^level` of its factors' offsets).
pub fn coarse_radiance(asset: &Asset, c: &CoarseBrick, fine: &[BrickRadiance]) -> BrickRadiance {
    let mut mean = [0.0f32; 3];
    let mut b = [[0.0f32; 3]; 3];
    let run = c.first_child as usize..(c.first_child + c.child_count) as usize;
    for &child in &asset.coarse.children[run] {
        let (r, m) = (&fine[child as usize], &asset.coarse.moments[child as usize]);
        let mu = asset.bricks[child as usize].centroid;
        let d = std::array::from_fn::<f32, 3, _>(|a| mu[a] - c.centroid[a]);
        for ch in 0..3 {
            let mg = symmetric_times(&m.moment, r.gradient[ch]);
            mean[ch] += m.weight * r.mean[ch];
            for a in 0..3 {
                b[ch][a] += mg[a] + m.weight * d[a] * r.mean[ch];
            }
        }
    }
    BrickRadiance {
        mean: mean.map(|v| v / c.weight),
        gradient: b.map(|bc| symmetric_times(&c.inverse, bc)),
    }
}

/// A brick's linear radiance model: `max(0, mean + gradient . offset)` per channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BrickRadiance {
    pub mean: [f32; 3],
    /// Per colour channel, the radiance gradient (per metre).
    pub gradient: [[f32; 3]; 3],
}

impl BrickRadiance {
    /// Radiance at `offset` from the brick's centroid, clamped at 0.
    #[inline]
    pub fn at(&self, offset: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|c| {
            let g = self.gradient[c];
            (self.mean[c] + g[0] * offset[0] + g[1] * offset[1] + g[2] * offset[2]).max(0.0)
        })
    }
}
