//! Probe visibility data: per probe, an octahedral map ([`DEPTH_MAP_SIDE`]² texels; Cigolle et
//! al., "A Survey of Efficient Representations for Independent Unit Vectors", JCGT 2014) of the
//! mean and standard deviation of the distance to the first hit of its rays, in probe spacings
//! (so the data does not depend on the scene's scale), four bits each: 256 bytes per probe.
//! Sampling tests whether a shaded point is visible from a probe with Chebyshev's inequality on
//! these moments, as DDGI does (Majercik et al., "Dynamic Diffuse Global Illumination with
//! Ray-Traced Irradiance Fields", JCGT 2019). Every function here has a WGSL twin in
//! `shaders/sample_irradiance.wgsl`.
//!
//! Why 16x16 texels rather than DDGI's 16x16 half pairs or 8x8 halves: a texel must be narrow,
//! because the distance to a nearby wall changes fast with the angle (at 8x8, 25-degree texels
//! averaged grazing rays that travel far along the wall into the mean, and light leaked through
//! it: measured again in format 9, the depth-moment lookup's worst tuning level went from 19.2%
//! to 44.9%, `docs/results/packing.md`).
//!
//! Why four bits a moment, on a square-root scale (format 10; a byte each before): the levels
//! `4 (q / 15)^2` spacings (0, 0.018, 0.071, 0.16, 0.28, ...) are dense next to the probe,
//! where a wall close by must stop light, and 0.2-0.37 spacings apart between 1 and 2
//! spacings, where the shaded points of its cells lie (bytes had steps of a 64th). On the
//! level family's tuning seeds the depth-moment lookup measured as it did with bytes (median
//! level 9.1% both, worst 19.3% against 19.2%); on the held-out seeds its worst level went from
//! 19.8% to 20.3% (cave_15, 25 leaking points against 22). Four linear bits measured worse on
//! the tuning seeds (worst 20.2%, leaks 5.7% against 5.0%). Since the surface terms, the
//! runtime's default lookup reads the moments only where a point has no surfel
//! (`docs/results/packing.md`).

use crate::asset::DEPTH_MAP_SIDE;

/// Largest stored distance, in probe spacings (sky rays count as this). A shaded point is at
/// most sqrt(3) spacings plus the normal offset from any of its eight probes, so farther hits
/// never change a test.
pub const MAX_DEPTH: f32 = 4.0;
/// Largest stored standard deviation, in probe spacings.
pub const MAX_DEVIATION: f32 = 2.0;

