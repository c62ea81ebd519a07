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
//!   `sum L(w)` that arrives along the rays that escape. A ray that hits within reach brings
//!   nothing, or with [`RaySettings::near_light`] the relit radiance of the brick it hits
//!   ([`NearLight`]: without it the lit walls of a small room count as dark and the Cornell
//!   room gets worse, 4.05% -> 5.81%). This is a precomputed radiance transfer vector (Sloan et
//!   al., SIGGRAPH 2002) for the far field plus a surface-to-brick gather for the near field,
//!   evaluated here per point and exactly, to measure what a baked one could reach.
//!
//! Both cost rays per lookup (8 and 256, closest hits with the near light), which is why this is a benchmark reference and not the
//! runtime's lookup: `prt-bench surface --lookup rays` measures the upper bound of a baked
//! per-surface-cell visibility mask and transfer vector before either is built. Figures:
//! `docs/results/surface_candidates.md`.

use std::collections::HashMap;

use glam::Vec3;
use prt_bake::merge::key::dominant_axis;
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, Brick, Geometry, BRICK_AXIS_MASK, BRICK_BACKFACE};
use prt_runtime::relight::BrickRadiance;
use prt_runtime::shadow_rays::{closest_hit, occluded, ray_offset};
use prt_runtime::{Sample, VolumeSampler};

/// Where the rays start: this many probe spacings off the surface along its normal (1 cm on a
/// 1 m grid), and never less than the shadow rays' own offset.
pub const RAY_START: f32 = 0.01;

/// Weight kept by a probe the point cannot see: the runtime's surface lookup's (small enough that
/// the visible probes decide, unless their trilinear weights are below 1e-4 of the blocked
/// ones'; nonzero so that a point that sees none of its eight still gets their trilinear mean).
pub use prt_format::surface::BLOCKED_WEIGHT;

/// Hemisphere rays of the near-field term (a Fibonacci spiral, cosine-distributed).
pub const NEAR_FIELD_RAYS: u32 = 256;

/// Where rays from a surface point `p` with unit normal `n` start: [`RAY_START`] spacings along
/// the normal, and never less than the shadow rays' own offset.
pub(crate) fn ray_start(p: Vec3, n: Vec3, spacing: f32) -> Vec3 {
    p + n * (RAY_START * spacing).max(ray_offset(p, spacing))
}

/// Whether a ray from `start` reaches `probe` through `geo` (a probe at `start` is seen).
pub(crate) fn sees(geo: &Geometry, start: Vec3, probe: Vec3) -> bool {
    let d = probe - start;
    let len = d.length();
    !(len > 0.0 && occluded(geo, start, d / len, len))
}

/// What the ray lookup adds to the trilinear one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RaySettings {
    /// Weight each probe by whether a ray from the point reaches it.
    pub visibility: bool,
    /// Reach of the near-field occlusion term in probe spacings; `None` leaves it out.
    /// 0.75 was chosen on the family's tuning seeds (0.5 / 0.75 / 1.0 / 1.5: the best median,
    /// a worst level within 0.3 points of 0.5's, and leaks at 1.7% against 0.5's 4.0%;
    /// `docs/results/surface_candidates.md`).
    pub near_field: Option<f32>,
    /// Rays of the near-field term that hit a surface within reach bring that surface's relit
    /// radiance (its brick's, [`NearLight`]) instead of nothing. Then the reach can be longer:
    /// 1.0 spacing was chosen on the tuning seeds (0.5 / 0.75 / 1.0 / 1.5 / 3.0).
    pub near_light: bool,
}

impl RaySettings {
    /// The near field with its own light, reach 1.0 spacing: the best bound measured.
    pub fn with_near_light() -> Self {
        RaySettings {
            visibility: true,
            near_field: Some(1.0),
            near_light: true,
        }
    }
}

impl Default for RaySettings {
    fn default() -> Self {
        RaySettings {
            visibility: true,
            near_field: Some(0.75),
            near_light: false,
        }
    }
}

/// The relit bricks, found by position: what a near-field ray that hits a surface sees there.
pub struct NearLight {
    radiance: Vec<BrickRadiance>,
    centroids: Vec<Vec3>,
    axes: Vec<u32>,
    /// Back-face bricks of single-sided surfaces (black; [`Self::find`] passes them over).
    backface: Vec<bool>,
    /// Bricks by cell of `size` metres (a brick's extent), each in every cell its bounds touch.
    cells: HashMap<(i32, i32, i32), Vec<u32>>,
    size: f32,
}

impl NearLight {
    /// The bricks of `asset` with their one-bounce radiance `radiance` (one per brick).
    pub fn for_asset(asset: &Asset, radiance: Vec<BrickRadiance>) -> Self {
        let h = &asset.header;
        // A brick spans 4 surfel cells; merging off (cell 0) makes every hit a brick.
        let size = (4.0 * h.settings.merge_distance).max(1e-3 * h.grid.spacing);
        Self::new(&asset.bricks, size, radiance)
    }

