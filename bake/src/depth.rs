//! Probe visibility maps (`prt_format::depth`): per probe, per octahedral texel, the mean and
//! standard deviation of its rays' hit distances in probe spacings, each ray weighted by
//! `max(0, cos)^64` of its angle to the texel's centre direction (the filtering of DDGI,
//! Majercik et al. 2019, over the bake's own rays instead of new ones). Sky rays count as
//! `prt_format::depth::MAX_DEPTH`.
//!
//! Every probe shoots the same lattice, so which rays feed which texel, and with what weight, is
//! computed once per bake ([`DepthFilter`]); a probe then costs a few multiply-adds per texel.

use glam::Vec3;
use prt_format::depth::{pack_texels, quantise, texel_direction, MAX_DEPTH};
use prt_format::{DEPTH_TEXELS, DEPTH_WORDS};

use crate::trace::ProbeRays;

/// The texel filter is `cos^(2^SHARPNESS_SQUARINGS)`: cos^64 halves the weight 8.4 degrees off
/// the texel's centre, about the half-width of a 16x16 octahedral texel, so each texel averages
/// the few lattice rays around it (512 rays are about 9 degrees apart).
const SHARPNESS_SQUARINGS: u32 = 6;
/// Rays farther than this from a texel's centre (weight below 1e-4) are skipped.
const MIN_COS: f32 = 0.866;

/// Texels filtered together: their sums are independent, so interleaving them keeps the
/// floating-point adders busy instead of waiting on one texel's chain of additions.
const GROUP: usize = 4;
const _: () = assert!(DEPTH_TEXELS.is_multiple_of(GROUP));

/// Per texel, the lattice rays that feed it and their filter weights, padded with weight-0
/// feeds to the same count for every texel (adding `0 * d` to a sum leaves it as it is, bit for
/// bit: every distance is finite), laid out group by group, feed by feed, texel by texel, so
/// that groups of texels are filtered side by side in SIMD lanes. The padding and the f64
/// weights cost memory that grows with the ray count: 12 bytes a feed, about 34 feeds a texel
/// per 512 rays.
pub struct DepthFilter {
    /// Feeds per texel, padding included.
    feeds: usize,
    rays: Vec<u32>,
    weights: Vec<f64>,
    /// Per texel, the sum of its feeds' weights, added in the order [`DepthFilter::map`] adds
    /// the weighted distances: every probe has the same, since sky rays count too.
    weight_sums: Vec<f64>,
}

impl DepthFilter {
    /// The filter of the lattice `directions`.
    pub fn new(directions: &[Vec3]) -> DepthFilter {
        let texels: Vec<Vec<(u32, f64)>> = (0..DEPTH_TEXELS)
            .map(|t| {
                let centre = Vec3::from(texel_direction(t));
                directions
                    .iter()
                    .enumerate()
                    .filter_map(|(i, dir)| {
                        let mut w = centre.dot(*dir);
                        if w < MIN_COS {
                            return None;
                        }
                        for _ in 0..SHARPNESS_SQUARINGS {
                            w *= w;
                        }
                        Some((i as u32, f64::from(w)))
                    })
                    .collect()
            })
            .collect();
        let feeds = texels.iter().map(Vec::len).max().unwrap_or(0);
        let mut filter = DepthFilter {
            feeds,
            rays: Vec::with_capacity(DEPTH_TEXELS * feeds),
            weights: Vec::with_capacity(DEPTH_TEXELS * feeds),
            weight_sums: vec![0.0; DEPTH_TEXELS],
        };
        for (g, group) in texels.chunks(GROUP).enumerate() {
            for f in 0..feeds {
                for (l, texel) in group.iter().enumerate() {
                    let (ray, w) = texel.get(f).copied().unwrap_or((0, 0.0));
                    filter.rays.push(ray);
                    filter.weights.push(w);
                    filter.weight_sums[g * GROUP + l] += w;
                }
            }
        }
        filter
    }

