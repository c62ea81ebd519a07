//! The snorm8 quantiser behind the packed factors' fields ([`crate::FactorU8`]): a value clamped to
//! [-1, 1], times 127, rounded half away from zero, as a byte (NaN to 0).
//!
//! The baker quantises the eight SH terms of every factor row it makes (5.1 M rows at Sponza's
//! 1.0 m spacing). One term at a time, each float-to-integer cast is a compare-and-select
//! sequence (Rust's casts saturate, and NaN becomes 0), and a row took about 50 ns, 5% of the
//! bake's CPU time; [`snorm8_div8`] quantises four terms per SSE2 instruction (x86-64's
//! baseline), the same bits as `snorm8` term by term (tests below): 109-132 ms against
//! 240-273 ms of CPU time to encode the rows of the first 16,000 of the 16,758 probes of
//! Sponza at 1.0 m (release build, four bakes each). [`snorm8_div4`] does the same for the three offsets each factor gets
//! once its brick is known.

/// One value, quantised: the definition [`snorm8_div4`] computes four at a time (used alone
/// only where there is no SSE2, and by the tests).
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
#[inline]
fn snorm8(v: f32) -> u32 {
    (round_small(v.clamp(-1.0, 1.0) * 127.0) as u32) & 0xff
}

/// `v.round() as i32` (half away from zero; NaN to 0) for `|v| < 2^23`, by truncation, as
/// [`snorm8_div4`] rounds its lanes: the baseline x86-64 target has no SSE4.1 `roundps`, and
/// `round` is a call to a software routine. `v - trunc(v)` is exact in that range.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
#[inline]
fn round_small(v: f32) -> i32 {
    let t = v as i32;
    let f = v - t as f32;
    t + i32::from(f >= 0.5) - i32::from(f <= -0.5)
}

/// `snorm8(v[k] / scale)` for each of the eight values.
#[inline]
pub(crate) fn snorm8_div8(v: [f32; 8], scale: f32) -> [u32; 8] {
    let (a, b) = (
        snorm8_div4([v[0], v[1], v[2], v[3]], scale),
        snorm8_div4([v[4], v[5], v[6], v[7]], scale),
    );
    [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]]
}

