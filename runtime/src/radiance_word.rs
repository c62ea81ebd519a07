//! # Radiance words: a surfel's radiance in 32 bits
//!
//! The GPU runtime keeps every surfel's direct radiance (stage 2) and, with bounces, its bounce
//! radiance (stage 3) for stage 4 to average into its brick and near group. As three floats
//! they were 12 bytes a surfel each, a quarter of the street level's surfel memory (issue 32's
//! GPU budget). An asset with packed surfels (every preset but the exact one) keeps them as one
//! word each, Ward's shared-exponent RGBE (Ward, "Real pixels", Graphics Gems II, 1991): three
//! 8-bit mantissas (red from bit 0) and an 8-bit exponent (bit 24), so each channel keeps its
//! value to within 1/255 of the largest channel (half a step: the largest fills at least half
//! the mantissa range, 2^-8, a little more when it rounds up into the next exponent), and any
//! scale a rig sets fits: from 2^-100 (below it precision falls, below
//! 2^-108 a colour is black) to `255 * 2^120`, where a 5-bit exponent (RGB9E5,
//! [`prt_format::surfel::rgb9e5`]) would clip a bright rig and flush a dim one.
//!
//! The exact preset's f32 surfels keep f32 radiance ([`words_per_surfel`]): its probes equal
//! Mitsuba on the same directions as `tests/tests/relight.rs` holds them (Cornell within 1e-3
//! of SH0 per coefficient, Sponza's p95 within 1e-5), and words would move them off it (Cornell
//! by 4.5e-4 mean irradiance error, 1.0e-3 per coefficient; 1,490 of Sponza's 1,497 probes
//! past 1e-4 of SH0). A merged bake's bricks average many hits and its error is set by the
//! merge: its probes against the converged reference move by less than 0.01 point
//! (`docs/results/packing.md`, stop 60).
//!
//! The encoding is exact arithmetic on both sides (scaling by powers of two built from their
//! bits, rounding half to even), so `pack_radiance` in `shaders/types.wgsl` gives the same word as
//! [`pack_radiance`] for the same finite colour (WGSL may assume floats finite: the GPU's
//! radiance is), and the CPU reference ([`crate::relight`]) averages the same decoded radiance
//! the GPU does.

use prt_format::SurfelPrecision;

use crate::contract::{RADIANCE_EXPONENT_BIAS, RADIANCE_LOWEST_LOG2, RADIANCE_MAX_BITS};

/// The largest channel value a word holds, `255 * 2^120` ([`RADIANCE_MAX_BITS`]): brighter
/// channels are clamped to it, so that no word decodes to infinity.
pub const RADIANCE_MAX: f32 = f32::from_bits(RADIANCE_MAX_BITS);

/// Words per surfel of the runtime's radiance buffers for surfels stored at `precision`: a
/// radiance word for packed surfels, three f32 for the exact preset's f32 surfels.
pub fn words_per_surfel(precision: SurfelPrecision) -> u32 {
    match precision {
        SurfelPrecision::Packed => 1,
        SurfelPrecision::F32 => 3,
    }
}

/// `2^(8 - e)`, the reciprocal of the step of exponent byte `e + RADIANCE_EXPONENT_BIAS`:
/// its exponent field is 254 less that byte (exact).
fn scale(e: i32) -> f32 {
    f32::from_bits(((254 - (e + RADIANCE_EXPONENT_BIAS)) as u32) << 23)
}

/// `rgb` as a radiance word: negative and NaN channels as 0, channels above [`RADIANCE_MAX`]
/// as it, a colour whose largest channel is subnormal as black.
pub fn pack_radiance(rgb: [f32; 3]) -> u32 {
    let c = rgb.map(|v| if v > 0.0 { v.min(RADIANCE_MAX) } else { 0.0 });
    let largest = c[0].max(c[1]).max(c[2]);
    if largest < f32::MIN_POSITIVE {
        return 0;
    }
    let mut e = ((largest.to_bits() >> 23) as i32 - 127).max(RADIANCE_LOWEST_LOG2) + 1;
    if (largest * scale(e)).round_ties_even() >= 256.0 {
        e += 1;
    }
    let m = c.map(|v| (v * scale(e)).round_ties_even() as u32);
    m[0] | m[1] << 8 | m[2] << 16 | ((e + RADIANCE_EXPONENT_BIAS) as u32) << 24
}

