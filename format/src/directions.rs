//! The fixed ray direction set of a bake: the spherical Fibonacci lattice.
//!
//! Point i of N: `z_i = 1 - (2i+1)/N`, `phi_i = i * pi * (3 - sqrt 5)`,
//! `w_i = (sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi, z)` (docs/conventions.md section 2). Every
//! point stands for the same solid angle 4pi/N, the set is stratified and deterministic, and it is
//! the very lattice the independent reference (Mitsuba 3 oracle) uses, so a bake on it is directly
//! comparable to the reference data ray by ray. Computed in f64 and rounded once, as the oracle
//! does. See Keinert et al., "Spherical Fibonacci Mapping", SIGGRAPH Asia 2015.

use std::f64::consts::PI;

/// Direction `i` of the `n`-point lattice, unit length.
pub fn fibonacci_direction(i: u32, n: u32) -> [f32; 3] {
    let z = 1.0 - (2.0 * f64::from(i) + 1.0) / f64::from(n);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = f64::from(i) * PI * (3.0 - 5.0_f64.sqrt());
    [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
}

/// All `n` directions of the lattice, in index order.
pub fn fibonacci_directions(n: u32) -> Vec<[f32; 3]> {
    (0..n).map(|i| fibonacci_direction(i, n)).collect()
}

/// Solid angle each lattice direction stands for.
pub fn direction_weight(n: u32) -> f32 {
    (4.0 * PI / f64::from(n)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_is_unit_and_balanced() {
        let n = 512;
        let dirs = fibonacci_directions(n);
        let mut sum = [0.0f64; 3];
        for d in &dirs {
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-6, "length {len}");
            for a in 0..3 {
                sum[a] += f64::from(d[a]);
            }
        }
        for s in sum {
            assert!(s.abs() / f64::from(n) < 1e-3, "mean component {s}");
        }
        assert!((direction_weight(n) * n as f32 - 4.0 * std::f32::consts::PI).abs() < 1e-4);
    }
}