    /// `bricks` of about `size` metres with their radiance `radiance` (one per brick).
    pub fn new(bricks: &[Brick], size: f32, radiance: Vec<BrickRadiance>) -> Self {
        let mut cells: HashMap<(i32, i32, i32), Vec<u32>> = Default::default();
        for (i, b) in bricks.iter().enumerate() {
            let lo = (Vec3::from(b.min) / size).floor().as_ivec3();
            let hi = (Vec3::from(b.max) / size).floor().as_ivec3();
            for x in lo.x..=hi.x {
                for y in lo.y..=hi.y {
                    for z in lo.z..=hi.z {
                        cells.entry((x, y, z)).or_default().push(i as u32);
                    }
                }
            }
        }
        NearLight {
            radiance,
            centroids: bricks.iter().map(|b| Vec3::from(b.centroid)).collect(),
            axes: bricks.iter().map(|b| b.flags & BRICK_AXIS_MASK).collect(),
            backface: bricks
                .iter()
                .map(|b| b.flags & BRICK_BACKFACE != 0)
                .collect(),
            cells,
            size,
        }
    }

    /// What a ray from `o` along unit `d` brings from within `reach` through `geo`: the
    /// radiance where it first hits ([`Self::hit_radiance`]), or `None` when it escapes.
    pub fn trace(&self, geo: &Geometry, o: Vec3, d: Vec3, reach: f32) -> Option<[f32; 3]> {
        closest_hit(geo, o, d, reach).map(|(t, tri)| self.hit_radiance(geo, o, d, t, tri))
    }

    /// [`Self::trace`] with the brick that lit the hit (`None` where none was found: black).
    pub fn trace_brick(
        &self,
        geo: &Geometry,
        o: Vec3,
        d: Vec3,
        reach: f32,
    ) -> Option<([f32; 3], Option<u32>)> {
        closest_hit(geo, o, d, reach).map(|(t, tri)| self.hit_brick(geo, o, d, t, tri))
    }

    /// What a ray from `o` along `d` sees where it hits triangle `tri` of `geo` at distance
    /// `t`: the radiance of the nearest brick of the triangle's side that faces the ray.
    fn hit_radiance(&self, geo: &Geometry, o: Vec3, d: Vec3, t: f32, tri: usize) -> [f32; 3] {
        self.hit_brick(geo, o, d, t, tri).0
    }

    /// [`Self::hit_radiance`] and the brick it came from.
    fn hit_brick(
        &self,
        geo: &Geometry,
        o: Vec3,
        d: Vec3,
        t: f32,
        tri: usize,
    ) -> ([f32; 3], Option<u32>) {
        let p = o + d * t;
        let brick = self.find(p, dominant_axis(facing_normal(geo, tri, d)));
        let l = brick.map_or([0.0; 3], |b| {
            self.radiance[b as usize].at((p - self.centroids[b as usize]).to_array())
        });
        (l, brick)
    }

    /// The front-face brick of dominant axis `axis` whose centroid is nearest `p`, among those
    /// in `p`'s cell and its 26 neighbours.
    pub fn find(&self, p: Vec3, axis: u32) -> Option<u32> {
        self.nearest(p, axis, false)
    }

    /// [`Self::find`] among back-face bricks too, and whether the one found is one.
    pub fn find_side(&self, p: Vec3, axis: u32) -> Option<(u32, bool)> {
        self.nearest(p, axis, true)
            .map(|b| (b, self.backface[b as usize]))
    }

    fn nearest(&self, p: Vec3, axis: u32, backface: bool) -> Option<u32> {
        let c = (p / self.size).floor().as_ivec3();
        let mut best: Option<(f32, u32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = self.cells.get(&(c.x + dx, c.y + dy, c.z + dz)) else {
                        continue;
                    };
                    for &b in list {
                        if self.axes[b as usize] != axis || (!backface && self.backface[b as usize])
                        {
                            continue;
                        }
                        let d = self.centroids[b as usize].distance_squared(p);
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, b));
                        }
                    }
                }
            }
        }
        best.map(|(_, b)| b)
    }
}

/// The surfel of brick `brick` of `asset` nearest `p` (none in an empty brick).
pub(crate) fn nearest_surfel(asset: &Asset, brick: u32, p: Vec3) -> Option<&prt_format::Surfel> {
    let b = &asset.bricks[brick as usize];
    let range = b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize;
    let d = |s: &&prt_format::Surfel| Vec3::from(s.position).distance_squared(p);
    asset.surfels[range]
        .iter()
        .min_by(|a, b| d(a).total_cmp(&d(b)))
}

/// The unit geometric normal of triangle `tri` of `geo` on the side a ray along `d` hits.
pub(crate) fn facing_normal(geo: &Geometry, tri: usize, d: Vec3) -> Vec3 {
    let tri = &geo.triangles[tri];
    let (v0, v1, v2) = (Vec3::from(tri.v0), Vec3::from(tri.v1), Vec3::from(tri.v2));
    let normal = (v1 - v0).cross(v2 - v0).normalize_or_zero();
    if normal.dot(d) > 0.0 {
        -normal
    } else {
        normal
    }
}

