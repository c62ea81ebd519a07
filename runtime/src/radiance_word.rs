//! # Radiance words: a surfel's radiance in 32 bits
//!
//! The GPU runtime keeps every surfel's direct radiance (stage 2) and, with bounces, its bounce
//! radiance (stage 3) for stage 4 to average into its brick and near group. As three floats
//! they were 12 bytes a surfel each, a quarter of the street level's surfel memory (issue 32's
//! GPU budget). A word holds them as Ward's shared-exponent RGBE (Ward, "Real pixels", Graphics
//! Gems II, 1991): three 8-bit mantissas (red from bit 0) and an 8-bit exponent (bit 24), so
//! each channel keeps its value to within 2^-9 of the largest channel, and any scale a scene
//! sets fits: from 2^-100 (below it precision falls, below 2^-108 a colour is black) to
//! `f32::MAX`, where a 5-bit exponent
//! (RGB9E5, [`prt_format::surfel::rgb9e5`]) would clip a bright rig and flush a dim one.
//!
//! The encoding is exact arithmetic on both sides (scaling by powers of two built from their
//! bits, rounding half up), so `pack_radiance` in `shaders/types.wgsl` gives the same word as
//! [`pack_radiance`] for the same colour, and the CPU reference ([`crate::relight`]) averages
//! the same decoded radiance the GPU does.

/// Lowest `floor(log2)` of a colour's largest channel the exponent follows: below it the step
/// stays 2^-107, so that subnormals (which a GPU may flush) always round to zero.
const LOWEST_LOG2: i32 = -100;

/// What turns `e` (the largest channel is below 2^e) into the stored exponent byte, whose
/// f32 bits `byte << 23` are the step `2^(e - 8)` of the mantissas.
const EXPONENT_BIAS: i32 = 119;

/// `2^(8 - e)`, from its bits (exact).
fn scale(e: i32) -> f32 {
    f32::from_bits(((135 - e) as u32) << 23)
}

/// `rgb` as a radiance word: negative and NaN channels as 0, infinite ones as `f32::MAX`.
pub fn pack_radiance(rgb: [f32; 3]) -> u32 {
    let c = rgb.map(|v| if v > 0.0 { v.min(f32::MAX) } else { 0.0 });
    let largest = c[0].max(c[1]).max(c[2]);
    if largest <= 0.0 {
        return 0;
    }
    let mut e = ((largest.to_bits() >> 23) as i32 - 127).max(LOWEST_LOG2) + 1;
    if (largest * scale(e) + 0.5).floor() >= 256.0 {
        e += 1;
    }
    let m = c.map(|v| ((v * scale(e) + 0.5).floor() as u32).min(255));
    m[0] | m[1] << 8 | m[2] << 16 | ((e + EXPONENT_BIAS) as u32) << 24
}

/// The colour of a radiance word (as `unpack_radiance` in `shaders/types.wgsl` decodes it).
pub fn unpack_radiance(w: u32) -> [f32; 3] {
    let step = f32::from_bits((w >> 24) << 23);
    [w & 255, (w >> 8) & 255, (w >> 16) & 255].map(|m| m as f32 * step)
}

/// `rgb` as the runtime keeps it: [`unpack_radiance`] of [`pack_radiance`].
pub fn quantize_radiance(rgb: [f32; 3]) -> [f32; 3] {
    unpack_radiance(pack_radiance(rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every channel within 2^-9 of the largest, at every scale a rig may set.
    #[test]
    fn words_keep_radiance_to_half_a_step_at_any_scale() {
        for scale in [1e-28f32, 1e-6, 1e-3, 1.0, 7.3, 1e3, 6.5e4, 1e6, 1e30] {
            for rgb in [
                [1.0f32, 0.5, 0.25],
                [0.9999, 0.0, 0.0],
                [0.063, 0.0065, 0.005],
                [0.3, 0.3, 0.3],
                [0.999_99, 0.999_99, 0.5],
            ] {
                let v = rgb.map(|c| c * scale);
                let got = quantize_radiance(v);
                let largest = v[0].max(v[1]).max(v[2]);
                for c in 0..3 {
                    let err = (got[c] - v[c]).abs();
                    assert!(
                        err <= largest / 512.0 * 1.0001,
                        "{v:?} -> {got:?}: channel {c} off by {err}"
                    );
                }
            }
        }
    }

    #[test]
    fn black_negative_nan_and_infinite_channels() {
        assert_eq!(pack_radiance([0.0; 3]), 0);
        assert_eq!(unpack_radiance(0), [0.0; 3]);
        assert_eq!(quantize_radiance([-1.0, f32::NAN, 2.0]), [0.0, 0.0, 2.0]);
        assert_eq!(quantize_radiance([1e-34, 0.0, 0.0]), [0.0; 3]);
        let inf = quantize_radiance([f32::INFINITY, 1.0, 0.0]);
        assert!(inf[0].is_finite() && inf[0] > 3e38 && inf[1] == 0.0);
    }

    /// A largest channel that rounds up to 256 moves to the next exponent.
    #[test]
    fn rounding_up_carries_into_the_exponent() {
        let w = pack_radiance([0.9995, 0.0, 0.0]);
        assert_eq!(unpack_radiance(w), [1.0, 0.0, 0.0]);
        assert_eq!(w & 255, 128);
    }
}
