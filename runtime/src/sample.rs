//! # Sampling the probe volume at surface points: the CPU twin of the engine-side snippet
//!
//! Engines shade with `sample_irradiance(world_pos, normal)` from
//! `shaders/sample_irradiance.wgsl`. [`VolumeSampler`] computes exactly what it returns, on the
//! CPU, from the probes' SH, so that `prt sample` answers "what does the engine see here" without
//! a GPU and every GPU result has a reference:
//!
//! - the point is first moved along its normal by `normal_bias` metres
//!   (`LookupSettings::normal_bias`, in probe spacings, explains the trade-off);
//! - grid coordinate `(p - origin) / step` (texel centres sit on the probes), clamped to the
//!   grid: outside it the nearest face's probes are used, as the sampler's `ClampToEdge` does;
//! - each of the eight probes around the point gets its trilinear weight times its validity
//!   (`Probe::sample_weight`: 1 for a valid or dilated probe and a grid point filled from the
//!   coarse levels, `prt_format::tier`; 0 for an invalid one), and **with
//!   depth moments** (the runtime's default) also the facing term `clamp(1 + h / FACING_DEPTH,
//!   0, 1)^2 + FACING_FLOOR` (`h`: the probe's signed distance in spacings from the plane
//!   through the unmoved surface point) and the Chebyshev term `max(crush(cheb^3),
//!   MIN_CHEBYSHEV)` of the point's distance against the probe's depth moments in that
//!   direction (the mean and deviation of its hit distances, `prt_format::depth`; Majercik et
//!   al., JCGT 2019); distances are measured from where the probe's rays started
//!   (`Probe::position`: the grid position unless the probe was moved off a surface). A filled
//!   grid point has no depth moments and gets the facing term alone. A
//!   dilated probe sits inside geometry and its map sees that geometry close by, so it only
//!   weighs where no real probe sees the point;
//! - SH = weighted sum / summed weight, zero when the summed trilinear-times-probe weight
//!   (`Sample::validity`) is at most `MIN_VALIDITY` (no probe around the point);
//! - irradiance = `prt_format::sh::irradiance` (clamped-cosine convolution, clamped at 0).
//!
//! The GPU differs only by the volume's storage (half floats by default) and, without depth
//! moments, the hardware's filter weights (8-bit fixed-point fractions on most GPUs);
//! `tests/tests/gpu.rs` states the tolerance.

use glam::Vec3;
use prt_format::depth::MAX_DEPTH;
use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Asset, Grid, Probe, DEPTH_WORDS, NO_SLOT};

use crate::contract::{
    CRUSH_THRESHOLD, FACING_DEPTH, FACING_FLOOR, MIN_CHEBYSHEV, MIN_DISTANCE, MIN_VALIDITY,
    MIN_VARIANCE,
};
use crate::settings::LookupSettings;

/// What the engine-side snippet returns at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Interpolated SH of incident radiance (docs/conventions.md section 2), zero where no probe
    /// surrounds the point.
    pub sh: ShRgb,
    /// Irradiance E on a surface with the sample's normal (clamped at 0).
    pub irradiance: [f32; 3],
    /// Summed trilinear weight times probe weight of the probes around the point (1 = all
    /// eight valid, 0 = none).
    pub validity: f32,
}

/// The eight probes around `p` (world space) and their trilinear weights
/// (`prt_format::Grid::corners`, shared with the bake's sky terms); `prt-bench` counts the
/// probes surfaces read with it.
pub fn corners(grid: &Grid, p: Vec3) -> [(usize, f32); 8] {
    grid.corners(p.to_array())
}

/// DDGI's crush: `v` below the threshold becomes `v^3 / threshold^2` (continuous at it).
fn crush(v: f32) -> f32 {
    if v < CRUSH_THRESHOLD {
        v * v * v / (CRUSH_THRESHOLD * CRUSH_THRESHOLD)
    } else {
        v
    }
}

/// Samples probe SH like the engine-side snippet.
#[derive(Clone, Debug)]
pub struct VolumeSampler<'a> {
    grid: Grid,
    weight: Vec<f32>,
    /// Where each probe's rays started (`Probe::position`).
    positions: Vec<Vec3>,
    /// Where each probe's visibility map sits (`Probe::slot`).
    slots: Vec<u32>,
    sh: &'a [ShRgb],
    /// The probes' depth moments (`Asset::probe_depth`); empty: trilinear only.
    depth_moments: &'a [u32],
    normal_bias: f32,
}

