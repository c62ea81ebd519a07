//! # Surface gathers: what a baked per-surface irradiance table would give (issue 31)
//!
//! `gather` and `surfel_gather` (`prt-bench surface --lookup gather,surfel_gather`) measure a
//! design the runtime does not have: instead of interpolating probes a spacing away, the bake
//! would trace from the surface itself and keep, per *near group* (the surfels of one brick
//! that see the same probes, `prt_format::surface`) or per surfel, a table of the bricks its
//! rays hit, as the probes' factor tables are kept; the runtime would sum the relit bricks
//! over it, as it gathers a probe. No probe's parallax (the probes half a spacing in front of
//! a gallery wall see more of the sunlit court than the wall does), no interpolation across a
//! light's hotspot.
//!
//! Here the gather is traced at lookup time, once per group or surfel (cached): cosine rays
//! (the near field's spiral) about the group's mean surfel normal from its weighted centroid
//! (or the surfel's own), each hit bringing the relit radiance of the brick it hits at the hit
//! (its linear model, as a factor's stored point reads it: [`NearLight::trace_brick`]), each
//! escape the sky's; the irradiance is pi / N times their sum, the same for every point of
//! the group. A point with no surfel gets the runtime's lookup. It also counts the distinct
//! bricks each gather hit: the entries a baked table would hold (before any coarse level),
//! from which [`GatherLookup::note`] estimates its bytes.

use std::collections::{HashMap, HashSet};
use std::sync::Mutex;

use glam::Vec3;
use prt_format::Asset;
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{Sample, SkyModel};

use crate::ray_lookup::{ray_start, NearLight};

/// Rays per gather by default (`--path-rays` sets it): about what the near field traces from a
/// group's surfels (64 each).
pub const GATHER_RAYS: u32 = 512;

/// Bytes of one table entry a bake would keep: a brick and a ray count (32 bits) and the
/// stored point's offsets, as a u8 factor slot.
pub const ENTRY_BYTES: f64 = 8.0;

/// The gather lookup over one bake and one rig.
pub struct GatherLookup<'a> {
    asset: &'a Asset,
    surface: SurfaceSampler<'a>,
    bricks: &'a NearLight,
    sky: &'a SkyModel,
    rays: u32,
    per_surfel: bool,
    /// Gathers done, by group or surfel, with the distinct bricks each hit (two threads may
    /// gather the same one at once: the same result, kept once).
    done: Mutex<HashMap<usize, (Sample, usize)>>,
}

impl<'a> GatherLookup<'a> {
    /// `surface` finds a point's surfel (and samples where it has none); `bricks` are the
    /// relit bricks; one gather per near group, or per surfel with `per_surfel`.
    pub fn new(
        asset: &'a Asset,
        surface: SurfaceSampler<'a>,
        (bricks, sky): (&'a NearLight, &'a SkyModel),
        rays: u32,
        per_surfel: bool,
    ) -> Self {
        GatherLookup {
            asset,
            surface,
            bricks,
            sky,
            rays,
            per_surfel,
            done: Mutex::default(),
        }
    }

    /// The irradiance at `position` on a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let Some((brick, surfel)) = self.surface.surfel_of(position, normal) else {
            return self.surface.sample(position, normal);
        };
        let terms = &self.asset.surface;
        let group = (terms.groups[brick] + terms.surfels[surfel].group()) as usize;
        let key = if self.per_surfel { surfel } else { group };
        if let Some(&(s, _)) = self.done.lock().expect("gather cache").get(&key) {
            return s;
        }
        let members = match self.per_surfel {
            true => surfel..surfel + 1,
            false => {
                let [first, count] = terms.group_surfels[group];
                first as usize..(first + count) as usize
            }
        };
        let (mut at, mut n, mut w) = (Vec3::ZERO, Vec3::ZERO, 0.0);
        for s in &self.asset.surfels[members] {
            at += Vec3::from(s.position) * s.weight;
            n += Vec3::from(s.normal) * s.weight;
            w += s.weight;
        }
        let (at, n) = (at / w, n.try_normalize().unwrap_or(Vec3::from(normal)));
        let gathered = self.gather(at, n);
        self.done
            .lock()
            .expect("gather cache")
            .insert(key, gathered);
        gathered.0
    }

    /// Cosine rays about `n` from `at`: hits take their brick's relit radiance, escapes the
    /// sky's; and how many distinct bricks they hit.
    fn gather(&self, at: Vec3, n: Vec3) -> (Sample, usize) {
        let geo = &self.asset.geometry;
        let start = ray_start(at, n, self.asset.header.grid.spacing);
        let (t, b) = n.any_orthonormal_pair();
        let mut sum = Vec3::ZERO;
        let mut hit = HashSet::new();
        for k in 0..self.rays {
            let d = prt_bake::surface_terms::cosine_spiral(k, self.rays, t, b, n);
            sum += match self.bricks.trace_brick(geo, start, d, f32::MAX) {
                Some((l, brick)) => {
                    hit.extend(brick);
                    Vec3::from(l)
                }
                None => Vec3::from(self.sky.radiance(d.to_array())),
            };
        }
        let sample = Sample {
            irradiance: (sum * std::f32::consts::PI / self.rays as f32).to_array(),
            validity: 1.0,
            ..Sample::default()
        };
        (sample, hit.len())
    }

    /// The gathers done and what a baked table of every group (or surfel) would take:
    /// the mean distinct bricks per gather times [`ENTRY_BYTES`] times their number.
    pub fn note(&self) -> String {
        let done = self.done.lock().expect("gather cache");
        let mean = done.values().map(|&(_, n)| n).sum::<usize>() as f64 / done.len().max(1) as f64;
        let (what, all) = match self.per_surfel {
            true => ("surfels", self.asset.surface.surfels.len()),
            false => ("near groups", self.asset.surface.group_surfels.len()),
        };
        format!(
            "{} gathers of {} rays, {mean:.1} distinct bricks each: a table of all {all} {what} \
             would be about {:.1} MB",
            done.len(),
            self.rays,
            mean * ENTRY_BYTES * all as f64 / 1e6
        )
    }
}