    /// The packed visibility map of one probe at `origin` (`ray_count` lattice rays).
    pub fn map(
        &self,
        origin: Vec3,
        rays: &ProbeRays,
        ray_count: usize,
        spacing: f32,
    ) -> [u32; DEPTH_WORDS] {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.map_avx(origin, rays, ray_count, spacing) };
        }
        self.map_in(origin, rays, ray_count, spacing)
    }

    /// [`DepthFilter::map`] compiled for AVX: a group's four f64 sums in one vector instead of
    /// two SSE2 ones. The same bits (the same IEEE operations lane for lane; Rust never fuses a
    /// multiply and an add). AVX2's gathers, which could load the distances, gained nothing more.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn map_avx(
        &self,
        origin: Vec3,
        rays: &ProbeRays,
        ray_count: usize,
        spacing: f32,
    ) -> [u32; DEPTH_WORDS] {
        self.map_in(origin, rays, ray_count, spacing)
    }

    /// The body of [`DepthFilter::map`], inlined into each instruction set's copy.
    #[inline(always)]
    fn map_in(
        &self,
        origin: Vec3,
        rays: &ProbeRays,
        ray_count: usize,
        spacing: f32,
    ) -> [u32; DEPTH_WORDS] {
        let mut distance = vec![MAX_DEPTH; ray_count.max(1)];
        for h in &rays.hits {
            if let Some(d) = distance.get_mut(h.ray as usize) {
                *d = ((h.position - origin).length() / spacing).min(MAX_DEPTH);
            }
        }
        let mut texels = [0u8; DEPTH_TEXELS];
        let step = GROUP * self.feeds;
        for (g, out) in texels.chunks_mut(GROUP).enumerate() {
            let (rays, weights) = (
                &self.rays[g * step..(g + 1) * step],
                &self.weights[g * step..(g + 1) * step],
            );
            let w_sum = &self.weight_sums[g * GROUP..(g + 1) * GROUP];
            let (mut m1, mut m2) = ([0.0f64; GROUP], [0.0f64; GROUP]);
            for (rays, weights) in rays.chunks_exact(GROUP).zip(weights.chunks_exact(GROUP)) {
                for l in 0..GROUP {
                    let d = f64::from(distance[rays[l] as usize]);
                    let wd = weights[l] * d;
                    m1[l] += wd;
                    m2[l] += wd * d;
                }
            }
            for (l, texel) in out.iter_mut().enumerate() {
                *texel = if w_sum[l] <= 0.0 {
                    // No ray near this texel (very low ray counts): unbounded, so the sampler
                    // skips the test here.
                    quantise(MAX_DEPTH, 0.0)
                } else {
                    let mean = m1[l] / w_sum[l];
                    let deviation = (m2[l] / w_sum[l] - mean * mean).max(0.0).sqrt();
                    quantise(mean as f32, deviation as f32)
                };
            }
        }
        std::array::from_fn(|w| pack_texels(std::array::from_fn(|i| texels[4 * w + i])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Hit;

    /// The copy compiled for AVX gives the SSE2 copy's bits, probe after probe (hits at
    /// pseudo-random distances on a pseudo-random half of the rays, the rest sky).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn map_compiled_for_avx_gives_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx") {
            eprintln!("skipped: this CPU has no AVX");
            return;
        }
        let directions: Vec<Vec3> = prt_format::directions::fibonacci_directions(512)
            .into_iter()
            .map(Vec3::from)
            .collect();
        let filter = DepthFilter::new(&directions);
        let mut state = 0x9e37_79b9u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        for probe in 0..20 {
            let origin = Vec3::new(probe as f32, 0.5, -2.0);
            let hits = (0..512u32)
                .filter_map(|ray| {
                    let r = next();
                    (r % 2 == 0).then_some((ray, (r >> 1) % 10_000))
                })
                .map(|(ray, t)| {
                    let position = origin + directions[ray as usize] * (t as f32 * 1e-3);
                    Hit::grey(ray, position, Vec3::Z)
                })
                .collect();
            let rays = ProbeRays {
                hits,
                ..ProbeRays::default()
            };
            let sse2 = filter.map_in(origin, &rays, 512, 1.3);
            // SAFETY: the CPU has AVX (checked above).
            let avx = unsafe { filter.map_avx(origin, &rays, 512, 1.3) };
            assert_eq!(sse2, avx, "probe {probe}");
        }
    }
}