impl<'a> VolumeSampler<'a> {
    /// A trilinear sampler (no depth moments) over `sh` (one per probe, in `grid` index order),
    /// each probe weighted by `Probe::sample_weight`; `normal_bias` is in metres. Probes missing
    /// from `probes` or `sh` count as invalid.
    pub fn new(grid: &Grid, probes: &[Probe], sh: &'a [ShRgb], normal_bias: f32) -> Self {
        let count = usize::try_from(grid.probe_count()).unwrap_or(usize::MAX);
        let n = count.min(probes.len()).min(sh.len());
        let weight = (0..n).map(|i| probes[i].sample_weight()).collect();
        let positions = (0..n).map(|i| Vec3::from(probes[i].position)).collect();
        let slots = (0..n).map(|i| probes[i].slot).collect();
        VolumeSampler {
            grid: *grid,
            weight,
            positions,
            slots,
            sh,
            depth_moments: &[],
            normal_bias,
        }
    }

    /// What the GPU runtime's snippet samples for `asset` relit to `sh` with `lookup`:
    /// weighted by the probes' depth moments unless `lookup.depth_moments` is off.
    pub fn for_asset(asset: &'a Asset, sh: &'a [ShRgb], lookup: &LookupSettings) -> Self {
        let g = &asset.header.grid;
        let s = VolumeSampler::new(g, &asset.probes, sh, lookup.normal_bias * g.spacing);
        if lookup.depth_moments {
            s.with_depth_moments(&asset.probe_depth)
        } else {
            s
        }
    }

    /// Weights probes by their depth moments `depth` (`Asset::probe_depth`, one map per placed
    /// probe in slot order); ignored when it is too short for the probes' slots.
    pub fn with_depth_moments(mut self, depth: &'a [u32]) -> Self {
        let maps = depth.len() / DEPTH_WORDS;
        let fits = self
            .slots
            .iter()
            .zip(&self.weight)
            .all(|(&slot, &w)| w <= 0.0 || slot == NO_SLOT || (slot as usize) < maps);
        if fits && !depth.is_empty() {
            self.depth_moments = depth;
        }
        self
    }

    /// Facing and Chebyshev weight of probe `i` at `probe` for the surface point `surface`
    /// (facing), moved along its normal `n` to `x` (Chebyshev test), as DDGI does.
    fn depth_weight(&self, i: usize, probe: Vec3, surface: Vec3, x: Vec3, n: Vec3) -> f32 {
        let v = x - probe;
        let len = v.length();
        let dist = len / self.grid.spacing;
        if dist <= MIN_DISTANCE {
            return 1.0;
        }
        let dir = v / len;
        let behind =
            ((probe - surface).dot(n) / self.grid.spacing / FACING_DEPTH + 1.0).clamp(0.0, 1.0);
        let mut w = behind * behind + FACING_FLOOR;
        // A filled grid point has no visibility map: its facing term alone.
        if self.slots[i] == NO_SLOT {
            return w;
        }
        let slot = self.slots[i] as usize;
        let words = &self.depth_moments[slot * DEPTH_WORDS..(slot + 1) * DEPTH_WORDS];
        let (mean, deviation) =
            prt_format::depth::moments(words, prt_format::depth::texel_of(dir.to_array()));
        // A saturated mean (`prt_format::depth::TOP`, read as MAX_DEPTH: sky, or hits farther
        // than about 3.7 spacings) bounds nothing: points beyond it, outside the grid, stay
        // visible.
        if dist > mean && mean < MAX_DEPTH {
            let variance = (deviation * deviation).max(MIN_VARIANCE);
            let d = dist - mean;
            let chebyshev = variance / (variance + d * d);
            w *= crush(chebyshev * chebyshev * chebyshev).max(MIN_CHEBYSHEV);
        }
        w
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        self.sample_weighted(position, normal, |_, _| 1.0)
    }

