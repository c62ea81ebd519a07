//! # Sampling the probe volume at surface points: the CPU twin of the engine-side snippet
//!
//! Engines shade with `sample_irradiance(world_pos, normal)` from
//! `shaders/sample_irradiance.wgsl`: one hardware trilinear fetch per volume texture, whose texels
//! hold each probe's SH premultiplied by its validity (0 or 1), so the filter weights the eight
//! surrounding probes by validity, and dividing by the filtered validity renormalises.
//! [`VolumeSampler`] does exactly that on the CPU, from the probes' SH, so that `prt sample`
//! answers "what does the engine see here" without a GPU and every GPU result has a reference:
//!
//! - the point is first moved along its normal by `normal_bias` metres
//!   (`RuntimeSettings::normal_bias`, in probe spacings, explains the trade-off);
//! - texel coordinate `(p - origin) / spacing` (texel centres sit on the probes), clamp-to-edge:
//!   outside the grid the nearest face's probes are used, as the sampler's `ClampToEdge` does;
//! - trilinear weights times validity, summed; SH = weighted sum / summed weight, zero when the
//!   summed weight is at most 1e-6 (no valid probe around the point, where the shader returns 0);
//! - irradiance = `prt_format::sh::irradiance` (clamped-cosine convolution, clamped at 0).
//!
//! The GPU differs only by the volume's storage (half floats by default) and the hardware's
//! filter weights (8-bit fixed-point fractions on most GPUs); `tests/tests/gpu.rs` states the
//! tolerance.

use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{Grid, Probe};

/// What the engine-side snippet returns at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Interpolated SH of incident radiance (conventions.md section 2), zero where no valid probe
    /// surrounds the point.
    pub sh: ShRgb,
    /// Irradiance E on a surface with the sample's normal (clamped at 0).
    pub irradiance: [f32; 3],
    /// Summed trilinear weight of the valid probes around the point (1 = all eight valid).
    pub validity: f32,
}

/// Summed validity at or below which the sample is empty (as in the shader).
pub const MIN_VALIDITY: f32 = 1e-6;

/// Samples probe SH like the GPU's trilinear, validity-weighted fetch.
#[derive(Clone, Debug)]
pub struct VolumeSampler<'a> {
    grid: Grid,
    validity: Vec<f32>,
    sh: &'a [ShRgb],
    normal_bias: f32,
}

impl<'a> VolumeSampler<'a> {
    /// A sampler over `sh` (one per probe, in `grid` index order) with each probe's validity
    /// taken from `probes`; `normal_bias` is in metres. Probes missing from `probes` or `sh`
    /// count as invalid.
    pub fn new(grid: &Grid, probes: &[Probe], sh: &'a [ShRgb], normal_bias: f32) -> Self {
        let count = usize::try_from(grid.probe_count()).unwrap_or(usize::MAX);
        let validity = (0..count.min(probes.len()).min(sh.len()))
            .map(|i| if probes[i].is_valid() { 1.0 } else { 0.0 })
            .collect();
        VolumeSampler {
            grid: *grid,
            validity,
            sh,
            normal_bias,
        }
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        let g = &self.grid;
        // Per axis: the two clamped probe indices and the weight of the upper one.
        let axes: [(u32, u32, f32); 3] = std::array::from_fn(|a| {
            let p = position[a] + normal[a] * self.normal_bias;
            let t = (p - g.origin[a]) / g.spacing;
            let last = g.counts[a].saturating_sub(1) as f32;
            let lo = t.floor();
            let frac = t - lo;
            let clamp = |v: f32| v.clamp(0.0, last) as u32;
            (clamp(lo), clamp(lo + 1.0), frac)
        });
        let mut sum = [[0.0f32; 3]; SH_COUNT];
        let mut weight = 0.0f32;
        for corner in 0..8 {
            let mut w = 1.0f32;
            let mut ijk = [0u32; 3];
            for (a, &(lo, hi, frac)) in axes.iter().enumerate() {
                let upper = corner >> a & 1 == 1;
                ijk[a] = if upper { hi } else { lo };
                w *= if upper { frac } else { 1.0 - frac };
            }
            let i = g.index(ijk[0], ijk[1], ijk[2]);
            let w = w * self.validity.get(i).copied().unwrap_or(0.0);
            if w == 0.0 {
                continue;
            }
            weight += w;
            for k in 0..SH_COUNT {
                for ch in 0..3 {
                    sum[k][ch] += w * self.sh[i][k][ch];
                }
            }
        }
        if weight <= MIN_VALIDITY {
            return Sample {
                validity: weight,
                ..Sample::default()
            };
        }
        let sh = sum.map(|c| c.map(|v| v / weight));
        Sample {
            sh,
            irradiance: prt_format::sh::irradiance(&sh, normal),
            validity: weight,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prt_format::PROBE_VALID;

    /// A 2x1x1 grid (spacing 2) whose probes have constant SH `a` and `b`.
    fn two_probes(valid: [bool; 2]) -> (Grid, Vec<Probe>, Vec<ShRgb>) {
        let grid = Grid {
            origin: [1.0, 0.0, 0.0],
            spacing: 2.0,
            counts: [2, 1, 1],
        };
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
