//! # Lobe factors: a factor's SH transfer from two stored numbers
//!
//! A factor's transfer is the SH projection of the rays of one probe that end on one brick,
//! `t_k = 4pi/N sum_i Y_k(w_i)`. Those rays leave one point toward one small patch, so they
//! are a narrow bundle about their mean direction `d`, and their projection is nearly that of
//! a lobe symmetric about it:
//!
//! - band 1 is exactly `t_0 * R * Y_1(d) / Y_00`, with `R` the length of the rays' mean
//!   vector (`Y_1` is linear in the direction);
//! - band 2 of a lobe symmetric about `d` is `t_0 * A_2 * Y_2(d) / Y_00`, with `A_2` the mean
//!   of the Legendre polynomial `P_2` over the lobe. A von Mises-Fisher lobe of that `R` has
//!   `A_2 = 1 - 3 (1 - R^2) / (3 - R^2)` (with Banerjee et al. 2005's `kappa`); the rays onto
//!   a patch are closer to a uniform cone, so the bake fits `A_2` by itself ([`fit`]), which
//!   measured better on the two-room fixture (5.02% -> 4.92% at 6-bit `R`).
//!
//! The direction is not stored: it is the direction from the probe's ray origin to the
//! factor's *stored point*, the one its offset names (`crate::Asset::factor_point`). That is
//! the rays' mean hit point where the lobe toward it fits; elsewhere, in merged bakes, the bake
//! tries the point of the rays' mean direction nearest the mean hit point, whose direction is
//! the rays' own up to the offset's 6-bit steps (the radiance is then evaluated there, beside
//! the mean hit point). A lobe factor thus stores `R` in [`R_BITS`] bits
//! ([`r_level`]) and `A_2` in [`A2_BITS`]: 8 bytes, where a factor with its eight terms
//! takes 16 (two slots, `crate::FactorSlot`).
//!
//! The bake keeps a factor as a lobe only where the lobe fits its quantised terms: band 1
//! within [`BAND1_TOLERANCE`] and band 2 within [`BAND2_TOLERANCE`] of each term's range
//! (`crate::SH_RANGE`, in units of the factor's DC term). The tolerances were chosen on the
//! level family's tuning seeds and the bundled scenes (docs/results/packing.md, format 11):
//! with band 1 at a 120th of its range and `R` in 9 bits, 97% of Cornell's factors are lobes
//! and the tuning seeds measure as with 12-byte factors; at a 30th (and a 6-bit `R`) the
//! small scenes' surfaces lost 0.1-0.25 points, at a 240th only 73% are lobes for no gain.
//! Band 1 weighs 2.7x band 2 in irradiance (`2pi/3` against `pi/4`).

use crate::sh::{basis, Y00};

/// Bits of a lobe factor's `R`: a step of a 511th keeps band 1 of the narrow bundles (`R`
/// near 1) within its tolerance.
pub const R_BITS: u32 = 9;
/// Largest code of `R`: `R = code / R_TOP`.
pub const R_TOP: u32 = (1 << R_BITS) - 1;
/// Bits of a lobe factor's band-2 scale `A_2` (a step of a 15th, as the 5-bit terms').
pub const A2_BITS: u32 = 4;
/// Largest code of `A_2`: `A_2 = code / A2_TOP`, in 0..=1.
pub const A2_TOP: u32 = (1 << A2_BITS) - 1;
/// Largest difference, in units of the term's range times the DC term, between a band-1
/// term of the lobe and the factor's (the 7-bit terms' step is a 63rd).
pub const BAND1_TOLERANCE: f32 = 1.0 / 120.0;
/// The same for band 2 (the 5-bit terms' step is a 15th).
pub const BAND2_TOLERANCE: f32 = 1.0 / 15.0;

/// `R` of code `q` (`q <= R_TOP`).
pub fn r_level(q: u32) -> f32 {
    q as f32 / R_TOP as f32
}

/// The code nearest `r` (clamped to 0..=1).
pub fn quantise_r(r: f32) -> u32 {
    (r.clamp(0.0, 1.0) * R_TOP as f32).round() as u32
}

/// `A_2` of code `q` (`q <= A2_TOP`).
pub fn a2_level(q: u32) -> f32 {
    q as f32 / A2_TOP as f32
}