    /// [`Self::sample`] with each probe's weight also multiplied by `extra(index, position)`
    /// (the probe's index in grid order and where its rays started), for reference lookups
    /// that know more than the engine-side snippet: `prt-bench`'s ray lookup multiplies by
    /// the exact visibility of each probe through the asset's BVH. `extra` sees only probes
    /// with a positive trilinear and probe weight.
    pub fn sample_weighted(
        &self,
        position: [f32; 3],
        normal: [f32; 3],
        extra: impl Fn(usize, Vec3) -> f32,
    ) -> Sample {
        let n = Vec3::from(normal);
        let p = Vec3::from(position) + n * self.normal_bias;
        let mut sum = [[0.0f32; 3]; SH_COUNT];
        let (mut validity, mut total) = (0.0f32, 0.0f32);
        for (i, w_tri) in corners(&self.grid, p) {
            let probe_weight = self.weight.get(i).copied().unwrap_or(0.0);
            if w_tri <= 0.0 || probe_weight <= 0.0 {
                continue;
            }
            validity += w_tri * probe_weight;
            let mut w = w_tri;
            if !self.depth_moments.is_empty() {
                w *= self.depth_weight(i, self.positions[i], Vec3::from(position), p, n);
            }
            let w = w * probe_weight * extra(i, self.positions[i]);
            total += w;
            for k in 0..SH_COUNT {
                for ch in 0..3 {
                    sum[k][ch] += w * self.sh[i][k][ch];
                }
            }
        }
        if validity <= MIN_VALIDITY || total <= 0.0 {
            return Sample::default();
        }
        let sh = sum.map(|c| c.map(|v| v / total));
        Sample {
            sh,
            irradiance: prt_format::sh::irradiance(&sh, normal),
            validity,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prt_format::PROBE_VALID;

    /// A 2x1x1 grid (spacing 2) whose probes have constant SH `a` and `b`.
    fn two_probes(valid: [bool; 2]) -> (Grid, Vec<Probe>, Vec<ShRgb>) {
        let grid = Grid::cubic([1.0, 0.0, 0.0], 2.0, [2, 1, 1]);
        let probes = valid
            .iter()
            .enumerate()
            .map(|(i, &v)| Probe {
                position: grid.position(i as u32, 0, 0),
                flags: if v { PROBE_VALID } else { 0 },
                ..Probe::default()
            })
            .collect();
        let mut a = [[0.0f32; 3]; SH_COUNT];
        a[0] = [1.0, 2.0, 3.0];
        a[3] = [0.5, 0.25, 0.125];
        let mut b = [[0.0f32; 3]; SH_COUNT];
        b[0] = [4.0, 5.0, 6.0];
        b[2] = [-1.0, 0.0, 1.0];
        (grid, probes, vec![a, b])
    }

    const UP: [f32; 3] = [0.0, 1.0, 0.0];

    #[test]
    fn a_probe_centre_gives_that_probe() {
        let (grid, probes, sh) = two_probes([true, true]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        for i in 0..2 {
            let got = s.sample(grid.position(i, 0, 0), UP);
            assert_eq!(got.sh, sh[i as usize]);
            assert_eq!(got.validity, 1.0);
            assert_eq!(
                got.irradiance,
                prt_format::sh::irradiance(&sh[i as usize], UP)
            );
        }
        // Halfway: the mean of both, full validity.
        let mid = s.sample([2.0, 0.0, 0.0], UP);
        assert_eq!(mid.validity, 1.0);
        assert!((mid.sh[0][0] - 2.5).abs() < 1e-6);
    }

    #[test]
    fn midway_to_an_invalid_probe_gives_the_valid_one() {
        let (grid, probes, sh) = two_probes([true, false]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        let got = s.sample([2.0, 0.0, 0.0], UP);
        assert_eq!(got.validity, 0.5);
        assert_eq!(got.sh, sh[0]);
    }

    /// An extra weight of zero drops a probe as its invalidity would, but keeps the validity.
    #[test]
    fn an_extra_weight_scales_each_probe() {
        let (grid, probes, sh) = two_probes([true, true]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        let got = s.sample_weighted([2.0, 0.0, 0.0], UP, |i, at| {
            assert_eq!(at, Vec3::from(grid.position(i as u32, 0, 0)));
            if i == 1 {
                0.0
            } else {
                1.0
            }
        });
        assert_eq!(got.sh, sh[0]);
        assert_eq!(got.validity, 1.0);
    }

    #[test]
    fn all_invalid_gives_nothing() {
        let (grid, probes, sh) = two_probes([false, false]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        let got = s.sample([1.7, 0.0, 0.0], UP);
        assert_eq!(got, Sample::default());
    }

    #[test]
    fn outside_the_grid_clamps_to_the_edge() {
        let (grid, probes, sh) = two_probes([true, true]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        assert_eq!(s.sample([-5.0, 3.0, -2.0], UP).sh, sh[0]);
        assert_eq!(s.sample([9.0, 0.0, 2.0], UP).sh, sh[1]);
    }

    /// The bias moves the point along the normal: from the first probe, a bias of one spacing
    /// along +x lands on the second probe, along -x it clamps to the first.
    #[test]
    fn the_bias_moves_the_point_along_the_normal() {
        let (grid, probes, sh) = two_probes([true, true]);
        let s = VolumeSampler::new(&grid, &probes, &sh, 2.0);
        let at = grid.position(0, 0, 0);
        assert_eq!(s.sample(at, [1.0, 0.0, 0.0]).sh, sh[1]);
        assert_eq!(s.sample(at, [-1.0, 0.0, 0.0]).sh, sh[0]);
        let quarter = VolumeSampler::new(&grid, &probes, &sh, 0.5);
        let got = quarter.sample(at, [1.0, 0.0, 0.0]);
        assert!((got.sh[0][0] - (0.75 * 1.0 + 0.25 * 4.0)).abs() < 1e-6);
        // Unbiased, the same point is the first probe whatever the normal.
        let none = VolumeSampler::new(&grid, &probes, &sh, 0.0);
        assert_eq!(none.sample(at, [1.0, 0.0, 0.0]).sh, sh[0]);
    }
}