/// The colour of a radiance word (as `unpack_radiance` in `shaders/types.wgsl` decodes it).
pub fn unpack_radiance(w: u32) -> [f32; 3] {
    let step = f32::from_bits((w >> 24) << 23);
    [w & 255, (w >> 8) & 255, (w >> 16) & 255].map(|m| m as f32 * step)
}

/// `rgb` as the runtime keeps it for surfels stored at `precision`: [`unpack_radiance`] of
/// [`pack_radiance`] for packed surfels, itself for f32 ones.
pub fn kept_radiance(rgb: [f32; 3], precision: SurfelPrecision) -> [f32; 3] {
    match precision {
        SurfelPrecision::Packed => unpack_radiance(pack_radiance(rgb)),
        SurfelPrecision::F32 => rgb,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quantize(rgb: [f32; 3]) -> [f32; 3] {
        kept_radiance(rgb, SurfelPrecision::Packed)
    }

    /// Every channel within 2^-8 of the largest, at every scale a rig may set (none of these
    /// colours carries into the next exponent, where the bound is 1/255).
    #[test]
    fn words_keep_radiance_to_half_a_step_at_any_scale() {
        let mut worst = 0.0f32;
        for scale in [1e-28f32, 1e-6, 1e-3, 1.0, 7.3, 1e3, 6.5e4, 1e6, 1e30] {
            for rgb in [
                [1.0f32, 0.5, 0.25],
                [0.9999, 0.0, 0.0],
                [0.063, 0.0065, 0.005],
                [0.3, 0.3, 0.3],
                [0.999_99, 0.999_99, 0.5],
                [0.5001, 0.2, 0.7],
            ] {
                let v = rgb.map(|c| c * scale);
                let got = quantize(v);
                let largest = v[0].max(v[1]).max(v[2]);
                for c in 0..3 {
                    let err = (got[c] - v[c]).abs() / largest;
                    assert!(
                        err <= 1.0 / 256.0,
                        "{v:?} -> {got:?}: channel {c} off by {err}"
                    );
                    worst = worst.max(err);
                }
            }
        }
        assert!(worst > 1.0 / 512.0, "the bound is not loose: {worst}");
    }

    #[test]
    fn black_negative_nan_infinite_and_subnormal_channels() {
        assert_eq!(pack_radiance([0.0; 3]), 0);
        assert_eq!(unpack_radiance(0), [0.0; 3]);
        assert_eq!(quantize([-1.0, f32::NAN, 2.0]), [0.0, 0.0, 2.0]);
        assert_eq!(quantize([1e-34, 0.0, 0.0]), [0.0; 3]);
        assert_eq!(
            pack_radiance([1e-39, 0.0, 0.0]),
            0,
            "a subnormal largest channel"
        );
        for bright in [f32::INFINITY, f32::MAX, RADIANCE_MAX] {
            let got = quantize([bright, 1.0, 0.0]);
            assert_eq!(got, [RADIANCE_MAX, 0.0, 0.0], "{bright}");
        }
    }

    /// A largest channel that rounds up to 256 moves to the next exponent.
    #[test]
    fn rounding_up_carries_into_the_exponent() {
        let w = pack_radiance([0.9995, 0.0, 0.0]);
        assert_eq!(unpack_radiance(w), [1.0, 0.0, 0.0]);
        assert_eq!(w & 255, 128);
    }

    #[test]
    fn f32_surfels_keep_f32_radiance() {
        let v = [0.123_456_79, 1e-30, 7.0];
        assert_eq!(kept_radiance(v, SurfelPrecision::F32), v);
        assert_eq!(words_per_surfel(SurfelPrecision::F32), 3);
        assert_eq!(words_per_surfel(SurfelPrecision::Packed), 1);
    }
}
