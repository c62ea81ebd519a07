//! Real spherical harmonics up to L2 (9 coefficients), the one basis every part of prt uses.
//!
//! Basis and order as docs/conventions.md section 2: no Condon-Shortley sign, evaluated on the world
//! direction's x, y, z as they are. Coefficients project **incident radiance** (no cosine, no
//! 1/pi). Irradiance is reconstructed with the clamped-cosine convolution factors of
//! Ramamoorthi & Hanrahan, "An Efficient Representation for Irradiance Environment Maps"
//! (SIGGRAPH 2001): `E(n) = sum_k A_l(k) c_k Y_k(n)`, `A_0 = pi`, `A_1 = 2pi/3`, `A_2 = pi/4`.
//! Deringing follows Sloan, "Stupid Spherical Harmonics (SH) Tricks" (GDC 2008), section on
//! windowing: band l is scaled by a Hanning window `(1 + cos(pi l / w)) / 2`.

use std::f32::consts::PI;

/// Number of coefficients of L2 SH.
pub const SH_COUNT: usize = 9;

/// One RGB triple per coefficient, index k as in docs/conventions.md section 2.
pub type ShRgb = [[f32; 3]; SH_COUNT];

/// Normalisation constants of the basis functions.
pub const Y00: f32 = 0.282_094_8;
pub const Y1: f32 = 0.488_602_5;
pub const Y2_OFF: f32 = 1.092_548_4;
pub const Y20: f32 = 0.315_391_57;
pub const Y22: f32 = 0.546_274_2;

/// Band l of coefficient k.
pub const BAND: [usize; SH_COUNT] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// Clamped-cosine convolution factor A_l per coefficient (irradiance = sum A c Y).
pub const COSINE_LOBE: [f32; SH_COUNT] = [
    PI,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
];

/// The six axis directions, where benchmarks and the bake compare irradiance without a normal of
/// their own.
pub const AXIS_NORMALS: [[f32; 3]; 6] = [
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0],
];

/// All 9 basis functions at unit direction `d`.
#[inline]
pub fn basis(d: [f32; 3]) -> [f32; SH_COUNT] {
    let [x, y, z] = d;
    [
        Y00,
        Y1 * y,
        Y1 * z,
        Y1 * x,
        Y2_OFF * x * y,
        Y2_OFF * y * z,
        Y20 * (3.0 * z * z - 1.0),
        Y2_OFF * x * z,
        Y22 * (x * x - y * y),
    ]
}

/// Adds `weight * radiance * Y(d)` to `acc`: one term of the Monte Carlo projection
/// `c_k = (4pi/N) sum_i L(w_i) Y_k(w_i)`.
#[inline]
pub fn accumulate(acc: &mut ShRgb, d: [f32; 3], weight: f32, radiance: [f32; 3]) {
    let y = basis(d);
    for k in 0..SH_COUNT {
        for c in 0..3 {
            acc[k][c] += weight * y[k] * radiance[c];
        }
    }
}

/// SH of a constant radiance field `l` over the whole sphere: `c_0 = 4pi Y00 l`, rest 0.
pub fn constant(l: [f32; 3]) -> ShRgb {
    let mut c = [[0.0; 3]; SH_COUNT];
    for ch in 0..3 {
        c[0][ch] = 4.0 * PI * Y00 * l[ch];
    }
    c
}

/// Irradiance at a surface with unit normal `n` from incident-radiance SH `c`, clamped at 0
/// (L2 SH of a sharp signal can ring below zero).
pub fn irradiance(c: &ShRgb, n: [f32; 3]) -> [f32; 3] {
    let y = basis(n);
    let mut e = [0.0f32; 3];
    for k in 0..SH_COUNT {
        let w = COSINE_LOBE[k] * y[k];
        for ch in 0..3 {
            e[ch] += w * c[k][ch];
        }
    }
    e.map(|v| v.max(0.0))
}

/// Radiance reconstructed from the 9 coefficients in direction `d` (not clamped).
pub fn radiance(c: &ShRgb, d: [f32; 3]) -> [f32; 3] {
    let y = basis(d);
    let mut l = [0.0f32; 3];
    for k in 0..SH_COUNT {
        for ch in 0..3 {
            l[ch] += y[k] * c[k][ch];
        }
    }
    l
}

