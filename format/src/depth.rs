//! Probe visibility data: per probe, an octahedral map ([`DEPTH_MAP_SIDE`]² texels; Cigolle et
//! al., "A Survey of Efficient Representations for Independent Unit Vectors", JCGT 2014) of the
//! mean and standard deviation of the distance to the first hit of its rays, in probe spacings
//! (so the data does not depend on the scene's scale), one byte each: 512 bytes per probe.
//! Sampling tests whether a shaded point is visible from a probe with Chebyshev's inequality on
//! these moments, as DDGI does (Majercik et al., "Dynamic Diffuse Global Illumination with
//! Ray-Traced Irradiance Fields", JCGT 2019). Every function here has a WGSL twin in
//! `shaders/sample_irradiance.wgsl`.
//!
//! Why 16x16 bytes rather than DDGI's 16x16 half pairs or 8x8 halves: a texel must be narrow,
//! because the distance to a nearby wall changes fast with the angle (at 8x8, 25-degree texels
//! averaged grazing rays that travel far along the wall into the mean, and light leaked through
//! it); byte precision (1/64 spacing for the mean) is far finer than the test needs.

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

/// A texel's two bytes: mean and standard deviation, quantised to [0, MAX_DEPTH] and
/// [0, MAX_DEVIATION].
pub fn quantise(mean: f32, deviation: f32) -> [u8; 2] {
    let q = |v: f32, max: f32| (v / max * 255.0).round().clamp(0.0, 255.0) as u8;
    [q(mean, MAX_DEPTH), q(deviation, MAX_DEVIATION)]
}

/// Mean and standard deviation of texel `t` of a probe's map (`words` = its [`crate::DEPTH_WORDS`]
/// words); the WGSL twin reads them with `unpack4x8unorm`.
pub fn moments(words: &[u32], t: usize) -> (f32, f32) {
    let b = words[t / 2].to_le_bytes();
    let (m, d) = if t.is_multiple_of(2) {
        (b[0], b[1])
    } else {
        (b[2], b[3])
    };
    (
        f32::from(m) / 255.0 * MAX_DEPTH,
        f32::from(d) / 255.0 * MAX_DEVIATION,
    )
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

    #[test]
    fn moments_round_trip_within_a_quantisation_step() {
        let a = quantise(1.25, 0.3);
        let b = quantise(9.0, -1.0);
        let word = u32::from_le_bytes([a[0], a[1], b[0], b[1]]);
        let (m, d) = moments(&[word], 0);
        assert!((m - 1.25).abs() <= MAX_DEPTH / 510.0 && (d - 0.3).abs() <= MAX_DEVIATION / 510.0);
        assert_eq!(moments(&[word], 1), (MAX_DEPTH, 0.0));
    }
}