/// Terms k = 1..8 of the lobe of length `r` and band-2 scale `a2` about `toward` (any
/// length), in units of the DC term; all zero when `toward` is zero (no direction: the lobe
/// is uniform).
pub fn lobe_terms(r: f32, a2: f32, toward: [f32; 3]) -> [f32; 8] {
    let len_sq = toward[0] * toward[0] + toward[1] * toward[1] + toward[2] * toward[2];
    // Zero, or not finite (a point past the f32 range, from extreme coordinates or offset
    // scales): no direction.
    if !len_sq.is_finite() || len_sq <= 0.0 {
        return [0.0; 8];
    }
    let inv = 1.0 / len_sq.sqrt();
    let y = basis(toward.map(|v| v * inv));
    std::array::from_fn(|k| y[k + 1] / Y00 * if k < 3 { r } else { a2 })
}

/// The codes of `R` and of the band-2 scale whose lobe about `toward` fits `terms` (k = 1..8
/// in units of the DC term) within the tolerances, or `None`: each the least-squares fit of
/// its band along `toward`.
pub fn fit(terms: &[f32; 8], toward: [f32; 3]) -> Option<(u32, u32)> {
    let unit = lobe_terms(1.0, 1.0, toward);
    // |Y_1(d) / Y_00|^2 = 3 and |Y_2(d) / Y_00|^2 = 5 for a unit direction.
    let r = (0..3).map(|k| terms[k] * unit[k]).sum::<f32>() / 3.0;
    let a2 = (3..8).map(|k| terms[k] * unit[k]).sum::<f32>() / 5.0;
    let q = quantise_r(r);
    let q2 = (a2.clamp(0.0, 1.0) * A2_TOP as f32).round() as u32;
    let lobe = lobe_terms(r_level(q), a2_level(q2), toward);
    let fits = (0..8).all(|k| {
        let tolerance = if k < 3 {
            BAND1_TOLERANCE
        } else {
            BAND2_TOLERANCE
        };
        (lobe[k] - terms[k]).abs() <= tolerance * crate::SH_RANGE[k]
    });
    fits.then_some((q, q2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::SH_COUNT;

    fn normalise(v: [f32; 3]) -> [f32; 3] {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / l)
    }

    fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    /// The projection of a bundle of rays about a direction, in units of its DC term.
    fn bundle(axis: [f32; 3], spread: f32) -> [f32; 8] {
        let mut t = [0.0f32; SH_COUNT];
        let n = 64;
        let a = normalise(axis);
        let u = normalise(cross(a, [0.6, 0.0, 0.8]));
        let v = cross(a, u);
        for i in 0..n {
            let phi = i as f32 * 2.399_963;
            let s = spread * ((i as f32 + 0.5) / n as f32).sqrt();
            let w = normalise(std::array::from_fn(|c| {
                a[c] + s * (phi.cos() * u[c] + phi.sin() * v[c])
            }));
            for (t, y) in t.iter_mut().zip(basis(w)) {
                *t += y;
            }
        }
        std::array::from_fn(|k| t[k + 1] / t[0])
    }

    /// A narrow bundle fits its lobe about its axis, whose `R` is the bundle's; about a
    /// direction 30 degrees off it does not, nor does a bundle of two directions far apart.
    #[test]
    fn narrow_bundles_fit_their_lobe() {
        let axis = [0.3, -0.5, 0.8];
        for spread in [0.0, 0.1, 0.3] {
            let terms = bundle(axis, spread);
            let (q, q2) = fit(&terms, axis.map(|v| v * 7.0)).expect("fits");
            let lobe = lobe_terms(r_level(q), a2_level(q2), axis);
            for k in 0..8 {
                let tolerance = if k < 3 {
                    BAND1_TOLERANCE
                } else {
                    BAND2_TOLERANCE
                };
                assert!((lobe[k] - terms[k]).abs() <= tolerance * crate::SH_RANGE[k]);
            }
        }
        let off = [0.3 + 0.55, -0.5, 0.8];
        assert_eq!(fit(&bundle(axis, 0.05), off), None);
        let two: [f32; 8] = std::array::from_fn(|k| {
            0.5 * (bundle([1.0, 0.0, 0.0], 0.0)[k] + bundle([0.0, 1.0, 0.0], 0.0)[k])
        });
        assert_eq!(fit(&two, [1.0, 1.0, 0.0]), None);
    }

    /// The scales keep 0 and 1 exactly, every code quantises back to itself, and a zero
    /// direction gives a uniform lobe.
    #[test]
    fn codes_round_trip() {
        assert_eq!((r_level(0), r_level(R_TOP)), (0.0, 1.0));
        assert_eq!((a2_level(0), a2_level(A2_TOP)), (0.0, 1.0));
        for q in 0..=R_TOP {
            assert_eq!(quantise_r(r_level(q)), q);
        }
        assert_eq!(lobe_terms(0.5, 0.5, [0.0; 3]), [0.0; 8]);
    }
}