/// The trilinear lookup (without depth moments) with [`RaySettings`]' ray tests on top.
pub struct RayLookup<'a> {
    sampler: VolumeSampler<'a>,
    near_light: Option<&'a NearLight>,
    geometry: &'a Geometry,
    spacing: f32,
    settings: RaySettings,
}

impl<'a> RayLookup<'a> {
    /// The ray lookup of `asset` relit to `sh`, the point moved `normal_bias` spacings along
    /// its normal for the trilinear weights (`LookupSettings::normal_bias`).
    pub fn for_asset(
        asset: &'a Asset,
        sh: &'a [ShRgb],
        normal_bias: f32,
        settings: RaySettings,
    ) -> Self {
        let g = &asset.header.grid;
        let sampler = VolumeSampler::new(g, &asset.probes, sh, normal_bias * g.spacing);
        Self::new(sampler, &asset.geometry, g.spacing, settings)
    }

    /// The ray tests on top of `sampler` (a grid of `spacing` metres), tracing through
    /// `geometry`.
    pub fn new(
        sampler: VolumeSampler<'a>,
        geometry: &'a Geometry,
        spacing: f32,
        settings: RaySettings,
    ) -> Self {
        RayLookup {
            sampler,
            near_light: None,
            geometry,
            spacing,
            settings,
        }
    }

    /// Near-field rays that hit read `near`'s radiance (with [`RaySettings::near_light`]).
    pub fn with_near_light(mut self, near: &'a NearLight) -> Self {
        self.near_light = Some(near);
        self
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let n = Vec3::from(normal);
        let p = Vec3::from(position);
        let start = ray_start(p, n, self.spacing);
        let mut s = if self.settings.visibility {
            self.sampler.sample_weighted(position, normal, |_, probe| {
                if sees(self.geometry, start, probe) {
                    1.0
                } else {
                    BLOCKED_WEIGHT
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
        let near = self.near_light.filter(|_| self.settings.near_light);
        let (mut open, mut all) = ([0.0f32; 3], [0.0f32; 3]);
        for k in 0..NEAR_FIELD_RAYS {
            let d = cosine_spiral(k, t, b, n);
            let y = prt_format::sh::basis(d.to_array());
            // None: the ray escapes within reach; else what it brings from the near field.
            let blocked = match near {
                Some(light) => light.trace(self.geometry, start, d, reach),
                None => occluded(self.geometry, start, d, reach).then_some([0.0; 3]),
            };
            for ch in 0..3 {
                let l = (0..SH_COUNT)
                    .map(|i| sh[i][ch] * y[i])
                    .sum::<f32>()
                    .max(0.0);
                all[ch] += l;
                open[ch] += blocked.map_or(l, |r| r[ch]);
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

/// Direction `k` of [`NEAR_FIELD_RAYS`] cosine-distributed ones about `n` (tangents `t`, `b`):
/// the bake's spiral (`prt_bake::surface_terms::cosine_spiral`) at this lookup's ray count.
pub(crate) fn cosine_spiral(k: u32, t: Vec3, b: Vec3, n: Vec3) -> Vec3 {
    prt_bake::surface_terms::cosine_spiral(k, NEAR_FIELD_RAYS, t, b, n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use prt_format::{BvhNode, Grid, Probe, Triangle, PROBE_VALID};

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
        let (grid, probes, geometry) = parts;
        // The runtime's default bias, 0.2 spacings (0.4 m here).
        let sampler = VolumeSampler::new(grid, probes, sh, 0.2 * grid.spacing);
        RayLookup::new(sampler, geometry, grid.spacing, settings)
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
            near_light: false,
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
    /// wall, and none with a reach short of it; with the near light it gets the wall's instead.
    #[test]
    fn the_near_field_term_darkens_only_within_its_reach() {
        let sh = lit_and_dark();
        let walled = two_probes(true);
        let facing_wall = [1.0, 0.0, 0.0];
        let at = [0.8, 0.0, 0.0];
        // The wall's side facing the point (-X, axis 1) as one brick of radiance 2.
        let brick = Brick {
            min: [1.0, -5.0, -5.0],
            max: [1.0, 5.0, 5.0],
            centroid: [1.0, 0.0, 0.0],
            flags: 1,
            ..Brick::default()
        };
        let lit = BrickRadiance {
            mean: [2.0; 3],
            ..BrickRadiance::default()
        };
        let near = NearLight::new(&[brick], 1.0, vec![lit]);
        let sample = |reach, near_light| {
            let settings = RaySettings {
                visibility: false,
                near_field: Some(reach),
                near_light,
            };
            let rays = lookup(&walled, &sh, settings).with_near_light(&near);
            rays.sample(at, facing_wall).irradiance[0]
        };
        let plain = VolumeSampler::new(&walled.0, &walled.1, &sh, 0.4).sample(at, facing_wall);
        let plain = plain.irradiance[0];
        assert_eq!(sample(0.05, false), plain);
        assert!(sample(0.75, false) < 0.05 * plain);
        // With its light the wall, brighter than the probes' uniform radiance, brightens.
        assert!(
            sample(0.75, true) > 3.0 * plain,
            "{} {plain}",
            sample(0.75, true)
        );
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
