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
