//! Probe visibility maps (`prt_format::depth`): per probe, per octahedral texel, the mean and
//! standard deviation of its rays' hit distances in probe spacings, each ray weighted by
//! `max(0, cos)^64` of its angle to the texel's centre direction (the filtering of DDGI,
//! Majercik et al. 2019, over the bake's own rays instead of new ones). Sky rays count as
//! `prt_format::depth::MAX_DEPTH`.
//!
//! Every probe shoots the same lattice, so which rays feed which texel, and with what weight, is
//! computed once per bake ([`DepthFilter`]); a probe then costs a few multiply-adds per texel.

use glam::Vec3;
use prt_format::depth::{quantise, texel_direction, MAX_DEPTH};
use prt_format::{DEPTH_TEXELS, DEPTH_WORDS};

use crate::trace::ProbeRays;

/// The texel filter is `cos^(2^SHARPNESS_SQUARINGS)`: cos^64 halves the weight 8.4 degrees off
/// the texel's centre, about the half-width of a 16x16 octahedral texel, so each texel averages
/// the few lattice rays around it (512 rays are about 9 degrees apart).
const SHARPNESS_SQUARINGS: u32 = 6;
/// Rays farther than this from a texel's centre (weight below 1e-4) are skipped.
const MIN_COS: f32 = 0.866;

/// Per texel, the lattice rays that feed it and their filter weights.
pub struct DepthFilter {
    texels: Vec<Vec<(u32, f32)>>,
}

impl DepthFilter {
    /// The filter of the lattice `directions`.
    pub fn new(directions: &[Vec3]) -> DepthFilter {
        let texels = (0..DEPTH_TEXELS)
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
                        Some((i as u32, w))
                    })
                    .collect()
            })
            .collect();
        DepthFilter { texels }
    }

    /// The packed visibility map of one probe at `origin` (`ray_count` lattice rays).
    pub fn map(
        &self,
        origin: Vec3,
        rays: &ProbeRays,
        ray_count: usize,
        spacing: f32,
    ) -> [u32; DEPTH_WORDS] {
        let mut distance = vec![MAX_DEPTH; ray_count];
        for h in &rays.hits {
            if let Some(d) = distance.get_mut(h.ray as usize) {
                *d = ((h.position - origin).length() / spacing).min(MAX_DEPTH);
            }
        }
        let texels: Vec<[u8; 2]> = self
            .texels
            .iter()
            .map(|feeds| {
                let (mut w_sum, mut m1, mut m2) = (0.0f64, 0.0f64, 0.0f64);
                for &(i, w) in feeds {
                    let (w, d) = (f64::from(w), f64::from(distance[i as usize]));
                    w_sum += w;
                    m1 += w * d;
                    m2 += w * d * d;
                }
                if w_sum <= 0.0 {
                    // No ray near this texel (very low ray counts): unbounded, so the sampler
                    // skips the test here.
                    return quantise(MAX_DEPTH, 0.0);
                }
                let mean = m1 / w_sum;
                let deviation = (m2 / w_sum - mean * mean).max(0.0).sqrt();
                quantise(mean as f32, deviation as f32)
            })
            .collect();
        std::array::from_fn(|w| {
            let (a, b) = (texels[2 * w], texels[2 * w + 1]);
            u32::from_le_bytes([a[0], a[1], b[0], b[1]])
        })
    }
}