/// Sign that is +1 at zero (WGSL's `sign(0)` is 0, which would fold the map's seams).
fn sign_not_zero(x: f32) -> f32 {
    if x >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// Octahedral coordinates in [-1, 1]² of a unit direction (+Y hemisphere in the middle).
pub fn oct_encode(d: [f32; 3]) -> [f32; 2] {
    let l1 = d[0].abs() + d[1].abs() + d[2].abs();
    if l1 <= 0.0 {
        return [0.0, 0.0];
    }
    let (a, b) = (d[0] / l1, d[2] / l1);
    if d[1] >= 0.0 {
        [a, b]
    } else {
        [
            (1.0 - b.abs()) * sign_not_zero(a),
            (1.0 - a.abs()) * sign_not_zero(b),
        ]
    }
}

/// Unit direction of octahedral coordinates.
pub fn oct_decode(e: [f32; 2]) -> [f32; 3] {
    let (mut a, mut b) = (e[0], e[1]);
    let y = 1.0 - a.abs() - b.abs();
    if y < 0.0 {
        let (pa, pb) = (a, b);
        a = (1.0 - pb.abs()) * sign_not_zero(pa);
        b = (1.0 - pa.abs()) * sign_not_zero(pb);
    }
    let len = (a * a + y * y + b * b).sqrt();
    [a / len, y / len, b / len]
}

/// Texel of the map (row-major) that holds direction `d`.
pub fn texel_of(d: [f32; 3]) -> usize {
    let e = oct_encode(d);
    let side = DEPTH_MAP_SIDE as f32;
    let at = |v: f32| ((v * 0.5 + 0.5) * side).floor().clamp(0.0, side - 1.0) as usize;
    at(e[1]) * DEPTH_MAP_SIDE as usize + at(e[0])
}

/// Direction at the centre of texel `t`.
pub fn texel_direction(t: usize) -> [f32; 3] {
    let side = DEPTH_MAP_SIDE as usize;
    let c = |i: usize| ((i as f32 + 0.5) / side as f32) * 2.0 - 1.0;
    oct_decode([c(t % side), c(t / side)])
}

/// The top value of a moment's four bits: a mean there is saturated (sky, or hits farther than
/// about 3.7 spacings) and bounds nothing.
pub const TOP: u32 = 15;

/// What one unit of `q^2` is worth, `q` a moment's four bits: the mean `q^2 * MEAN_STEP`, the
/// deviation `q^2 * DEVIATION_STEP` (`max / 225`). The WGSL twin multiplies by the same f32
/// values (injected by `prt_runtime::contract`), so both decode every byte to the same bits.
pub const MEAN_STEP: f32 = MAX_DEPTH / (TOP * TOP) as f32;
/// See [`MEAN_STEP`].
pub const DEVIATION_STEP: f32 = MAX_DEVIATION / (TOP * TOP) as f32;

/// A texel's byte: the mean in the low four bits, the standard deviation in the high four,
/// each `round(15 sqrt(v / max))` of its range [0, MAX_DEPTH] or [0, MAX_DEVIATION].
pub fn quantise(mean: f32, deviation: f32) -> u8 {
    let top = TOP as f32;
    let q = |v: f32, max: f32| ((v / max).clamp(0.0, 1.0).sqrt() * top).round() as u8;
    q(mean, MAX_DEPTH) | q(deviation, MAX_DEVIATION) << 4
}

/// A moment of four bits `q` whose unit is `step` ([`MEAN_STEP`], [`DEVIATION_STEP`]); the
/// top value reads as `max` exactly, which callers test for a saturated mean.
fn level(q: u32, step: f32, max: f32) -> f32 {
    if q == TOP {
        max
    } else {
        (q * q) as f32 * step
    }
}

/// Mean and standard deviation of texel `t` of a probe's map (`words` = its [`crate::DEPTH_WORDS`]
/// words, four texels a word, the first in the low byte); the WGSL twin
/// (`shaders/sample_irradiance.wgsl`, `prt_depth_weight`) decodes the same.
pub fn moments(words: &[u32], t: usize) -> (f32, f32) {
    let b = words[t / 4] >> (8 * (t % 4)) & 0xff;
    (
        level(b & 0xf, MEAN_STEP, MAX_DEPTH),
        level(b >> 4, DEVIATION_STEP, MAX_DEVIATION),
    )
}

/// The four texel bytes of a word, the first in the low byte.
pub fn pack_texels(bytes: [u8; 4]) -> u32 {
    u32::from_le_bytes(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octahedral_round_trip_and_texels() {
        for t in 0..(DEPTH_MAP_SIDE * DEPTH_MAP_SIDE) as usize {
            let d = texel_direction(t);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-5);
            assert_eq!(texel_of(d), t, "texel {t} direction {d:?}");
        }
        for d in [
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
        ] {
            let back = oct_decode(oct_encode(d));
            for c in 0..3 {
                assert!((back[c] - d[c]).abs() < 1e-6, "{d:?} -> {back:?}");
            }
        }
    }

    /// A moment comes back within half a step of its square-root scale, exact at zero and at
    /// the top (a saturated mean must read as `MAX_DEPTH` exactly: it means "no bound"); out of
    /// range values clamp; each texel of a word is read from its own byte.
    #[test]
    fn moments_round_trip_within_a_quantisation_step() {
        let half_step = |v: f32, back: f32, max: f32| {
            ((back / max).sqrt() - (v / max).sqrt()).abs() <= 0.5 / TOP as f32 + 1e-6
        };
        for (mean, deviation) in [
            (0.0, 0.0),
            (0.05, 0.01),
            (0.3, 0.1),
            (1.25, 0.3),
            (3.9, 1.9),
        ] {
            let word = pack_texels([0, 0, quantise(mean, deviation), 0]);
            let (m, d) = moments(&[word], 2);
            assert!(half_step(mean, m, MAX_DEPTH), "{mean} -> {m}");
            assert!(half_step(deviation, d, MAX_DEVIATION), "{deviation} -> {d}");
        }
        let word = pack_texels([quantise(0.0, 0.0), quantise(9.0, -1.0), 0, 0xff]);
        assert_eq!(moments(&[word], 0), (0.0, 0.0));
        assert_eq!(moments(&[word], 1), (MAX_DEPTH, 0.0));
        assert_eq!(moments(&[word], 3), (MAX_DEPTH, MAX_DEVIATION));
    }
}