/// Deringing: scales band l by the Hanning window `(1 + cos(pi l / width)) / 2` (Sloan 2008).
/// `width` > 2 keeps band 2; a larger width rings more and blurs less. Returns a new set.
pub fn hanning_window(c: &ShRgb, width: f32) -> ShRgb {
    let mut out = *c;
    for k in 0..SH_COUNT {
        let l = BAND[k] as f32;
        let h = if l >= width {
            0.0
        } else {
            0.5 * (1.0 + (PI * l / width).cos())
        };
        for ch in 0..3 {
            out[k][ch] *= h;
        }
    }
    out
}

/// Irradiance on a surface of unit normal `n` from the L0 and L1 coefficients of `c` alone,
/// by the non-linear model of Enlighten (G. Hazel and C. Doran; G. Hazel, "Converting SH
/// radiance to irradiance", 2017): `E0 (a + (1 - a) (p + 1) q^p)` with `E0 = pi Y00 c0` the
/// mean irradiance, `r = |c1| / (sqrt(3) c0)` in [0, 1] how directional the light is (1: from
/// one direction), `q = (1 + cos) / 2` on the angle to `c1`'s direction, `p = 1 + 2r` and
/// `a = (1 - r) / (1 + r)`. It keeps the mean (`E0`) and, for small `r`, the linear term
/// `2 r E0 cos` of L1, and is never negative where the radiance is not: what the surface
/// lookup floors L2's ringing with (`prt_runtime::surface`). A channel with `c0 <= 0` gives 0.
pub fn irradiance_l1_nonlinear(c: &ShRgb, n: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|ch| {
        let c0 = c[0][ch];
        if c0.is_nan() || c0 <= 0.0 {
            return 0.0;
        }
        // L1 along x, y, z (coefficients 3, 1, 2: docs/conventions.md section 2).
        let v = [c[3][ch], c[1][ch], c[2][ch]];
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let r = (len / (3f32.sqrt() * c0)).min(1.0);
        let cos = match len > 0.0 {
            true => (v[0] * n[0] + v[1] * n[1] + v[2] * n[2]) / len,
            false => 0.0,
        };
        // Not 0: pow(0, p) is exp2(p log2 0) on a GPU, which WGSL leaves undefined.
        let q = (0.5 * (1.0 + cos)).clamp(1e-20, 1.0);
        let p = 1.0 + 2.0 * r;
        let a = (1.0 - r) / (1.0 + r);
        PI * Y00 * c0 * (a + (1.0 - a) * (p + 1.0) * q.powf(p))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::directions::{direction_weight, fibonacci_directions};

    fn project(n: u32, f: impl Fn([f32; 3]) -> [f32; 3]) -> ShRgb {
        let mut acc = [[0.0; 3]; SH_COUNT];
        let w = direction_weight(n);
        for d in fibonacci_directions(n) {
            accumulate(&mut acc, d, w, f(d));
        }
        acc
    }

    /// The non-linear L1 model: exact for uniform light, never negative, and for a light
    /// from one direction 0 straight behind it where the linear L1 model gives `-E0`.
    #[test]
    fn nonlinear_l1_irradiance_is_non_negative_and_keeps_the_mean() {
        let uniform = constant([0.2, 0.3, 0.5]);
        let e = irradiance_l1_nonlinear(&uniform, [0.0, 0.0, 1.0]);
        assert!((e[1] - PI * 0.3).abs() < 1e-5, "{e:?}");
        let mut lobe = [[0.0; 3]; SH_COUNT];
        let d = [0.6, 0.0, -0.8];
        accumulate(&mut lobe, d, 1.0, [1.0, 1.0, 1.0]);
        let behind = irradiance_l1_nonlinear(&lobe, [-0.6, 0.0, 0.8]);
        assert!(behind[0].abs() < 1e-6, "{behind:?}");
        let facing = irradiance_l1_nonlinear(&lobe, d)[0];
        assert!(
            (facing - 1.0).abs() < 1e-5,
            "a unit light head on: {facing}"
        );
        // A lobe over an ambient floor: non-negative everywhere, its mean over the sphere E0.
        let mut field = project(4096, |_| [0.05; 3]);
        accumulate(&mut field, d, 1.0, [1.0; 3]);
        let dirs = fibonacci_directions(4096);
        let mean = dirs
            .iter()
            .map(|&n| irradiance_l1_nonlinear(&field, n)[0])
            .inspect(|&e| assert!(e >= 0.0))
            .sum::<f32>()
            / dirs.len() as f32;
        let e0 = PI * Y00 * field[0][0];
        assert!((mean - e0).abs() < 1e-3 * e0, "mean {mean} against {e0}");
        assert_eq!(irradiance_l1_nonlinear(&[[0.0; 3]; SH_COUNT], d), [0.0; 3]);
    }

    #[test]
    fn constant_field_projects_to_c0_only() {
        let c = project(4096, |_| [0.2, 0.3, 0.5]);
        let expect = constant([0.2, 0.3, 0.5]);
        assert!((expect[0][0] - 0.2 * 3.544_907_7).abs() < 1e-5);
        for k in 0..SH_COUNT {
            for ch in 0..3 {
                assert!(
                    (c[k][ch] - expect[k][ch]).abs() < 1e-4,
                    "k {k}: {}",
                    c[k][ch]
                );
            }
        }
        // Uniform radiance L gives irradiance pi L whatever the normal.
        for n in [[0.0, 1.0, 0.0], [0.6, 0.0, 0.8], [0.0, 0.0, -1.0]] {
            let e = irradiance(&expect, n);
            assert!((e[1] - PI * 0.3).abs() < 1e-5, "{e:?}");
        }
    }

    #[test]
    fn basis_is_orthonormal_on_the_lattice() {
        let n = 16384;
        let w = direction_weight(n);
        let mut gram = [[0.0f64; SH_COUNT]; SH_COUNT];
        for d in fibonacci_directions(n) {
            let y = basis(d);
            for i in 0..SH_COUNT {
                for j in 0..SH_COUNT {
                    gram[i][j] += f64::from(w * y[i] * y[j]);
                }
            }
        }
        for i in 0..SH_COUNT {
            for j in 0..SH_COUNT {
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (gram[i][j] - expect).abs() < 2e-3,
                    "<Y{i},Y{j}> = {}",
                    gram[i][j]
                );
            }
        }
    }

    #[test]
    fn single_direction_is_the_basis_itself() {
        let d = [0.0, 0.6, 0.8];
        let mut acc = [[0.0; 3]; SH_COUNT];
        accumulate(&mut acc, d, 1.0, [1.0, 2.0, 3.0]);
        let y = basis(d);
        for k in 0..SH_COUNT {
            assert_eq!(acc[k], [y[k], 2.0 * y[k], 3.0 * y[k]]);
        }
    }

    #[test]
    fn cosine_lobe_irradiance_matches_closed_form() {
        // Radiance L = max(0, d.z): irradiance at normal +z is 2pi/3, at -z is 0; L2 SH gets
        // them to within the Ramamoorthi-Hanrahan error (under 3% of the maximum).
        let c = project(65536, |d| [d[2].max(0.0); 3]);
        let up = irradiance(&c, [0.0, 0.0, 1.0])[0];
        let down = irradiance(&c, [0.0, 0.0, -1.0])[0];
        let exact_up = 2.0 * PI / 3.0;
        assert!((up - exact_up).abs() / exact_up < 0.03, "up {up}");
        assert!(down.abs() / exact_up < 0.03, "down {down}");
        // Coefficient c_0 of max(0,z) is Y00 * pi exactly.
        assert!((c[0][0] - Y00 * PI).abs() < 1e-3, "c0 {}", c[0][0]);
    }

    #[test]
    fn window_keeps_dc_and_damps_higher_bands() {
        let c = project(1024, |d| [d[2].max(0.0); 3]);
        let w = hanning_window(&c, 4.0);
        assert_eq!(w[0], c[0]);
        assert!(w[2][0].abs() < c[2][0].abs());
        assert!(w[6][0].abs() < c[6][0].abs());
    }
}