/// `snorm8(v[k] / scale)` for each of the four values.
#[inline]
pub(crate) fn snorm8_div4(v: [f32; 4], scale: f32) -> [u32; 4] {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    {
        sse2::snorm8_div4(v, scale)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    {
        v.map(|x| snorm8(x / scale))
    }
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod sse2 {
    use std::arch::x86_64::*;

    /// [`super::snorm8_div4`] in one SSE2 vector, each lane the scalar path's IEEE operations:
    /// the division, `f32::clamp` (below -1 to -1, above 1 to 1, as two compare-and-selects),
    /// the product, and the rounding by truncation (exact: after the clamp every lane is
    /// within 127 of zero). NaN lanes are zeroed first, which is what the scalar path's
    /// saturating cast makes of them.
    #[inline]
    pub(super) fn snorm8_div4(v: [f32; 4], scale: f32) -> [u32; 4] {
        let mut out = [0u32; 4];
        // SAFETY: the module is compiled only where SSE2 is enabled, so every intrinsic here is
        // available;
        // the unaligned load reads the four floats of `v` and the store writes the four words
        // of `out`.
        unsafe {
            let (low, high) = (_mm_set1_ps(-1.0), _mm_set1_ps(1.0));
            let x = _mm_div_ps(_mm_loadu_ps(v.as_ptr()), _mm_set1_ps(scale));
            let x = _mm_and_ps(x, _mm_cmpord_ps(x, x));
            let below = _mm_cmplt_ps(x, low);
            let x = _mm_or_ps(_mm_and_ps(below, low), _mm_andnot_ps(below, x));
            let above = _mm_cmpgt_ps(x, high);
            let x = _mm_or_ps(_mm_and_ps(above, high), _mm_andnot_ps(above, x));
            let x = _mm_mul_ps(x, _mm_set1_ps(127.0));
            let t = _mm_cvttps_epi32(x);
            let f = _mm_sub_ps(x, _mm_cvtepi32_ps(t));
            // All ones (-1) where the remainder rounds away from zero.
            let up = _mm_castps_si128(_mm_cmpge_ps(f, _mm_set1_ps(0.5)));
            let down = _mm_castps_si128(_mm_cmple_ps(f, _mm_set1_ps(-0.5)));
            let q = _mm_add_epi32(_mm_sub_epi32(t, up), down);
            let q = _mm_and_si128(q, _mm_set1_epi32(0xff));
            _mm_storeu_si128(out.as_mut_ptr().cast(), q);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`round_small`] is `round` then a cast for every 37th float of magnitude below 2^23 (and
    /// NaN) and around every half-integer near zero, and through [`snorm8`] for every 61st
    /// float of all bit patterns.
    #[test]
    fn round_by_truncation_is_round() {
        let check = |v: f32| assert_eq!(round_small(v), v.round() as i32, "{v:e}");
        for bits in (0..0x4b00_0000u32).step_by(37) {
            check(f32::from_bits(bits));
            check(-f32::from_bits(bits));
        }
        check(f32::NAN);
        for n in -300..300 {
            let v = n as f32 + 0.5;
            for w in [v, v.next_down(), v.next_up()] {
                check(w);
            }
        }
        for bits in (0..=u32::MAX).step_by(61) {
            let v = f32::from_bits(bits);
            let want = ((v.clamp(-1.0, 1.0) * 127.0).round() as i32 as u32) & 0xff;
            assert_eq!(snorm8(v), want, "{v:e}");
        }
    }

    /// Eight at a time gives [`snorm8`] of each quotient, bit for bit: every 97th float of all
    /// bit patterns (NaNs, infinities, subnormals and both zeros among them) over scales from
    /// tiny to huge, and the quotients at and next to every rounding tie and to the clamp.
    #[test]
    fn eight_at_a_time_is_one_at_a_time() {
        let check = |v: [f32; 8], scale: f32| {
            let want = v.map(|x| snorm8(x / scale));
            assert_eq!(snorm8_div8(v, scale), want, "{v:?} / {scale:e}");
        };
        let scales = [
            1.0,
            0.017_3,
            3.7e-3,
            2.24 * 0.069,
            1e-30,
            1e30,
            -0.5,
            0.0,
            f32::NAN,
        ];
        let mut special = Vec::new();
        for k in -140..140 {
            let tie = (k as f32 + 0.5) / 127.0;
            special.extend([tie, tie.next_up(), tie.next_down(), k as f32 / 127.0]);
        }
        special.extend([
            1.0,
            -1.0,
            1.0f32.next_up(),
            (-1.0f32).next_down(),
            0.0,
            -0.0,
        ]);
        special.extend([
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
        ]);
        for &scale in &scales {
            let mut lanes = (0..=u32::MAX).step_by(97).map(f32::from_bits);
            while let Some(first) = lanes.next() {
                let mut v = [first; 8];
                for lane in &mut v[1..] {
                    *lane = lanes.next().unwrap_or(0.0);
                }
                check(v, scale);
            }
            for chunk in special.chunks(8) {
                let mut v = [0.0; 8];
                v[..chunk.len()].copy_from_slice(chunk);
                check(v, scale);
            }
        }
        // Ties as quotients of the scales the baker uses.
        for &scale in &scales[..4] {
            for k in -140..140 {
                let v = (k as f32 + 0.5) / 127.0 * scale;
                check(
                    [
                        v,
                        v.next_up(),
                        v.next_down(),
                        -v,
                        k as f32,
                        0.5,
                        -0.5,
                        v * 2.0,
                    ],
                    scale,
                );
            }
        }
    }
}
